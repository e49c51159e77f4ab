"""A device's random draws taken in blocks (pure: numpy only)."""
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


class CaptureDraws:
    """The motion capture's draws, capture after capture, taken a block of `rows` captures at
    once into `block` ((rows, 7): a view of a fleet's, simulator.devices): per capture
    `rng.standard_normal(6)`, then `rng.random()` if `with_drop` (else column 6 is left 0),
    the numbers, in the order, that a call per capture gives. Without drops, one call fills
    the block, as `NoiseBlock`; with them the normals and the uniforms interleave in the
    generator's stream, so each capture's are drawn in turn."""

    def __init__(self, rng: np.random.Generator, rows: int, block: np.ndarray, with_drop: bool) -> None:
        self.rng, self.rows, self.block, self.with_drop = rng, rows, block, with_drop
        if block.shape != (rows, 7):
            raise ValueError(f"a capture block of {block.shape}, not ({rows}, 7)")

    def fill(self) -> None:
        """The next block, in place."""
        b, rng = self.block, self.rng
        if not self.with_drop:
            b[:, :6] = rng.standard_normal(self.rows * 6).reshape(self.rows, 6)
            return
        for r in range(self.rows):
            b[r, :6] = rng.standard_normal(6)
            b[r, 6] = rng.random()
