"""A run's telemetry key files: every one written with mode 0600, or none at all."""
from __future__ import annotations

import errno
import stat

import pytest

from telemetry import keyfiles


def test_a_run_gets_the_master_and_one_key_per_publisher_only_its_owner_reads(tmp_path):
    files = keyfiles.write_run_keys(tmp_path, [4, 5])
    assert set(files) == {"recorder", "simulator", "am4", "am5"}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in files.values())
    for path in files.values():
        assert stat.S_IMODE(path.stat().st_mode) == 0o600


def test_a_key_that_cannot_be_written_leaves_no_key_behind(tmp_path, monkeypatch):
    """A master key left alone would make `ground-station keys` refuse the folder on a retry."""
    real, calls = keyfiles.write_secret, []

    def disk_fills_on_the_third(path, text):
        calls.append(path)
        if len(calls) == 3:
            path.write_text(text[:5])  # half-written
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, text)

    monkeypatch.setattr(keyfiles, "write_secret", disk_fills_on_the_third)
    with pytest.raises(OSError, match="No space left"):
        keyfiles.write_run_keys(tmp_path, [4, 5])
    assert len(calls) == 3 and list(tmp_path.iterdir()) == []
