"""Run `ground-station record` as a subprocess in tests: started, awaited, always stopped."""
from __future__ import annotations

import queue
import subprocess
import sys
import threading
import time


class RecorderProcess:
    """`python -m ground_station record --out PATH --zenoh-listen ENDPOINT ...`; waits for
    its 'recording' line. Used as a context manager: killed on exit if still alive."""

    def __init__(self, out_path, endpoint: str, *extra: str, ready_timeout_s: float = 20.0):
        # a test that is not about authentication records without a key (--insecure)
        key = [] if "--telemetry-key-file" in extra else ["--insecure"]
        self.cmd = [sys.executable, "-m", "ground_station", "record", "--out", str(out_path), "--zenoh-listen",
                    endpoint, "--summary-json", *key, *extra]
        self.ready_timeout_s = ready_timeout_s
        self.proc: subprocess.Popen | None = None
        self.stderr_lines: list[str] = []
        self._lines: queue.Queue = queue.Queue()

    def __enter__(self) -> "RecorderProcess":
        self.proc = subprocess.Popen(self.cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        threading.Thread(target=self._pump, daemon=True).start()
        deadline = time.monotonic() + self.ready_timeout_s
        while True:
            try:
                line = self._lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise RuntimeError(f"recorder not ready after {self.ready_timeout_s} s: {self.stderr_lines}") from None
            if line is None:
                raise RuntimeError(f"recorder exited before it was ready: {self.stderr_lines}")
            if line.startswith("recording "):
                return self

    def _pump(self) -> None:
        for line in self.proc.stderr:
            self.stderr_lines.append(line.rstrip())
            self._lines.put(line)
        self._lines.put(None)

    def wait(self, timeout_s: float) -> tuple[int, str]:
        """Exit code and stdout; kills the recorder and raises if it does not exit in time."""
        try:
            self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise AssertionError(f"recorder did not exit within {timeout_s} s: {self.stderr_lines}") from None
        return self.proc.returncode, self.proc.stdout.read()

    def __exit__(self, *exc) -> None:
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            self.proc.stdout.close()
