"""Named random streams of the digital twin: one generator per noise channel.

Each channel draws from ``np.random.default_rng([seed, channel])`` (:class:`NoiseStream`):
independent, deterministic per seed; switching one off leaves the others' draws unchanged.
"""

from __future__ import annotations

import enum

import numpy as np
from numpy.typing import NDArray

__all__ = ["NoiseChannel", "NoiseStream"]

_BLOCK = 4096


class NoiseChannel(enum.IntEnum):
    """The twin's noise channels; the value is the channel id mixed into the seed."""

    SLIP = 1
    """Drive of the Ornstein–Uhlenbeck slip on vx, vy, wz."""
    GYRO = 2
    """Gyro white noise, x, y, z."""
    ACCEL = 3
    """Accelerometer white noise, x, y, z."""
    MAGNETOMETER = 4
    """Magnetometer white noise, x, y, z."""


class NoiseStream:
    """Standard-normal triples of one channel, block-drawn from the channel's own generator."""

    def __init__(self, seed: int, channel: NoiseChannel, *, block: int = _BLOCK) -> None:
        self.channel = channel
        self._rng = np.random.default_rng([seed, int(channel)])
        self._block_size = block
        self._rows: NDArray[np.float64] = np.empty((0, 3))
        self._block: list[list[float]] = []
        self._i = 0

    @property
    def block_size(self) -> int:
        """Rows (x, y, z samples) drawn from the generator at a time."""
        return self._block_size

    def _draw(self) -> None:
        self._rows = self._rng.standard_normal((self._block_size, 3))
        self._block = []
        self._i = 0

    def next3(self) -> list[float]:
        """The next three independent standard normals (one x, y, z sample)."""
        if self._i >= len(self._rows):
            self._draw()
        if not self._block:
            self._block = self._rows.tolist()
        row = self._block[self._i]
        self._i += 1
        return row

    def take_rows(self) -> NDArray[np.float64]:
        """All samples left in the current block, (r, 3) with 1 ≤ r ≤ ``block_size``, as consumed.

        The samples :meth:`next3` would have returned next, in order.
        """
        if self._i >= len(self._rows):
            self._draw()
        rows = self._rows[self._i :]
        self._i = len(self._rows)
        return rows
