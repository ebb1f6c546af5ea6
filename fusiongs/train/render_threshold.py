"""Thresholds read off the renders: a lower bound on θ checked when the events start.

When the event term starts, the model has been fitted to the blurred frames alone. Its renders at
the two ends of a window ``[t_a, t_b)`` give each pixel's log change ``d``, and the window's
counts say ``d ≈ θ₊ n₊ − θ₋ n₋`` (docs/method.md §2, EventNeRF Eq. 5). The least-squares θ of that
relation, per colour channel and polarity, is what the event loss itself would learn at this
render. A model fitted to blurred frames has at most the true contrast, usually less (fine detail
is still missing), so this θ reads low, not high: on the states of 26 tuning scenes when their
events started it was 31 % low in the geometric mean and at most 10 % high; low-passed by 3 px
(below), at most 17 % high. A calibration below it is then
too low, and a θ far below the truth makes the event term ask for less contrast than the frames
show (the events then cost PSNR). :func:`raise_to_render_floor` lifts each θ to that floor;
it cannot lower a calibration that is too high.

Counts that are lower bounds (the pixel hit its dead time in the window: ``TrainData.censored_map``)
are left out of the fit.

:func:`refined_thresholds` writes the raised θ as a calibration (``fusiongs calibrate --refine``,
``OUT/calibration_refined.json`` of ``deblur``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import kornia
import numpy as np
import torch

from fusiongs.events.thresholds import SensorThresholds
from fusiongs.losses.event import delta_log, select_channel
from fusiongs.train.data import TrainData


@dataclass(frozen=True)
class RenderFloor:
    """Thresholds fitted to the renders.

    Attributes:
        theta: ``[2, C]`` fitted θ (row 0 ON, row 1 OFF; NaN where a channel had too few pixels
            or the fit was not positive).
        pixels: ``[2, C]`` pixels with events of that polarity that entered the fit.
    """

    theta: torch.Tensor
    pixels: torch.Tensor


def window_sums(d: torch.Tensor, n_pos: torch.Tensor, n_neg: torch.Tensor, channel: torch.Tensor,
                keep: torch.Tensor, channels: int, sigma: float = 0.0) -> torch.Tensor:
    """Normal-equation sums of ``d ≈ θ₊ n₊ − θ₋ n₋`` per channel, optionally on low-passed maps.

    With ``sigma > 0`` each channel's kept pixels (zero elsewhere) are blurred by a Gaussian of
    ``sigma`` pixels on both sides of the relation, which stays exact under any linear filter:
    scales finer than the model resolves yet leave the fit, and the counts' quantisation averages
    out. The fit then runs over every pixel of the blurred maps.

    Args:
        d: ``[H, W]`` rendered log change; n_pos, n_neg: ``[H, W]`` counts; channel: ``[H, W]``
            int64 in ``[0, channels)``; keep: ``[H, W]`` bool (pixels that enter the fit).
        sigma: the low-pass's standard deviation in pixels; 0 for none.

    Returns:
        ``[7, C]``: Σn₊², Σn₊n₋, Σn₋², Σd n₊, Σd n₋ (over the maps, blurred or not), and the
        kept pixels with ON / OFF events.
    """
    masks = (channel[None] == torch.arange(channels, device=channel.device)[:, None, None]) & keep
    m = masks.to(d.dtype)  # [C, H, W]
    maps = torch.stack([d, n_pos, n_neg])[None] * m[:, None]  # [C, 3, H, W]
    if sigma > 0:
        k = 2 * math.ceil(3 * sigma) + 1
        maps = kornia.filters.gaussian_blur2d(maps, (k, k), (sigma, sigma), border_type="constant")
    dd, pp, nn = maps.flatten(2).unbind(1)  # [C, H W] each
    fired = torch.stack([(m * (n_pos > 0)).flatten(1).sum(1), (m * (n_neg > 0)).flatten(1).sum(1)])
    return torch.cat([torch.stack([(pp * pp).sum(1), (pp * nn).sum(1), (nn * nn).sum(1),
                                   (dd * pp).sum(1), (dd * nn).sum(1)]), fired])


def solve_floor(sums: torch.Tensor, min_pixels: int) -> RenderFloor:
    """θ₊, θ₋ per channel from :func:`window_sums` (summed over windows): the 2x2 least squares
    ``[[Σn₊², −Σn₊n₋], [−Σn₊n₋, Σn₋²]] [θ₊, θ₋] = [Σd n₊, −Σd n₋]``, solved in closed form.
    NaN where either polarity has fewer than ``min_pixels`` pixels or a θ is not positive."""
    pp, pn, nn, dp, dn, cp, cn = sums
    det = pp * nn - pn * pn
    th_pos = (dp * nn - dn * pn) / det
    th_neg = (dp * pn - dn * pp) / det
    theta = torch.stack([th_pos, th_neg])
    pixels = torch.stack([cp, cn])
    ok = (pixels >= min_pixels).all(0) & (theta > 0).all(0) & torch.isfinite(theta).all(0)
    return RenderFloor(torch.where(ok, theta, torch.full_like(theta, float("nan"))), pixels)


def render_floor(state, data: TrainData, windows: list[tuple[float, float]], grey_weights,
                 log_eps: float, backend: str = "auto", min_pixels: int = 200,
                 batch: int = 8, sigma: float = 0.0) -> RenderFloor:
    """Fit ``θ₊, θ₋`` per channel to the counts of ``windows`` from the state's renders.

    Args:
        state: a :class:`~fusiongs.train.state.FusionState` (rendered without gradients).
        data: the training data (events, CFA, censored counts).
        windows: ``(t_a, t_b)`` seconds (:func:`~fusiongs.train.schedules.sample_free_windows`).
        grey_weights, log_eps: as the event loss (``events.grey_weights``, ``events.log_eps``).
        min_pixels: fewest pixels with events of each polarity for a channel's fit.
        batch: windows rendered at once.
        sigma: low-pass of both sides (pixels; :func:`window_sums`).

    Returns:
        :class:`RenderFloor` with ``[2, C]`` tensors on the state's device (C = 1 grey, 3 CFA).
    """
    channels = 1 if data.cfa_index is None else 3
    h, w = data.camera.height, data.camera.width
    device = data.targets.device
    ch = (torch.zeros(h, w, dtype=torch.long, device=device) if data.cfa_index is None
          else data.cfa_index.to(device))
    sums = torch.zeros(7, channels, dtype=torch.float64, device=device)
    for i in range(0, len(windows), batch):
        chunk = windows[i:i + batch]
        t = torch.tensor([x for w in chunk for x in w], dtype=torch.float64, device="cpu")
        with torch.no_grad():
            lin, _, _ = state.render(data.camera, t, backend, check_values=False)
        lin = lin.reshape(len(chunk), 2, -1, 3)
        for (t_a, t_b), pair in zip(chunk, lin):
            if data.cfa_index is None:
                d = delta_log(pair[0], pair[1], "grey", grey_weights, log_eps)[:, 0]
            else:
                d = select_channel(delta_log(pair[0], pair[1], "rgb", eps=log_eps), ch.reshape(-1))[:, 0]
            d = d.reshape(h, w).double()
            counts = data.count_maps(t_a, t_b, device).double()
            cens = data.censored_map(t_a, t_b)
            keep = torch.ones_like(d, dtype=torch.bool) if cens is None else ~cens.to(device)
            sums += window_sums(d, counts[0], counts[1], ch, keep, channels, sigma)
    return solve_floor(sums, min_pixels)


def raise_to_render_floor(log_theta: torch.Tensor, floor: RenderFloor) -> torch.Tensor:
    """``[2, C]`` log θ raised to ``log floor.theta`` where that is larger (and known);
    a one-channel floor applies to every channel."""
    f = torch.log(floor.theta).to(log_theta.dtype).expand_as(log_theta)
    return torch.where(torch.isfinite(f) & (f > log_theta), f, log_theta)


def apply_render_floor(state, data: TrainData, cfg) -> tuple[torch.Tensor, torch.Tensor] | None:
    """Raise the state's scalar log θ to the renders' floor (``threshold.render_floor``), once,
    when the events start; the windows come from their own generator (``cfg.seed``), so the
    training draws are the same with and without it.

    Returns:
        ``(θ before, θ after)`` as ``[2, C]`` host tensors, or None where it does not apply (no
        events, fewer than 2 frames: the renders' scale is then not the frames').
    """
    from fusiongs.train.schedules import sample_free_windows
    from fusiongs.train.step import longest_free_window

    if data.events is None or data.n_frames < 2:
        return None
    gen = torch.Generator(device="cpu").manual_seed(cfg.seed)
    ev = cfg.events
    longest = longest_free_window(cfg, data)
    windows = sample_free_windows(cfg.threshold.render_floor_windows, data.t_range, longest, gen,
                                  min(ev.min_window, longest), spacing="linear").tolist()
    floor = render_floor(state, data, windows, ev.grey_weights, ev.log_eps, cfg.backend,
                         sigma=cfg.threshold.render_floor_sigma)
    log_theta = state.threshold.log_theta
    before = torch.exp(log_theta.detach()).cpu()
    with torch.no_grad():
        log_theta.copy_(raise_to_render_floor(log_theta.detach(), floor))
    return before, torch.exp(log_theta.detach()).cpu()


# One-sigma relative uncertainty of a θ the floor raised: the raised θ's rms log error over the 26
# tuning scenes was 0.112 (the same 12 % as a calibration whose
# refractory gate fell back, CalibrateOptions.systematic_fallback).
REFINED_SYSTEMATIC = 0.12


def refined_thresholds(calibration: SensorThresholds, before: torch.Tensor, after: torch.Tensor,
                       **details) -> SensorThresholds:
    """The calibration with the θ that :func:`raise_to_render_floor` raised put in, as a calibration.

    Args:
        calibration: where θ started (its channels match the trainer's: one grey, or R, G, B).
        before, after: ``[2, C]`` θ before and after the floor (row 0 ON, row 1 OFF).
        details: recorded under ``details["refine"]`` (iterations, windows, low-pass, ...).

    Returns:
        :class:`SensorThresholds` whose raised entries carry a ``REFINED_SYSTEMATIC`` relative
        one-sigma (the others keep the calibration's), ``method`` "<calibration's> + render floor"
        and ``details["refine"]`` with θ before and which entries were raised.
    """
    b = before.detach().double().cpu().numpy()
    a = after.detach().double().cpu().numpy()
    if a.shape != (2, calibration.n_channels) or b.shape != a.shape:
        raise ValueError(f"thresholds of shape {tuple(a.shape)} for a {calibration.n_channels}-channel "
                         "calibration")
    raised = a > b
    std = np.stack([calibration.std_pos, calibration.std_neg])
    std = np.where(raised, REFINED_SYSTEMATIC * a, std)
    info = {"method": "render_floor", "before": b.tolist(), "raised": raised.tolist(),
            "systematic": REFINED_SYSTEMATIC, **details}
    return SensorThresholds(calibration.channels, a[0], a[1], std[0], std[1], calibration.scale_known,
                            f"{calibration.method} + render floor", {**calibration.details, "refine": info})
