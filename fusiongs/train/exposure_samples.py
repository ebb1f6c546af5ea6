"""Renders per exposure that follow the motion: ``blur.sample_spacing`` (docs/configuration.md).

The blur loss averages N sharp renders spread over each exposure (docs/method.md §1). The renders
must lie close enough together that their mean looks like the continuous blur trail: the image
moves ``m`` pixels during an exposure, so consecutive renders are ``m / (N − 1)`` pixels apart.
A run whose exposures blur by a few pixels needs fewer renders than one whose exposures blur by
twelve, and each render of a full-resolution step costs about as much as any other.

Measured on tuning seeds (benchmarks/RESULTS.md, "What was tried and not adopted" and "CPU
speed"): renders 1 px apart or closer cost at most 0.04 dB against 9 renders, 1.5 px apart 0.10 dB,
2 px apart 0.23 dB, 3 px apart 1.0 dB. The default spacing is 1 px.
"""

from __future__ import annotations

import math

import torch

from fusiongs.camera.pinhole import PinholeCamera, world_to_pixels

MIN_SAMPLES = 5  # the fewest renders per exposure chosen (the coarse steps' default)
MOTION_QUANTILE = 0.9  # the exposures' motion statistic: this quantile over the frames


def exposure_motion_px(points: torch.Tensor, c2w_start: torch.Tensor, c2w_end: torch.Tensor,
                       camera: PinholeCamera) -> torch.Tensor:
    """Mean image motion (px) of ``points`` during each exposure.

    Args:
        points: ``[M, 3]`` world points (scene units), e.g. the initial Gaussians' means.
        c2w_start, c2w_end: ``[F, 4, 4]`` camera-to-world poses at each exposure's start and end.
        camera: the pinhole camera (px).

    Returns:
        ``[F]`` float64: for each exposure, the mean over the points seen at its start (in front
        of the camera at both ends and inside the image at the start) of the distance (px)
        between their projections at the start and at the end; 0 where no point is seen.
    """
    p = points.to(torch.float64)
    uv0, z0 = world_to_pixels(p, c2w_start.to(torch.float64), camera)  # [F, M, 2], [F, M]
    uv1, z1 = world_to_pixels(p, c2w_end.to(torch.float64), camera)
    seen = (z0 > 1e-6) & (z1 > 1e-6) & (uv0[..., 0] >= 0) & (uv0[..., 0] <= camera.width) \
        & (uv0[..., 1] >= 0) & (uv0[..., 1] <= camera.height)
    d = (uv1 - uv0).norm(dim=-1).masked_fill(~seen, 0.0)
    return d.sum(1) / seen.sum(1).clamp(min=1)


def samples_for_motion(motion_px: float, spacing: float, n_max: int, n_min: int = MIN_SAMPLES) -> int:
    """The fewest odd renders per exposure ``N >= n_min`` that keep consecutive renders of an
    exposure moving ``motion_px`` within ``spacing`` px (``motion / (N − 1) <= spacing``), at most
    ``n_max`` (``n_max`` itself when it is below ``n_min``)."""
    if n_max <= n_min:
        return n_max
    need = max(n_min, math.ceil(motion_px / spacing - 1e-9) + 1)
    need += 1 - need % 2  # odd: the middle render is the mid-exposure instant
    return min(n_max, need)


def derived_samples(points: torch.Tensor, c2w_start: torch.Tensor, c2w_end: torch.Tensor,
                    camera: PinholeCamera, spacing: float, n_max: int) -> tuple[int, float]:
    """``(N, motion)``: :func:`samples_for_motion` of the :data:`MOTION_QUANTILE` quantile (px) of
    :func:`exposure_motion_px` over the exposures."""
    per_frame = exposure_motion_px(points, c2w_start, c2w_end, camera)
    motion = float(torch.quantile(per_frame, MOTION_QUANTILE)) if len(per_frame) else 0.0
    return samples_for_motion(motion, spacing, n_max), motion
