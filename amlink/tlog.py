"""Telemetry logs (.tlog) as MAVProxy writes them, for stock tools (mavlogdump.py, MAVExplorer).

A .tlog is a plain sequence of records, each the wall-clock time as a big-endian uint64 of
microseconds since the Unix epoch followed by one whole MAVLink frame, as sent or received.
:meth:`TlogWriter.write` takes a datagram (or a stream's whole frames) and writes one record
per frame.  Writes are buffered; nothing is written until :meth:`open`, which raises
:class:`TlogError` (an OSError naming the file) if the file cannot be created.
"""

from __future__ import annotations

import struct
import threading
import time
from pathlib import Path

from amlink.wire import split_frames

_STAMP = struct.Struct(">Q")


class TlogError(OSError):
    """The .tlog cannot be created: its folder cannot be made, or is not writable."""

    def __init__(self, path: Path, cause: OSError) -> None:
        super().__init__(cause.errno, cause.strerror or str(cause), str(path))

    def __str__(self) -> str:
        return f"cannot write {self.filename}: {self.strerror}"


class TlogWriter:
    """Appends MAVLink frames to ``path`` with MAVProxy's timestamps; thread-safe."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.records = 0
        self._file = None
        self._lock = threading.Lock()

    def open(self) -> TlogWriter:
        """Create the file (and its folder); TlogError if it cannot be."""
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "wb", buffering=1 << 16)
        except OSError as exc:
            raise TlogError(self.path, exc) from exc
        return self

    def write(self, data: bytes, t_s: float | None = None) -> None:
        """One record per whole MAVLink 2 frame of ``data``, stamped ``t_s`` [s since the epoch] or now."""
        if self._file is None:
            return
        stamp = _STAMP.pack(int((time.time() if t_s is None else t_s) * 1e6))
        frames = split_frames(data)
        with self._lock:
            for frame in frames:
                self._file.write(stamp)
                self._file.write(frame)
            self.records += len(frames)

    def write_frame(self, frame: bytes, t_s: float | None = None) -> None:
        """One record holding ``frame`` as it is (a MAVLink 1 frame, say)."""
        if self._file is None:
            return
        stamp = _STAMP.pack(int((time.time() if t_s is None else t_s) * 1e6))
        with self._lock:
            self._file.write(stamp)
            self._file.write(frame)
            self.records += 1

    def flush(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.flush()

    def close(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None

    def __enter__(self) -> TlogWriter:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()
