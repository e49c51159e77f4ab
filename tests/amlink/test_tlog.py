"""amlink.tlog: a .tlog that cannot be created is a typed error naming the file."""
from __future__ import annotations

import pytest

from amlink.tlog import TlogError, TlogWriter


def test_a_tlog_whose_folder_cannot_be_made_raises_an_oserror_naming_the_file(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    path = blocker / "sub" / "c.tlog"
    with pytest.raises(TlogError) as err:
        TlogWriter(path).open()
    assert isinstance(err.value, OSError) and err.value.filename == str(path)
    assert str(err.value).startswith(f"cannot write {path}: ") and "Errno" not in str(err.value)


def test_a_tlog_is_written_once_opened(tmp_path):
    path = tmp_path / "new" / "c.tlog"
    with TlogWriter(path) as w:
        w.write_frame(b"\xfd\x00", t_s=1.0)
    assert path.read_bytes() == (1_000_000).to_bytes(8, "big") + b"\xfd\x00"
