"""Pinhole camera intrinsics shared by the frame and event sensors (a DAVIS-style sensor)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import torch

from fusiongs.errors import InputError


def _check_size(width: object, height: object) -> None:
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
            raise InputError("camera", name, "a positive integer", repr(v))


def _check_distortion(distortion: tuple[float, ...] | None) -> None:
    if distortion is not None and len(distortion) != 5:
        raise InputError("camera", "distortion", "5 numbers [k1, k2, p1, p2, k3]",
                         f"{len(distortion)} numbers")


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics in pixels; pixel centres are at integer + 0.5 (gsplat convention).

    Attributes:
        width, height: image size in pixels.
        fx, fy: focal lengths in pixels.
        cx, cy: principal point in pixels.
        distortion: optional OpenCV ``[k1, k2, p1, p2, k3]``; ``None`` for an ideal pinhole.
        intrinsics_known: always ``True`` (class constant; :class:`UncalibratedCamera` has
            ``False``), so ``scene.camera.intrinsics_known`` tells the two apart.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] | None = None
    intrinsics_known: ClassVar[bool] = True

    def __post_init__(self) -> None:
        _check_size(self.width, self.height)
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise InputError("camera", name, "a finite number", repr(v))
        if self.fx <= 0 or self.fy <= 0:
            raise InputError("camera", "fx/fy", "positive focal lengths", f"{self.fx}, {self.fy}")
        _check_distortion(self.distortion)

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


@dataclass(frozen=True)
class UncalibratedCamera:
    """A camera of known size whose intrinsics are to be estimated (``scene.json`` without
    ``fx``, ``fy``, ``cx``, ``cy``; docs/scene-format.md). It has no focal length or principal point, so code
    that needs them fails loudly until poses and intrinsics are estimated
    (:func:`fusiongs.sfm.register.estimate_camera_and_trajectory`).

    Attributes:
        width, height: image size in pixels.
        distortion: optional OpenCV ``[k1, k2, p1, p2, k3]``; ``None`` for an ideal pinhole.
        intrinsics_known: always ``False`` (class constant).
    """

    width: int
    height: int
    distortion: tuple[float, ...] | None = None
    intrinsics_known: ClassVar[bool] = False

    def __post_init__(self) -> None:
        _check_size(self.width, self.height)
        _check_distortion(self.distortion)

    def guess(self, focal_factor: float = 1.2) -> PinholeCamera:
        """A starting pinhole: focal ``focal_factor x width`` (COLMAP's default prior), principal
        point at the image centre."""
        f = focal_factor * self.width
        return PinholeCamera(self.width, self.height, f, f, self.width / 2, self.height / 2,
                             self.distortion)


SceneCamera = PinholeCamera | UncalibratedCamera
"""The camera of a scene: calibrated, or of known size only."""


def world_to_pixels(points: torch.Tensor, c2w: torch.Tensor, camera: PinholeCamera
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """Pixel coordinates and depths of world points seen by posed pinhole cameras (no distortion).

    Args:
        points: ``[..., M, 3]`` world points (scene units).
        c2w: ``[..., 4, 4]`` camera-to-world poses (OpenCV axes), broadcast against ``points``'
            leading dimensions (e.g. ``[F, 4, 4]`` with ``[M, 3]`` gives ``[F, M, ...]``).
        camera: the intrinsics (px; pixel centres at integer + 0.5).

    Returns:
        ``(uv [..., M, 2] px, z [..., M])`` in the inputs' dtype; ``z`` is the depth along the
        optical axis (points with ``z <= 0`` are behind the camera and their ``uv`` meaningless).
    """
    cam = (points - c2w[..., None, :3, 3]) @ c2w[..., :3, :3]
    z = cam[..., 2]
    uv = torch.stack([camera.fx * cam[..., 0] / z + camera.cx, camera.fy * cam[..., 1] / z + camera.cy], -1)
    return uv, z
