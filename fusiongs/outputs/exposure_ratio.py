"""Exposure-ratio correction: the captured frame's own detail put back into the deblurred frame.

The blur model (docs/method.md §1) says a frame is ``B = CRF(g · mean_k L(t_k))`` over its exposure.
The fitted scene renders ``R(t)`` and predicts ``B̂ = g · mean_k R(t_k)`` (linear). Write the true
sharp image as ``L(t) = ρ · R(t)`` with a per-pixel factor ``ρ`` that stays the same over the
exposure (what the model lacks: texture finer than its Gaussians, small geometry and colour
errors); then the exposure model gives ``ρ = B / B̂`` and the corrected sharp frame is

    L̂(t) = R(t) · (B + ε) / (B̂ + ε)            (linear light, per pixel and channel)

This is the relation EDI inverts (Pan et al., "Bringing a Blurry Frame Alive at High Frame-Rate
with an Event Camera", CVPR 2019: ``L(t) = B / mean_s exp(c · E(t → s))``) with the temporal profile
``R(t_k) / R(t)`` taken from the fitted scene (frames and events together) instead of from the
events alone. Where the model already explains the frame, ``ρ = 1`` and nothing changes; where it
misses detail, the frame supplies it; the assumption fails where the missing detail moves a lot
within the exposure (heavy blur), and there it brings back that detail blurred. With
``output.ratio_iterations`` >= 1 (the default) ``ρ`` is attached to the scene's surfaces instead and
carried by the fitted motion, which deblurs that detail too (:mod:`fusiongs.outputs.motion_ratio`).

``ε`` (linear units) keeps dark pixels, where read noise dominates, from amplifying noise; its
default was chosen on tuning seeds. Pixels that are saturated
in the frame carry no ratio (the true value may be higher): there ``ρ = 1``.

Instants between two exposures (``renders/``, novel instants) are corrected too with
``output.ratio_between`` (the default, with ``ratio_iterations`` >= 1): both frames' factors are
carried there along the fitted motion (:func:`factor_carried`) and weighted linearly in time.
Instants before the first or after the last exposure stay the
scene's renders. ``--holdout`` scores, beside the renders, their prediction of a held-out frame
with the kept neighbours' factors carried the same way: a check, on recordings without truth, that
the detail the factor adds is the scene's.
"""

from __future__ import annotations

import numpy as np
import torch

from fusiongs.camera.reproject import reference_grid
from fusiongs.frames.response import response_to_linear
from fusiongs.io.scene import Scene
from fusiongs.losses.blur import exposure_instants
from fusiongs.losses.event import to_grey
from fusiongs.outputs.motion_ratio import carry, motion_ratio
from fusiongs.train.state import FusionState

SATURATED = 1.0 - 0.5 / 255.0  # encoded frame values at or above this are clipped (8-bit full scale)


def exposure_ratio(observed: torch.Tensor, predicted: torch.Tensor, saturated: torch.Tensor,
                   eps: float) -> torch.Tensor:
    """Per-pixel ratio ``ρ = (B + ε) / (B̂ + ε)``, 1 where the frame is saturated.

    Args:
        observed: ``[..., H, W, C]`` the captured frame, linear (>= 0).
        predicted: ``[..., H, W, C]`` the model's blurry frame, linear, same device.
        saturated: ``[..., H, W, C]`` bool, True where the captured value is clipped.
        eps: linear offset > 0.

    Returns:
        ``[..., H, W, C]`` the ratio (unitless, > 0).
    """
    ratio = (observed.clamp_min(0) + eps) / (predicted.clamp_min(0) + eps)
    return torch.where(saturated, torch.ones_like(ratio), ratio)


