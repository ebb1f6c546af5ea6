"""The low-pass event term of one step: long windows between the ends of its free windows.

A step renders the two ends of each free window (:func:`fusiongs.train.step.training_step`); any
two ends of *different* windows also bound a window, usually a long one (a third of the recording
on average), at no extra render. Its counts are compared after a spatial low-pass
(:func:`fusiongs.losses.event_lowpass.event_loss_lowpass`), so what they know about large-scale
levels (a plain wall against the objects in front of it) reaches the model without the per-pixel
threshold mismatch that makes long windows harmful pixel by pixel (benchmarks/RESULTS.md,
session 14).
"""

from __future__ import annotations

import numpy as np
import torch

from fusiongs.events.stats import spatial_hot_pixels
from fusiongs.losses.event import log_intensity, select_channel
from fusiongs.losses.event_lowpass import event_loss_lowpass, full_support
from fusiongs.train.data import TrainData, square_dilate
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.state import FusionState


def hot_map(data: TrainData, device: torch.device) -> torch.Tensor:
    """``[H, W]`` bool hot pixels of the stream (spatial outliers of the event count,
    :func:`fusiongs.events.stats.spatial_hot_pixels`), computed once and kept in ``data``."""
    if data.hot is None:
        h, w = data.camera.height, data.camera.width
        hot = spatial_hot_pixels(data.events).reshape(h, w)
        # non_blocking: a pageable source is staged by the copy itself, and the host does not wait
        # for the queue (the first step's only synchronisation otherwise, caught on CUDA)
        data.hot = torch.from_numpy(np.ascontiguousarray(hot)).to(device, non_blocking=True)
    return data.hot


def support_map(data: TrainData, sigma: float, device: torch.device) -> torch.Tensor:
    """:func:`fusiongs.losses.event_lowpass.full_support` of the sensor, computed once per
    ``sigma`` and kept in ``data`` (it depends only on the pixel grid and the CFA)."""
    if data.lowpass_support is None or data.lowpass_support[0] != sigma:
        channels = 1 if data.cfa_index is None else 3
        data.lowpass_support = (sigma, full_support(data.cfa_index, channels, sigma, data.camera.height,
                                                    data.camera.width, device))
    return data.lowpass_support[1]


def cross_pairs(ends: list[tuple[int, float, int]], min_length: float) -> list[tuple[int, int, float, float]]:
    """Pairs of window ends from different windows, in time order, at least ``min_length`` s apart.

    Args:
        ends: ``(render index, t seconds, window)`` of each rendered window end.

    Returns:
        ``(render index at t_a, render index at t_b, t_a, t_b)`` with ``t_a < t_b``.
    """
    out = []
    for i, (ja, ta, wa) in enumerate(ends):
        for jb, tb, wb in ends[i + 1:]:
            if wa == wb or abs(tb - ta) < min_length:
                continue
            out.append((ja, jb, ta, tb) if ta < tb else (jb, ja, tb, ta))
    return out


def lowpass_term(state: FusionState, data: TrainData, cfg: DeblurConfig, lin: torch.Tensor,
                 ends: list[tuple[int, float, int]], min_length: float) -> torch.Tensor | None:
    """Low-pass event loss (:func:`fusiongs.losses.event_lowpass.event_loss_lowpass`) of the
    :func:`cross_pairs` of the step's window ends, from its whole-sensor linear renders
    ``lin [T, H, W, 3]`` (grey sensor, or each pixel's own CFA channel: the raw grid, whatever
    ``events.colour_mode``); None when there is no such pair."""
    pairs = cross_pairs(ends, min_length)
    if not pairs:
        return None
    ev = cfg.events
    device = lin.device
    h, w = data.camera.height, data.camera.width
    pix = torch.arange(h * w, device=device)
    times = sorted({t for _, t, _ in ends})
    rank = {t: k for k, t in enumerate(times)}
    # one small host-to-device copy: each pair's renders and count rows
    rows = torch.tensor([[a for a, *_ in pairs], [b for _, b, *_ in pairs],
                         [rank[ta] for *_, ta, _ in pairs], [rank[tb] for *_, tb in pairs]],
                        device="cpu").to(device, non_blocking=True)
    flat = lin.reshape(lin.shape[0], -1, 3)  # [T, P, 3]
    t_mid = 0.5 * (pairs[0][2] + pairs[0][3])  # a drifting θ is taken at the first pair's middle
    if data.cfa_index is None:  # each render's log once; a pair's change is a difference of two
        logs = log_intensity(flat, "grey", ev.grey_weights, ev.log_eps)[..., 0]  # [T, P]
        th_p, th_n = state.threshold.theta(pix, t=t_mid)
        channel, channels = None, 1
    else:
        ch = data.cfa_index.reshape(-1)
        logs = select_channel(log_intensity(flat, "rgb", eps=ev.log_eps), ch)[..., 0]  # [T, P]
        th_p, th_n = state.threshold.theta(pix, t=t_mid, channel=ch)
        channel, channels = data.cfa_index, 3
    d = logs[rows[1]] - logs[rows[0]]  # [B, P]: delta_log of each pair
    cum, cum_fast = data.cumulative_counts(times, device)  # [K, 2, P], [K, P] | None
    counts = cum[rows[3]] - cum[rows[2]]  # [B, 2, P]: count_maps of each pair
    target = th_p[:, 0] * counts[:, 0] - th_n[:, 0] * counts[:, 1]  # [B, P]
    valid = (~hot_map(data, device)).expand(len(pairs), h, w)
    if cum_fast is not None:  # censored_map of each pair
        fast = (cum_fast[rows[3]] - cum_fast[rows[2]]).reshape(-1, h, w)
        valid = valid & ~(square_dilate(fast, ev.censor_radius) > 0)
    scale = 0.5 * (th_p.detach().mean() + th_n.detach().mean())
    return event_loss_lowpass(d.reshape(-1, h, w), target.reshape(-1, h, w), valid, channel, channels,
                              ev.lowpass_sigma, scale, support=support_map(data, ev.lowpass_sigma, device))
