"""Pinhole camera intrinsics shared by the frame and event sensors (a DAVIS-style sensor)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from fusiongs.errors import InputError


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics in pixels; pixel centres are at integer + 0.5 (gsplat convention).

    Attributes:
        width, height: image size in pixels.
        fx, fy: focal lengths in pixels.
        cx, cy: principal point in pixels.
        distortion: optional OpenCV ``[k1, k2, p1, p2, k3]``; ``None`` for an ideal pinhole.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise InputError("camera", name, "a positive integer", repr(v))
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise InputError("camera", name, "a finite number", repr(v))
        if self.fx <= 0 or self.fy <= 0:
            raise InputError("camera", "fx/fy", "positive focal lengths", f"{self.fx}, {self.fy}")
        if self.distortion is not None and len(self.distortion) != 5:
            raise InputError("camera", "distortion", "5 numbers [k1, k2, p1, p2, k3]",
                             f"{len(self.distortion)} numbers")

    def K(self, dtype: torch.dtype = torch.float32, device: torch.device | str | None = None) -> torch.Tensor:
        """Intrinsic matrix ``[3, 3]``."""
        return torch.tensor([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]],
                            dtype=dtype, device=device)

    def scaled(self, factor: float) -> PinholeCamera:
        """The same camera at ``factor`` times the resolution (rounded)."""
        w, h = max(1, round(self.width * factor)), max(1, round(self.height * factor))
        sx, sy = w / self.width, h / self.height
        return PinholeCamera(w, h, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy,
                             self.distortion)
