"""The progress bar of a run's simulated time (tqdm), shared by `simulator` and `am-run`.

    bar = SimBar(duration_s)      # to stderr; disabled=True for none
    bar.show(t_s, real_time_factor)
    bar.close()

On a terminal it redraws about twice a second; into a file or pipe it writes a line at
every tenth of the run, so that logs stay readable.
"""
from __future__ import annotations

import sys

from tqdm import tqdm


class SimBar:
    def __init__(self, duration_s: float, disabled: bool = False) -> None:
        tty = sys.stderr.isatty()
        self.duration = max(float(duration_s), 1e-9)
        self._bar = tqdm(total=round(self.duration, 3), unit="sim s", file=sys.stderr, disable=disabled,
                         dynamic_ncols=True, mininterval=0.5 if tty else 1e9, leave=True, delay=0.1,
                         bar_format="{l_bar}{bar}| {n:.2f}/{total:.1f} s sim [{elapsed}{postfix}]")
        self._tty, self._decile = tty, -1

    def show(self, t_s: float, rtf: float) -> None:
        b = self._bar
        if b.disable:
            return
        b.n = round(min(t_s, self.duration), 3)
        b.set_postfix_str(f"{rtf:.2f}x real time", refresh=False)
        decile = int(10 * min(1.0, t_s / self.duration))
        if self._tty:
            b.update(0)  # redraws when mininterval has passed
        elif decile > self._decile:
            self._decile = decile
            b.refresh()
            b.fp.write("\n")

    def close(self) -> None:
        self._bar.close()
