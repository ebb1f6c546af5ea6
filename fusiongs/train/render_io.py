"""Sharp sRGB renders of a fitted state, and the truth images they are compared with."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from fusiongs.frames.image_io import read_image
from fusiongs.frames.response import linear_to_srgb
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.state import FusionState

#: Exposure of renders whose absolute level nothing fixes (event-only runs without a colour
#: anchor): one gain in linear light puts this percentile of the rendered values ...
EXPOSURE_PERCENTILE = 99.5
#: ... at this level, so that no more than the brightest 0.5 % of values clip at white.
EXPOSURE_LEVEL = 0.9


def auto_exposure(cfg: DeblurConfig, n_frames: int) -> bool:
    """Whether renders get :func:`exposure_gain`: without frames (their
    level is arbitrary: events measure changes of log intensity) unless ``output.exposure`` is
    ``none``. With one frame the colour anchor fixes the level; with several, the blur loss."""
    return n_frames == 0 and cfg.output.exposure == "auto"


def exposure_gain(linear: np.ndarray) -> float:
    """One gain for linear renders ``[..., 3]`` whose level is arbitrary (events measure changes
    of log intensity, so an event-only model's level is wherever its start put it): the
    :data:`EXPOSURE_PERCENTILE` of all values goes to :data:`EXPOSURE_LEVEL` (a gain only, so
    the ratios between pixels and channels, which the events do measure, are kept). Without it the
    start's level decides what clips at white and is lost from the written images. 1 for renders
    with no positive values."""
    if not np.size(linear):
        return 1.0
    q = float(np.percentile(np.asarray(linear, dtype=np.float64), EXPOSURE_PERCENTILE))
    return EXPOSURE_LEVEL / q if q > 0 and np.isfinite(q) else 1.0


@torch.no_grad()
def render_linear(state: FusionState, camera, times, backend: str = "auto", batch: int = 8,
                  poses: np.ndarray | None = None) -> np.ndarray:
    """Sharp linear renders ``[T, H, W, 3]`` float32 (not clipped) at instants ``times`` (s) on the
    fitted path, or, when ``poses`` ``[T, 4, 4]`` (camera-to-world, the run's world frame) are
    given, from those poses (``times`` is then ignored)."""
    out = [lin for lin, *_ in _batches(state.render, state.render_poses, camera, times, poses, backend,
                                       batch)]
    return np.concatenate(out) if out else np.zeros((0, camera.height, camera.width, 3), np.float32)


@torch.no_grad()
def render_depth_maps(state: FusionState, camera, times, backend: str = "auto", batch: int = 8,
                      poses: np.ndarray | None = None, min_alpha: float = 0.5) -> np.ndarray:
    """Depth along the optical axis ``[T, H, W]`` float32 (scene units) at ``times`` or from
    ``poses`` (as :func:`render_linear`); NaN where the accumulated opacity is under ``min_alpha``
    (nothing there to measure: :meth:`~fusiongs.train.state.FusionState.render_depth`)."""
    out = [np.where(alpha >= min_alpha, depth, np.nan).astype(np.float32) for depth, alpha in
           _batches(state.render_depth, state.render_depth_poses, camera, times, poses, backend, batch)]
    return np.concatenate(out) if out else np.zeros((0, camera.height, camera.width), np.float32)


def _batches(at_times, at_poses, camera, times, poses, backend: str, batch: int):
    """Numpy results of ``at_times(camera, t, backend)`` over ``times``, or of ``at_poses(camera,
    c2w, backend)`` over ``poses`` when given, ``batch`` views a call."""
    if poses is None:
        views, draw = torch.as_tensor(np.asarray(times, dtype=np.float64)), at_times
    else:
        views, draw = torch.as_tensor(np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)), at_poses
    for i in range(0, views.shape[0], batch):
        yield tuple(v.float().cpu().numpy() for v in draw(camera, views[i:i + batch], backend)[:2])


def render_srgb(state: FusionState, camera, times, backend: str = "auto", batch: int = 8,
                auto_exposure: bool = False, gain: float = 1.0, poses: np.ndarray | None = None
                ) -> np.ndarray:
    """Sharp sRGB renders ``[T, H, W, 3]`` in [0, 1] at instants ``times`` (s), or from ``poses``
    (:func:`render_linear`): times ``gain``, or the :func:`exposure_gain` of these renders when
    ``auto_exposure``, then clipped to [0, 1] in linear light."""
    lin = render_linear(state, camera, times, backend, batch, poses)
    return exposed_srgb(lin, exposure_gain(lin) if auto_exposure else gain)


def exposed_srgb(linear: np.ndarray, gain: float = 1.0) -> np.ndarray:
    """float32 sRGB of linear renders ``[..., 3]`` times ``gain``, clipped to [0, 1] in linear light."""
    lin = linear * np.float32(gain) if gain != 1.0 else linear
    return np.asarray(linear_to_srgb(np.clip(lin, 0.0, 1.0)), dtype=np.float32)


def read_gt(gt_dir: Path, names) -> dict[str, np.ndarray]:
    """Truth images ``gt_dir/<name>.png`` that exist, as sRGB ``[H, W, 3]``."""
    out = {}
    for name in names:
        p = gt_dir / f"{name}.png"
        if p.is_file():
            img = read_image(p)
            out[name] = np.repeat(img, 3, axis=-1) if img.shape[-1] == 1 else img
    return out
