"""The low-pass term pair by pair, as first written: each cross pair's own ``count_maps``,
``censored_map`` and ``delta_log``. Obviously correct and slower (every long window's events are
added again); the specification :func:`fusiongs.train.lowpass_term.lowpass_term` is compared
against (tests/train/test_lowpass_term.py, benchmarks/bench_lowpass_term.py); training does not
call it."""

from __future__ import annotations

import torch

from fusiongs.losses.event import delta_log, select_channel
from fusiongs.losses.event_lowpass import event_loss_lowpass
from fusiongs.train.data import TrainData
from fusiongs.train.lowpass_term import cross_pairs, hot_map
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.state import FusionState


def lowpass_term_pairwise(state: FusionState, data: TrainData, cfg: DeblurConfig, lin: torch.Tensor,
                          ends: list[tuple[int, float, int]], min_length: float,
                          n_current: int | None = None) -> torch.Tensor | None:
    """:func:`~fusiongs.train.lowpass_term.lowpass_term` (same arguments and result), one window
    pair at a time. Kept ends of earlier steps are given as renders: ``lin[n_current:]`` (detached),
    with their own windows in ``ends`` (see :func:`~fusiongs.train.lowpass_term.cross_pairs`)."""
    pairs = cross_pairs(ends, min_length, n_current)
    if not pairs:
        return None
    ev, device = cfg.events, lin.device
    h, w = data.camera.height, data.camera.width
    pix = torch.arange(h * w, device=device)
    a_idx = torch.tensor([a for a, *_ in pairs], device=device)
    b_idx = torch.tensor([b for _, b, *_ in pairs], device=device)
    la, lb = lin[a_idx].reshape(len(pairs), -1, 3), lin[b_idx].reshape(len(pairs), -1, 3)
    t_mid = 0.5 * (pairs[0][2] + pairs[0][3])
    if data.cfa_index is None:
        d = delta_log(la, lb, "grey", ev.grey_weights, ev.log_eps)[..., 0]
        th_p, th_n = state.threshold.theta(pix, t=t_mid)
        channel, channels = None, 1
    else:
        ch = data.cfa_index.reshape(-1)
        d = select_channel(delta_log(la, lb, "rgb", eps=ev.log_eps), ch)[..., 0]
        th_p, th_n = state.threshold.theta(pix, t=t_mid, channel=ch)
        channel, channels = data.cfa_index, 3
    counts = torch.stack([data.count_maps(ta, tb, device).reshape(2, -1) for *_, ta, tb in pairs])
    target = th_p[:, 0] * counts[:, 0] - th_n[:, 0] * counts[:, 1]
    valid = (~hot_map(data, device)).expand(len(pairs), h, w)
    cens = [data.censored_map(ta, tb, ev.censor_radius) for *_, ta, tb in pairs]
    if cens[0] is not None:
        valid = valid & ~torch.stack(cens)
    scale = 0.5 * (th_p.detach().mean() + th_n.detach().mean())
    return event_loss_lowpass(d.reshape(-1, h, w), target.reshape(-1, h, w), valid, channel, channels,
                              ev.lowpass_sigma, scale)
