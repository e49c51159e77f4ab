"""A device's standard normal draws taken in blocks (pure: numpy only)."""
from __future__ import annotations

import numpy as np


class NoiseBlock:
    """Draws of `rng.standard_normal(width)` step after step, taken from blocks of `rows`
    draws at once: numpy's generator fills a large array with the numbers, in the order,
    that the small calls would give (tests/simulator/test_device_kernels.py)."""

    def __init__(self, rng: np.random.Generator, width: int, rows: int = 256) -> None:
        self.rng, self.width, self.rows = rng, width, rows
        self._block = np.empty((0, width))
        self._i = 0

    def next(self) -> np.ndarray:
        if self._i == self._block.shape[0]:
            self._block = self.rng.standard_normal(self.rows * self.width).reshape(self.rows, self.width)
            self._i = 0
        self._i += 1
        return self._block[self._i - 1]
