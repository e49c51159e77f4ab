"""A device's standard normal draws taken in blocks (pure: numpy only)."""
from __future__ import annotations

import numpy as np


class NoiseBlock:
    """Draws of `rng.standard_normal(width)` step after step, taken from blocks of `rows`
    draws at once: numpy's generator fills a large array with the numbers, in the order,
    that the small calls would give (tests/simulator/test_device_kernels.py). `block`: the
    (rows, width) array to hold a block in, e.g. a view of a fleet's (simulator.devices);
    None: one of its own."""

    def __init__(self, rng: np.random.Generator, width: int, rows: int = 256, block: np.ndarray | None = None) -> None:
        self.rng, self.width, self.rows = rng, width, rows
        self.block = np.empty((rows, width)) if block is None else block
        if self.block.shape != (rows, width):
            raise ValueError(f"a noise block of {self.block.shape}, not ({rows}, {width})")
        self._i = rows  # nothing drawn yet: the first `next` fills the first block

    def fill(self) -> None:
        """The next block, in place."""
        self.block[:] = self.rng.standard_normal(self.rows * self.width).reshape(self.rows, self.width)
        self._i = 0

    def next(self) -> np.ndarray:
        if self._i == self.rows:
            self.fill()
        self._i += 1
        return self.block[self._i - 1]
