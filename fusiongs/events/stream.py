"""The event stream container."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CFA_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")


@dataclass(frozen=True, eq=False)
class EventStream:
    """A time-sorted stream of events from one sensor.

    Attributes:
        t: ``[E]`` int64 timestamps in microseconds, sorted ascending (non-decreasing).
        x: ``[E]`` uint16 column, ``0 <= x < width``.
        y: ``[E]`` uint16 row, ``0 <= y < height``.
        p: ``[E]`` int8 polarity, +1 (brightness increase) or -1.
        width, height: sensor size in pixels.
        cfa: ``None`` for a monochrome sensor, else one of ``CFA_PATTERNS`` (2x2 layout named by
            its top-left cells in row-major order; ``"RGGB"`` = R at even row and even column).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    width: int
    height: int
    cfa: str | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])
