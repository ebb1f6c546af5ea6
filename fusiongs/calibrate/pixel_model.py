"""Which pixel model a recording's events follow, measured from the frames (see :mod:`.estimate`).

A DVS pixel held in reset during its dead time ``d`` (Lichtsteiner et al., IEEE JSSC 2008) loses
the change of its blind time: an event ``Δt`` after its pixel's previous one stands for
``w = Δt / (Δt - d)`` crossings (:func:`fusiongs.events.dead_time.reset_weights`). A pixel whose level
keeps every crossing loses only the events themselves, and outside its fastest pairs (which the
refractory gate leaves out) each event stands for one crossing. So between two frames

    ``log L_j - log L_i = theta_+ (N_+ + beta E_+) - theta_- (N_- + beta E_-) + b_ij``

with ``N`` the plain counts, ``E = sum (w - 1)`` the crossings the reset model adds, and ``beta``
= 1 for a reset pixel, 0 for the other. :func:`excess_coefficient` estimates ``beta`` from the
frames, one value for all channels and both polarities, by the same instrumental variables as the
threshold fit (:func:`fusiongs.calibrate.fit.iv_thresholds`): the neighbours' counts and
excesses instrument the pixel's. Per channel, it is too noisy on a Bayer sensor's sparse red and
blue pixels (tuning scenes: -0.4 to 3.3 on one reset pixel); pooled, it separates the two
simulated pixels on every tuning scene where either model's fit holds.

A criterion that compares how well each model's counts correlate with the frames (the fits'
agreement) cannot do this: noisier weighted counts lower the correlation even when they are right.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import torch

from fusiongs.calibrate.data import (
    channel_pixels,
    count_inputs,
    gate_inputs,
    prepare_channel,
    saturated,
    sensor_intensity,
)
from fusiongs.calibrate.fit import (
    PairData,
    _identified,
    iv_columns,
    iv_thresholds,
    log_sharp,
    moment_rows,
    search_thresholds,
)
from fusiongs.errors import InputError
from fusiongs.events.dead_time import reset_weights
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet

if TYPE_CHECKING:
    from fusiongs.calibrate.options import CalibrateOptions


def excess_coefficient(channels: list[tuple[PairData, PairData, tuple[float, float]]],
                       iters: int = 4) -> float:
    """The coefficient ``beta`` of the reset model's extra crossings, pooled over channels.

    Args:
        channels: per channel ``(plain, weighted, (theta_+, theta_-))``: the same pixels, pairs and
            gate with plain counts and with reset-weighted counts (their difference is ``E``), and
            a starting estimate of the channel's thresholds (from the plain counts).
        iters: re-solves (the EDI term of the log change depends on ``beta`` and the thresholds).

    Returns:
        ``beta`` (dimensionless; about 1 for a reset pixel, 0 for one whose level keeps every
        crossing), NaN when there is no channel, the pooled system is singular, or a channel's
        thresholds come out non-positive.

    One block IV system: per channel its ON and OFF thresholds and the two indicator offsets of
    :func:`~fusiongs.calibrate.fit.iv_thresholds` (each channel with its own per-pair offset),
    and one shared coefficient on ``theta_+ E_+ - theta_- E_-`` (the current thresholds held
    fixed inside that regressor).
    """
    n_ch = len(channels)
    if n_ch == 0:
        return float("nan")
    theta = [tuple(float(v) for v in start) for _, _, start in channels]
    beta = 0.0
    k = 4 * n_ch + 1
    for _ in range(iters):
        system = torch.zeros(k, k + 1, dtype=torch.float64)
        for c, (plain, weighted, _) in enumerate(channels):
            tp, tn = theta[c]
            mixed = replace(plain, n=plain.n + beta * (weighted.n - plain.n))
            log_l = log_sharp(mixed, tp, tn)
            y = log_l[plain.pairs[:, 1]] - log_l[plain.pairs[:, 0]]
            ex, ez = weighted.dn - plain.dn, weighted.z - plain.z  # [Q, 2, P]
            xs, zs = iv_columns(plain, y.dtype)
            xs.append(tp * ex[:, 0] - tn * ex[:, 1])
            zs.append(tp * ez[:, 0] - tn * ez[:, 1])
            m = moment_rows(y, xs, zs, plain.valid).sum(0)  # [5, 6]
            rows = torch.tensor(list(range(4 * c, 4 * c + 4)) + [k - 1])
            system[rows[:, None], torch.cat([rows, torch.tensor([k])])] += m
        idx = _identified(system[None])
        if (k - 1) not in idx.tolist():
            return float("nan")
        sol, info = torch.linalg.solve_ex(system[idx[:, None], idx], system[idx, -1])
        if int(info) != 0 or not bool(torch.isfinite(sol).all()):
            return float("nan")
        full = dict(zip(idx.tolist(), sol.tolist()))
        theta = [(full[4 * c], full[4 * c + 1]) for c in range(n_ch)]
        if not all(np.isfinite(t).all() and min(t) > 0 for t in theta):
            return float("nan")
        beta = full[k - 1]
    return float(beta)


def excess_test(frames: FrameSet, lin: np.ndarray, events: EventStream, hot: np.ndarray,
                chan: np.ndarray, names: tuple[str, ...], opts: CalibrateOptions,
                dead: float) -> dict:
    """The pixel model's test of ``pixel_model="auto"``: the frames' coefficient on the crossings a
    reset pixel's events would add (:func:`excess_coefficient`), pooled over the channels with at
    least ``opts.excess_min_pairs`` gated pixel pairs; plain and weighted counts on the same pixels
    with the gate at the dead time ``dead`` (µs).

    Returns:
        ``{"coefficient": beta or None, "channels": names used, "dead_time_us", "cut", "max"}``.
    """
    rng = np.random.default_rng(opts.seed)
    weights = reset_weights(events, dead, opts.reset_weight_cap, opts.reset_burst_end)
    sens = sensor_intensity(lin, events.cfa)
    sat = saturated(lin, opts)
    plain, weighted = count_inputs(frames, events, opts, None), count_inputs(frames, events, opts, weights)
    _, _, bad_pair = gate_inputs(frames, events, opts, dead)
    # A coarse start is enough: the IV re-solves from it (the coefficient, the model kept and the
    # estimate were those of the full grid's start on 30 tuning and test scenes; benchmarks/RESULTS.md).
    quick = replace(opts, bootstrap=0, coarse_pixels=min(opts.coarse_pixels, 1000),
                    coarse_steps=min(opts.coarse_steps, 9))
    used, channels = [], []
    for c, name in enumerate(names):
        try:
            sel, frame_ok = channel_pixels(sens, sat, plain[1], chan, hot, c, name, opts, rng)
        except InputError:
            continue
        d0, d1 = (prepare_channel(sens, *inp[:2], sel, bad_pair, frame_ok, events.width, opts.tile,
                                  opts.max_gap, inp[2]) for inp in (plain, weighted))
        if int(d0.valid.sum()) < opts.excess_min_pairs:
            continue
        start = search_thresholds(d0, quick, rng, count_units=False, refine=False)
        fit = iv_thresholds(d0, (start["theta_pos"], start["theta_neg"]), quick, rng)
        used.append(name)
        channels.append((d0, d1, (fit["theta_pos"], fit["theta_neg"])))
    beta = excess_coefficient(channels)
    return {"coefficient": beta if np.isfinite(beta) else None, "channels": used,
            "dead_time_us": dead, "cut": opts.excess_cut, "max": opts.excess_max}
