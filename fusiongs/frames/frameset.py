"""The frame set container: images with exposure windows and their response curve."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class FrameSet:
    """Frames of one camera with their exposure windows.

    Attributes:
        images: ``[F, H, W, C]`` float32 pixel values in [0, 1] as stored in the files (encoded by
            ``response``; C = 3 for RGB, 1 for a monochrome camera). ``[0, H, W, C]`` when empty.
        t_start, t_end: ``[F]`` float64 exposure start and end in seconds (events' clock / 1e6).
        names: frame stems (``"000000"`` for ``frames/000000.png``), used for output file names.
        response: how stored values relate to linear irradiance: ``"srgb"``, ``"linear"`` or
            ``"gamma:G"``.
    """

    images: np.ndarray
    t_start: np.ndarray
    t_end: np.ndarray
    names: tuple[str, ...]
    response: str = "srgb"

    def __len__(self) -> int:
        return int(self.images.shape[0])
