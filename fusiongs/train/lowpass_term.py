"""The low-pass event term of one step: long windows between the ends of its free windows.

A step renders the two ends of each free window (:func:`fusiongs.train.step.training_step`); any
two ends of *different* windows also bound a window, usually a long one (a third of the recording
on average), at no extra render. Its counts are compared after a spatial low-pass
(:func:`fusiongs.losses.event_lowpass.event_loss_lowpass`), so what they know about large-scale
levels (a plain wall against the objects in front of it) reaches the model without the per-pixel
threshold mismatch that makes long windows harmful pixel by pixel.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import torch

from fusiongs.events.dead_time import spatial_hot_pixels
from fusiongs.losses.event import log_intensity, select_channel
from fusiongs.losses.event_lowpass import event_loss_lowpass, full_support
from fusiongs.train.data import TrainData, square_dilate
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.state import FusionState


def hot_map(data: TrainData, device: torch.device) -> torch.Tensor:
    """``[H, W]`` bool hot pixels of the stream (spatial outliers of the event count,
    :func:`fusiongs.events.dead_time.spatial_hot_pixels`), computed once and kept in ``data``."""
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


class LowpassHistory:
    """The window ends of the last ``steps`` training steps: ``(t seconds, log image [H*W])``, the
    log intensity each pixel's own channel saw (detached), oldest first; each step's ends replace
    the oldest step's once ``steps`` are kept."""

    def __init__(self, steps: int):
        self.steps = int(steps)
        self._rows: deque[list[tuple[float, torch.Tensor]]] = deque(maxlen=max(self.steps, 1))

    def ends(self) -> list[tuple[float, torch.Tensor]]:
        """Every kept end, oldest step first."""
        return [row for step in self._rows for row in step]

    def push(self, ends: list[tuple[float, torch.Tensor]]) -> None:
        """Keep one step's ends: ``(t seconds, log image [H*W])`` each (kept detached)."""
        if self.steps > 0:
            self._rows.append([(t, row.detach()) for t, row in ends])


def cross_pairs(ends: list[tuple[int, float, int]], min_length: float,
                n_current: int | None = None) -> list[tuple[int, int, float, float]]:
    """Pairs of window ends from different windows, in time order, at least ``min_length`` s apart.

    Args:
        ends: ``(render index, t seconds, window)`` of each rendered window end.
        n_current: when given, render indices from it on are kept ends of earlier steps
            (:class:`LowpassHistory`), and a pair of two such ends is left out (it has no gradient).

    Returns:
        ``(render index at t_a, render index at t_b, t_a, t_b)`` with ``t_a < t_b``.
    """
    out = []
    for i, (ja, ta, wa) in enumerate(ends):
        for jb, tb, wb in ends[i + 1:]:
            if wa == wb or abs(tb - ta) < min_length:
                continue
            if n_current is not None and ja >= n_current and jb >= n_current:
                continue
            out.append((ja, jb, ta, tb) if ta < tb else (jb, ja, tb, ta))
    return out


def own_logs(data: TrainData, cfg: DeblurConfig, lin: torch.Tensor) -> torch.Tensor:
    """``[T, H*W]`` log intensity of linear renders ``[T, H, W, 3]`` as each pixel sees it (grey
    sensor, or the pixel's own CFA channel)."""
    ev = cfg.events
    flat = lin.reshape(lin.shape[0], -1, 3)  # [T, P, 3]
    if data.cfa_index is None:
        return log_intensity(flat, "grey", ev.grey_weights, ev.log_eps)[..., 0]
    # the channel first, then its log: a third of the logs (and of their backward)
    return log_intensity(select_channel(flat, data.cfa_index.reshape(-1)), "rgb", eps=ev.log_eps)[..., 0]


def lowpass_term(state: FusionState, data: TrainData, cfg: DeblurConfig, lin: torch.Tensor,
                 ends: list[tuple[int, float, int]], min_length: float,
                 history: LowpassHistory | None = None) -> torch.Tensor | None:
    """Low-pass event loss (:func:`fusiongs.losses.event_lowpass.event_loss_lowpass`) of the
    :func:`cross_pairs` of the step's window ends, from its whole-sensor linear renders
    ``lin [T, H, W, 3]`` (grey sensor, or each pixel's own CFA channel: the raw grid, whatever
    ``events.colour_mode``); None when there is no such pair.

    With ``history``, the kept ends of earlier steps take part too (pairs with a current end
    only), and this step's ends are then kept in it."""
    ev = cfg.events
    device = lin.device
    h, w = data.camera.height, data.camera.width
    past = [] if history is None else history.ends()
    current = ends
    if past:
        n_win = 1 + max(k for *_, k in ends)  # past ends: one window each, after the current ones
        ends = ends + [(len(lin) + i, t, n_win + i) for i, (t, _) in enumerate(past)]
    pairs = cross_pairs(ends, min_length, len(lin) if past else None)
    if not pairs and history is None:
        return None  # nothing to compare and nothing to keep: no logs taken
    logs = own_logs(data, cfg, lin)  # [T, P]: each render's log once, a pair's change a difference
    if history is not None:
        rows = logs.unbind(0)  # no index tensor (a host-to-device copy)
        history.push([(t, rows[j]) for j, t, _ in current])
    if not pairs:
        return None
    if past:
        logs = torch.cat([logs, torch.stack([row for _, row in past])])
    pix = torch.arange(h * w, device=device)
    times = sorted({t for _, t, _ in ends})
    rank = {t: k for k, t in enumerate(times)}
    # one small host-to-device copy: each pair's renders and count rows
    rows = torch.tensor([[a for a, *_ in pairs], [b for _, b, *_ in pairs],
                         [rank[ta] for *_, ta, _ in pairs], [rank[tb] for *_, tb in pairs]],
                        device="cpu").to(device, non_blocking=True)
    t_mid = 0.5 * (pairs[0][2] + pairs[0][3])  # a drifting θ is taken at the first pair's middle
    if data.cfa_index is None:
        th_p, th_n = state.threshold.theta(pix, t=t_mid)
        channel, channels = None, 1
    else:
        th_p, th_n = state.threshold.theta(pix, t=t_mid, channel=data.cfa_index.reshape(-1))
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