def containing_frame(t_start: np.ndarray, t_end: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``[T]`` index of the frame whose exposure ``[t_start, t_end]`` contains each instant, -1 where
    none does (of two overlapping exposures, the one whose mid-exposure is nearer)."""
    s, e = np.asarray(t_start, np.float64), np.asarray(t_end, np.float64)
    t = np.asarray(times, np.float64).reshape(-1, 1)
    inside = (t >= s) & (t <= e)
    dist = np.where(inside, np.abs(t - 0.5 * (s + e)), np.inf)
    best = dist.argmin(axis=1) if s.size else np.zeros(t.shape[0], np.int64)
    return np.where(inside.any(axis=1), best, -1) if s.size else np.full(t.shape[0], -1)


@torch.no_grad()
def corrected_renders(state: FusionState, scene: Scene, times, log_gain: torch.Tensor, n_samples: int,
                      eps: float, grey_weights: tuple[float, float, float], backend: str = "auto",
                      colour: tuple[np.ndarray, np.ndarray] | None = None, iterations: int = 0,
                      between: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sharp linear renders at ``times``, as rendered and exposure-ratio corrected.

    An instant inside a frame's exposure is corrected with that frame's ratio. With ``iterations``
    0 the ratio stays at each pixel over the exposure; with ``iterations >= 1`` it is attached to
    the scene's surfaces and carried by the fitted motion (:mod:`fusiongs.outputs.motion_ratio`, that
    many Richardson–Lucy iterations). An instant between two exposures is left as rendered, or
    with ``between`` (and ``iterations >= 1``) corrected with both frames' factors carried to it
    along the motion (:func:`factor_carried`), weighted linearly in time from the end of the one
    exposure (weight 1) to the start of the next (weight 0), so the correction is continuous at
    both. Instants before the first or after the last exposure stay as rendered.

    Args:
        state: the fitted scene, camera path.
        scene: its frames (``[F, H, W, C]``, C = 1 or 3) and camera.
        times: ``[T]`` instants (s).
        log_gain: ``[F]`` each frame's log exposure gain ``log g`` (on the state's device).
        n_samples: renders per exposure for the predicted blurry frame (the training's).
        eps: the ratio's linear offset (``output.ratio_eps``).
        grey_weights: ``w`` of a monochrome frame ``w · L``; its ratio scales all three channels.
        colour: ``(gain [3], offset [3])`` applied to every render (linear) before the ratio is
            taken (the one-frame colour anchor, :mod:`fusiongs.outputs.colour_anchor`); the corrected
            renders then carry it, the rendered ones do not.
        iterations: 0, or the iterations of the motion-carried ratio (``output.ratio_iterations``).
        between: correct the instants between two exposures too (``output.ratio_between``).

    Returns:
        ``(rendered, corrected, applied)``: ``[T, H, W, 3]`` float32 linear radiance (not clipped),
        and ``[T]`` bool, a ratio was applied.
    """
    fs = scene.frames
    times = np.asarray(times, np.float64).reshape(-1)
    frame = containing_frame(fs.t_start, fs.t_end, times) if len(fs) else np.full(times.size, -1)
    sides = between_frames(fs.t_start, fs.t_end, times) if between and iterations and len(fs) else None
    h, w = scene.camera.height, scene.camera.width
    rendered = np.zeros((times.size, h, w, 3), np.float32)
    corrected = np.zeros_like(rendered)
    applied = frame >= 0
    factors: dict[int, torch.Tensor] = {}

    def factor(i: int) -> torch.Tensor:
        if i not in factors:
            factors[i] = frame_factor(state, scene, i, log_gain, n_samples, eps, grey_weights, backend,
                                      iterations, colour)
        return factors[i]

    order = np.argsort(times, kind="stable")  # in time order, a frame's factor is needed only while near
    for j in range(0, times.size, 8):
        batch = order[j:j + 8]
        t = torch.as_tensor(times[batch])
        raw, _, _ = state.render(scene.camera, t, backend)
        lin = _coloured(raw, colour)
        rendered[batch] = corrected[batch] = raw.cpu().numpy()
        gap = np.zeros(batch.size, bool) if sides is None else (sides[batch, :2] >= 0).all(1)  # between two
        # the views' depth once per batch, and only when one of its instants gets a factor carried
        depth = state.render_depth(scene.camera, t, backend) if iterations and (
            (frame[batch] >= 0) | gap).any() else None
        for k, b in enumerate(batch):
            i, tk = int(frame[b]), t[k:k + 1]
            dk = None if depth is None else (depth[0][k:k + 1], depth[1][k:k + 1])
            if i >= 0:  # inside frame i's exposure
                fixed = lin[k] * (factor_carried(state, scene, factor(i), i, tk, backend, dk)[0]
                                  if iterations else factor(i))
            elif gap[k]:
                p, q, wp = int(sides[b, 0]), int(sides[b, 1]), float(sides[b, 2])
                at_p, at_q = (factor_carried(state, scene, factor(f), f, tk, backend, dk)[0] for f in (p, q))
                fixed = lin[k] * (wp * at_p + (1.0 - wp) * at_q)
                applied[b] = True
            else:
                continue
            corrected[b] = fixed.cpu().numpy()
            lowest = i if i >= 0 else p
            for old in [f for f in factors if f < lowest]:  # frames are in time order: no later
                del factors[old]                            # instant needs them (bounded memory)
    return rendered, corrected, applied


def between_frames(t_start: np.ndarray, t_end: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``[T, 3]`` for each instant outside every exposure: the frame whose exposure ended last before
    it, the frame whose exposure starts first after it (-1 where none), and the first one's weight
    ``(s_q - t) / (s_q - e_p)`` (1 at the end of its exposure, 0 at the start of the next). Rows of
    instants inside an exposure are ``(-1, -1, 0)``."""
    s, e = np.asarray(t_start, np.float64), np.asarray(t_end, np.float64)
    t = np.asarray(times, np.float64).reshape(-1)
    outside = containing_frame(s, e, t) < 0
    p = np.searchsorted(e, t, side="right") - 1  # frames are in time order, exposures disjoint
    q = np.searchsorted(s, t, side="left")
    q = np.where(q < s.size, q, -1)
    both = outside & (p >= 0) & (q >= 0)
    wp = np.where(both, (s[q] - t) / np.maximum(s[q] - e[np.maximum(p, 0)], 1e-12), 0.0)
    return np.stack([np.where(outside, p, -1), np.where(outside, q, -1), wp], 1).astype(np.float64)


def _coloured(raw: torch.Tensor, colour: tuple[np.ndarray, np.ndarray] | None) -> torch.Tensor:
    """Renders with the one-frame colour anchor applied, as it was fitted: on renders clipped to
    [0, 1] (``raw`` itself without one)."""
    if colour is None:
        return raw
    gain, offset = (torch.as_tensor(np.asarray(v, np.float32)).to(raw.device) for v in colour)
    return raw.clamp(0, 1) * gain + offset


def _observed(fs, i: int, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """Frame ``i`` linear ``[H, W, C]`` and its clipped pixels (bool, same shape), on ``device``."""
    encoded = np.asarray(fs.images[i], np.float32)
    linear = np.asarray(response_to_linear(encoded, fs.response), np.float32)
    return torch.as_tensor(linear).to(device), torch.as_tensor(encoded).to(device) >= SATURATED


def _grid_to_mid(state: FusionState, scene: Scene, i: int, times: torch.Tensor, backend: str,
                 depth: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
    """``[T, H, W, 2]`` where the views at ``times`` see frame ``i``'s mid-exposure pixels
    (:func:`~fusiongs.camera.reproject.reference_grid` on the fitted depth; ``depth``: the views'
    :meth:`~fusiongs.train.state.FusionState.render_depth`, rendered here when None)."""
    fs = scene.frames
    depth, alpha = state.render_depth(scene.camera, times, backend) if depth is None else depth
    t_mid = torch.tensor([0.5 * (fs.t_start[i] + fs.t_end[i])], dtype=torch.float64)
    return reference_grid(depth, alpha > 0.5, state.trajectory.c2w(times), state.trajectory.w2c(t_mid)[0],
                          scene.camera)


def _rgb(factor: torch.Tensor) -> torch.Tensor:
    """A factor ``[..., C]`` (C = 1 for a monochrome frame: it scales all three colours) as ``[..., 3]``."""
    return factor.expand(*factor.shape[:-1], 3)


def _factor(observed: torch.Tensor, saturated: torch.Tensor, renders: torch.Tensor, grid: torch.Tensor | None,
            gain: torch.Tensor, eps: float, iterations: int, grey_weights: tuple[float, float, float]
            ) -> torch.Tensor:
    """``[H, W, C]`` ρ of one frame: carried by the motion ``grid`` (``iterations`` >= 1,
    :func:`~fusiongs.outputs.motion_ratio.motion_ratio`) or per pixel (``grid`` None)."""
    if grid is not None:
        return motion_ratio(observed, renders, grid, gain, saturated, eps, iterations, grey_weights)
    predicted = renders.mean(0) * gain
    if observed.shape[-1] == 1:
        predicted = to_grey(predicted, grey_weights)
    return exposure_ratio(observed, predicted, saturated, eps)


@torch.no_grad()
def frame_factor(state: FusionState, scene: Scene, i: int, log_gain: torch.Tensor, n_samples: int, eps: float,
                 grey_weights: tuple[float, float, float], backend: str = "auto", iterations: int = 0,
                 colour: tuple[np.ndarray, np.ndarray] | None = None) -> torch.Tensor:
    """``[H, W, C]`` the factor ``ρ`` of frame ``i`` on its mid-exposure pixel grid, as
    :func:`corrected_renders` computes it (``log_gain``: ``[F]``, :func:`frame_log_gains`;
    ``colour``: the colour anchor, as there)."""
    fs = scene.frames
    t = exposure_instants(float(fs.t_start[i]), float(fs.t_end[i]), n_samples)
    lin = _coloured(state.render(scene.camera, t, backend)[0], colour)
    observed, saturated = _observed(fs, i, lin.device)
    grid = _grid_to_mid(state, scene, i, t, backend) if iterations else None
    return _factor(observed, saturated, lin, grid, torch.exp(log_gain[i]), eps, iterations, grey_weights)


@torch.no_grad()
def factor_carried(state: FusionState, scene: Scene, factor: torch.Tensor, i: int, times: torch.Tensor,
                   backend: str = "auto", depth: tuple[torch.Tensor, torch.Tensor] | None = None
                   ) -> torch.Tensor:
    """``[T, H, W, 3]`` frame ``i``'s factor (:func:`frame_factor`) where the views at ``times`` see the
    surfaces it is attached to: the detail of a frame carried along the fitted motion to other
    instants (the held-out prediction of ``--holdout``, :func:`fusiongs.pipeline.deblur.score_holdout`).
    ``depth``: ``(depth, alpha)`` of those views when the caller already rendered them
    (:meth:`~fusiongs.train.state.FusionState.render_depth`; carrying two frames' factors to the
    same instants needs them once)."""
    return _rgb(carry(factor, _grid_to_mid(state, scene, i, times, backend, depth)))


def frame_log_gains(state: FusionState, n_frames: int, kept: np.ndarray | None = None) -> torch.Tensor:
    """``[n_frames]`` log exposure gain of every frame of a scene, on the state's device.

    A run trained on the frames ``kept`` (``--holdout``) learned gains for those only; the others
    take the log of the mean learned gain (1 when gains are not learned). ``kept = None``: the run
    saw every frame, in order.
    """
    learned = state.log_gain.detach()
    if kept is None:
        return learned
    out = torch.log(learned.exp().mean()).expand(n_frames).clone() if learned.numel() \
        else torch.zeros(n_frames, device=learned.device)
    out[torch.as_tensor(np.asarray(kept, np.int64)).to(learned.device)] = learned
    return out
