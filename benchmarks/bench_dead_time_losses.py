"""Which event counts a sensor's dead time cuts short, and which of them the censoring marks.

Issue 18 (RESULTS.md, session 31). A scene written by ``fusiongs simulate`` is re-run through the
DVS pixel model twice at its own thresholds (per-pixel draws, threshold scale and leak as in
``gt/sim.json``), with its refractory period and without it; noise events are left out, so the
second stream is the first one's crossings with none lost (the model keeps the dropped crossings'
reference, so the first stream is a subset of the second). Windows are then drawn as event-only
training draws them (log-uniform from 1 ms to the time an average pixel takes to fire 4 events)
and every pixel's signed count is compared between the two streams:

- *wrong*: an active pixel-window whose count differs (events were lost in it);
- *missed*: a wrong one that a censoring rule does not mark as a lower bound. Rules: the
  default (a fast event, closer than 2 dead times to its pixel's previous one, in the window,
  ``events.censor 2``), the same with each fast event's predecessor marking too, and with the
  fast events' neighbours within 1 or 2 pixels (``events.censor_radius``); and, as the bound a
  model of the losses could reach, every window that meets a render step in which the true log
  intensity changes by more than one threshold per dead time (the simulator's truth: no run on a
  real sensor can know it);
- *censored*: the share of active pixel-windows a rule marks (information given up);
- the count corrections a stream alone allows, on the uncensored windows: the non-paralysable
  dead-time law ``n / (1 - n r / T)``, and half or all of each event's bound ``r / (dt - r)``
  (at most 3) on the crossings lost before it (all of it is exact for a reset pixel at a steady
  rate, ``DVSParams.refractory_reset``); mean shortfall (true minus estimate) and mean absolute error.

A third table predicts each window's emitted count from the true log intensities at its two ends
alone, as training sees a window (two renders): the plain ``ΔL / θ``, and the dead-time laws of
:func:`dead_time_count` (an edge whose intensity, not its log, moves linearly over the window;
a pixel that resets its reference after the dead time, or the simulator's, which keeps it); and,
from the log intensity inside the window (:func:`path_count`), the law along the truth's own
1 kHz renders (the best a model of the rate could know) and over 4 or 8 equal steps (what 5 or
9 renders a window would show). Mean absolute error against the emitted count, over the active
pixel-windows and over those that lost crossings.

The default rule is the reference every row is compared with. Grey and colour sensors alike (each
pixel sees its own channel's log intensity, as the simulator's sensor does).

    PYTHONPATH=. python benchmarks/bench_dead_time_losses.py SCENE [--windows 300] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch (numba's spinning threads)

import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_event_only_diagnose import TrueLog, sim_config, true_logs  # noqa: E402
from fusiongs.events.stats import fast_event_mask  # noqa: E402
from fusiongs.events.stream import EventStream  # noqa: E402
from fusiongs.train.data import square_dilate  # noqa: E402


def pixel_streams(scene: Path) -> dict:
    """Pixel events of ``scene`` with and without its refractory period, at its thresholds:
    ``{"dead": (t, pixel, p), "clean": (t, pixel, p), "width", "height", "dead_us", "duration_s"}``
    (t in µs from the recording's start), by the scene's own pixel model. The dense renders are
    :func:`benchmarks.bench_event_only_diagnose.true_logs` (cached in ``scene/gt/true_logs.npz``,
    the only file this benchmark writes)."""
    from fusiongs.sim.simulate import _pixel_events, sensor_draws

    cfg = sim_config(scene)
    scale = float(json.loads((scene / "gt" / "sim.json").read_text())["threshold_scale"])
    seeds = np.random.SeedSequence(cfg.seed).spawn(7)  # the simulator's streams
    times, logs = true_logs(scene)  # the simulator's dense renders (cached in the scene's gt/)
    th_on, th_off, drift, phase = sensor_draws(cfg.dvs, logs.shape[1], cfg.width, seeds)
    out = {"width": cfg.width, "height": cfg.height, "dead_us": cfg.dvs.refractory_s * 1e6,
           "logs": logs, "theta": (th_on * scale, th_off * scale), "reset": cfg.dvs.refractory_reset,
           "duration_s": float(cfg.duration), "times": times,
           "true_fast": true_fast_steps(logs, times, th_on * scale, th_off * scale, cfg.dvs.refractory_s)}
    for name, r in (("dead", cfg.dvs.refractory_s), ("clean", 0.0)):  # the scene's own pixel model
        out[name] = _pixel_events(logs, times, th_on * scale, th_off * scale, r, drift, phase, scale,
                                  cfg.dvs.refractory_reset)
    return out


def true_fast_steps(logs: np.ndarray, times: np.ndarray, th_on: np.ndarray, th_off: np.ndarray,
                    dead_s: float) -> np.ndarray:
    """``[K, P]`` int32 cumulative count of render steps (``logs [K, P]`` at ``times [K]``) in which
    the true log intensity of a pixel changes by more than one of its thresholds per dead time:
    the only places where the pixel model can lose a crossing (row ``k`` counts steps before
    ``times[k]``)."""
    d = np.diff(logs, axis=0)
    per_dead = np.abs(d) / np.where(d > 0, th_on, th_off) * (dead_s / (times[1] - times[0]))
    zero = np.zeros((1, logs.shape[1]), np.int32)
    return np.concatenate([zero, np.cumsum(per_dead > 1.0, axis=0, dtype=np.int32)])


def dead_time_count(log_a: np.ndarray, log_b: np.ndarray, dur_s: float, theta_on: np.ndarray,
                    theta_off: np.ndarray, dead_s: float, pixel: str = "grid") -> np.ndarray:
    """Expected signed count of a pixel whose log intensity goes from ``log_a`` to ``log_b`` (``[P]``,
    ``log(I + ε)``) over ``dur_s`` seconds, under a dead time of ``dead_s``.

    The intensity ``e = I + ε`` is taken to move linearly in time (an edge passing over a pixel
    that integrates its area), so the crossing rate is ``r = |ė| / (θ e)``, fastest where ``e`` is
    small. ``κ = |e_b − e_a| d / (T θ)`` is where ``r d = 1``. Two pixel models:

    - ``"reset"``: the reference is taken again when the dead time ends (a physical DVS pixel's
      reset), so events come at most every ``d + 1/r``, the non-paralysable law ``r / (1 + r d)``
      (e.g. Knoll, *Radiation Detection and Measurement*, ch. 4). Integrated:
      ``log((e_b + κ) / (e_a + κ)) / θ``.
    - ``"grid"``: the reference keeps every crossing and only events are dropped (this project's
      simulator, :func:`fusiongs.sim.dvs.dvs_events`): every ``ceil(r d)``-th crossing is emitted,
      on average ``r / (r d + 1/2)`` where ``r d > 1/2``. Integrated: ``(2/θ) log`` of
      ``(e + 2κ)`` over the part below ``e = 2κ`` plus the plain ``log e / θ`` above it.

    Both are the plain ``(log_b − log_a) / θ`` when ``d = 0``. ``θ`` is the ON threshold for a
    rise and the OFF one for a fall (``[P]`` each).
    """
    th = np.where(log_b > log_a, theta_on, theta_off)
    ea, eb = np.exp(log_a.astype(np.float64)), np.exp(log_b.astype(np.float64))
    kappa = np.abs(eb - ea) * dead_s / (max(dur_s, 1e-12) * th)
    if pixel == "reset":
        return (np.log(eb + kappa) - np.log(ea + kappa)) / th
    if pixel != "grid":
        raise ValueError(f"pixel: expected 'reset' or 'grid', got {pixel!r}")
    lo, hi, b = np.minimum(ea, eb), np.maximum(ea, eb), 2.0 * kappa
    m = np.clip(b, lo, hi)
    n = (2.0 * np.log((m + b) / (lo + b)) + np.log(hi / m)) / th
    return np.where(eb >= ea, n, -n)


def path_count(truth: TrueLog, t_a: float, t_b: float, theta_on: np.ndarray, theta_off: np.ndarray,
               dead_s: float, pixel: str = "grid", renders: int | None = None) -> np.ndarray:
    """Expected signed count of each pixel over ``[t_a, t_b]`` s from its log intensity *inside*
    the window: the dead-time law of :func:`dead_time_count` applied on each step of a piecewise
    linear log trajectory and summed (:func:`path_levels`, then :func:`law_along`).

    With ``renders=None`` the steps are the truth's own render instants inside the window (the
    simulator's 1 kHz renders: the rate a model of the losses could at best know); with
    ``renders=K`` they are ``K`` equal steps between ``K + 1`` instants (what ``K + 1`` renders a
    training window would show). Without a dead time it is the plain ``Σ δ / θ`` (``[P]`` float64).
    """
    instants, levels = path_levels(truth, t_a, t_b, renders)
    return law_along(instants, levels, theta_on, theta_off, dead_s, pixel)


def path_levels(truth: TrueLog, t_a: float, t_b: float, renders: int | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """``(instants [K + 1] s, true log intensity [K + 1, P] float64)`` of a window: its two ends and
    the truth's render instants between them (``renders=None``), or ``renders + 1`` equal steps."""
    if renders is not None and (isinstance(renders, bool) or int(renders) != renders or renders < 1):
        raise ValueError(f"renders: expected None or an integer >= 1, got {renders!r}")
    if renders is None:
        inner = truth.times[(truth.times > t_a) & (truth.times < t_b)]
        instants = np.concatenate([[t_a], inner, [t_b]])
    else:
        instants = np.linspace(t_a, t_b, renders + 1)
    return instants, np.stack([truth.at(float(t)).numpy().astype(np.float64) for t in instants])


def law_along(instants: np.ndarray, levels: np.ndarray, theta_on: np.ndarray, theta_off: np.ndarray,
              dead_s: float, pixel: str = "grid") -> np.ndarray:
    """``[P]`` signed emitted count along a piecewise linear log trajectory (``levels [K + 1, P]`` at
    ``instants [K + 1]`` s). Each step's change ``δ`` is ``c = |δ| / θ`` crossings at the rate
    ``r = c / Δt``; a ``"grid"`` pixel (this project's simulator) emits ``c / (r d + 1/2)`` of them
    where ``r d > 1/2`` (all below), a ``"reset"`` pixel ``c / (1 + r d)``."""
    if pixel not in ("grid", "reset"):
        raise ValueError(f"pixel: expected 'reset' or 'grid', got {pixel!r}")
    delta, dt = np.diff(levels, axis=0), np.diff(instants)[:, None]
    c = np.abs(delta) / np.where(delta > 0, theta_on, theta_off)
    rd = c / np.maximum(dt, 1e-12) * dead_s
    emitted = np.where(rd > 0.5, c / (rd + 0.5), c) if pixel == "grid" else c / (1.0 + rd)
    return (np.sign(delta) * emitted).sum(0)


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """``[H, W]`` bool: ``mask`` or a marked pixel within ``radius`` (Chebyshev): training's
    :func:`fusiongs.train.data.square_dilate` of the censored map (``events.censor_radius``)."""
    return (square_dilate(torch.from_numpy(mask.astype(np.float32)), radius) > 0).numpy()


def previous_gap(t: np.ndarray, pix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``([E] µs from each event to its pixel's previous event (inf for a pixel's first), [E] the
    events' order by pixel, then time)``."""
    order = np.lexsort((t, pix))
    same = np.r_[False, pix[order][1:] == pix[order][:-1]]
    gap = np.where(same, np.r_[0, np.diff(t[order])], np.inf).astype(np.float64)
    out = np.empty_like(gap)
    out[order] = gap
    return out, order


def window_table(s: dict, n_windows: int, seed: int) -> dict:
    """Shares of wrong / missed / censored pixel-windows per rule, and the corrections' errors."""
    w, h = s["width"], s["height"]
    n_pix, r = w * h, s["dead_us"]
    (dt, di, dp), (ct, ci, cp) = s["dead"], s["clean"]
    gap, order = previous_gap(dt, di)
    # training's rule (events.censor 2): fast_event_mask of the stream, at the true dead time
    stream = EventStream.create(dt, di % w, di // w, dp, w, h, None)
    fast = fast_event_mask(stream, 2 * r)
    pred = np.zeros_like(fast)  # the event before a fast one (a fast event's predecessor is its pixel's)
    pred[order[:-1]] = fast[order[1:]]
    bound = np.where(np.isfinite(gap) & (gap > r), np.minimum(r / np.maximum(gap - r, 1e-9), 3.0), 0.0)
    rng = np.random.default_rng(seed)
    span = s["duration_s"]
    longest = min(4.0 / (len(dt) / n_pix / span), span)  # s: an average pixel's 4 events
    rules = ("default", "with predecessors", "radius 1", "radius 2", "the true rate (oracle)")
    times_us, true_fast = s["times"] * 1e6, s["true_fast"]
    acc = {k: np.zeros(2) for k in rules}
    tot = np.zeros(2)
    corr = np.zeros(9)
    truth = TrueLog(s["times"], s["logs"].astype(np.float64))  # linear between render instants
    th_on, th_off = s["theta"]
    names = ("ΔL / θ", "dead-time law, reset pixel", "dead-time law, grid pixel (the simulator's)",
             "law along the truth's renders, reset pixel", "law along the truth's renders, grid pixel",
             "law over 4 equal steps (5 renders), grid pixel",
             "law over 8 equal steps (9 renders), grid pixel")
    pacc = np.zeros((2, 1 + 2 * len(names)))  # rows: active, lost; columns: n, |err| each, err each

    for _ in range(n_windows):
        dur = float(np.exp(rng.uniform(np.log(min(1e-3, longest)), np.log(longest))))
        ta = rng.uniform(0.0, span - dur) * 1e6
        tb = ta + dur * 1e6
        md, mc = (dt >= ta) & (dt < tb), (ct >= ta) & (ct < tb)
        nd = np.bincount(di[md], weights=dp[md].astype(float), minlength=n_pix)
        nc = np.bincount(ci[mc], weights=cp[mc].astype(float), minlength=n_pix)
        n_any = np.bincount(di[md], minlength=n_pix)
        active = (n_any > 0) | (np.bincount(ci[mc], minlength=n_pix) > 0)
        wrong = nd != nc
        tot += [active.sum(), wrong.sum()]
        own = np.bincount(di[md & fast], minlength=n_pix) > 0
        marks = {"default": own,
                 "with predecessors": own | (np.bincount(di[md & pred], minlength=n_pix) > 0)}
        for rad in (1, 2):
            marks[f"radius {rad}"] = dilate(own.reshape(h, w), rad).reshape(-1)
        k0 = max(int(np.searchsorted(times_us, ta, side="right")) - 1, 0)  # the steps the window meets
        k1 = min(int(np.searchsorted(times_us, tb, side="left")), len(true_fast) - 1)
        marks["the true rate (oracle)"] = true_fast[k1] - true_fast[k0] > 0
        for k in rules:
            acc[k] += [(wrong & ~marks[k]).sum(), (marks[k] & active).sum()]
        la, lb = truth.at(ta * 1e-6).numpy(), truth.at(tb * 1e-6).numpy()
        plain = (lb - la) / np.where(lb > la, th_on, th_off)
        laws = [dead_time_count(la, lb, dur, th_on, th_off, r * 1e-6, k) for k in ("reset", "grid")]
        span_s = (ta * 1e-6, tb * 1e-6)
        inside = path_levels(truth, *span_s)  # read once, for both pixel models
        laws += [law_along(*inside, th_on, th_off, r * 1e-6, k) for k in ("reset", "grid")]
        laws += [path_count(truth, *span_s, th_on, th_off, r * 1e-6, "grid", k) for k in (4, 8)]
        # errors in the direction of the pixel's change (positive: the prediction is too large)
        sgn = np.where(lb >= la, 1.0, -1.0)
        for row, m in enumerate((active, active & wrong)):
            preds = [plain, *laws]
            pacc[row] += [m.sum(), *(np.abs(q - nd)[m].sum() for q in preds),
                          *((sgn * (q - nd))[m].sum() for q in preds)]
        sel = ~own & (n_any > 0)
        true, emitted = np.abs(nc[sel]), np.abs(nd[sel])
        law_n = emitted / np.clip(1.0 - n_any[sel] * r / (dur * 1e6), 0.2, 1.0)
        lost_b = np.bincount(di[md], weights=bound[md], minlength=n_pix)[sel]
        half, full = emitted + 0.5 * lost_b, emitted + lost_b
        corr += [sel.sum(), (true - emitted).sum(), np.abs(true - emitted).sum(), (true - law_n).sum(),
                 np.abs(true - law_n).sum(), (true - half).sum(), np.abs(true - half).sum(),
                 (true - full).sum(), np.abs(true - full).sum()]
    return {"active": tot[0], "wrong": tot[1] / tot[0],
            "rules": {k: (a[0] / tot[1], a[1] / tot[0]) for k, a in acc.items()},
            "corrections": {"none": (corr[1] / corr[0], corr[2] / corr[0]),
                            "n / (1 - n r / T)": (corr[3] / corr[0], corr[4] / corr[0]),
                            "half of r / (dt - r)": (corr[5] / corr[0], corr[6] / corr[0]),
                            "all of r / (dt - r) (a reset pixel)": (corr[7] / corr[0], corr[8] / corr[0])},
            "predictions": {name: {grp: (pacc[i, 1 + j] / pacc[i, 0],
                                         pacc[i, 1 + len(names) + j] / pacc[i, 0])
                                   for i, grp in enumerate(("active", "lost"))}
                            for j, name in enumerate(names)}}


def lost_crossings(s: dict) -> dict:
    """Lost crossings and the gap (in dead times) between the events around each."""
    n_pix, r = s["width"] * s["height"], s["dead_us"]
    (dt, di, _), (ct, ci, _) = s["dead"], s["clean"]
    kd = np.sort(di.astype(np.int64) * 10**10 + dt)
    kc = np.sort(ci.astype(np.int64) * 10**10 + ct)
    lost = kc[~np.isin(kc, kd)]
    j = np.searchsorted(kd, lost)
    same = (j > 0) & (j < len(kd))
    pixel = lost[same] // 10**10
    same[same] = (kd[j[same] - 1] // 10**10 == pixel) & (kd[j[same]] // 10**10 == pixel)
    g = (kd[j[same]] - kd[j[same] - 1]) / r
    return {"crossings": len(kc), "events": len(kd), "lost": len(lost), "pixels": n_pix,
            "next_within_2": float(np.mean(g < 2)), "gap_median": float(np.median(g)),
            "gap_p90": float(np.quantile(g, 0.9))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", type=Path)
    p.add_argument("--windows", type=int, default=300)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.windows < 1:
        p.error(f"--windows: expected an integer >= 1, got {args.windows}")
    if not (args.scene / "gt" / "sim.json").is_file():
        p.error(f"{args.scene / 'gt' / 'sim.json'}: not found; the scene must come from fusiongs simulate")
    s = pixel_streams(args.scene)
    if s["dead_us"] <= 0:
        p.error(f"{args.scene}: its sensor has no refractory period (dvs.refractory_s = 0)")
    lc = lost_crossings(s)
    tab = window_table(s, args.windows, args.seed)
    print(f"scene {args.scene}: dead time {s['dead_us']:.0f} µs; crossings {lc['crossings']} -> events "
          f"{lc['events']} ({lc['lost'] / lc['crossings']:.1%} lost); lost crossings whose next event comes "
          f"within 2 dead times {lc['next_within_2']:.0%}; gap around a lost crossing median "
          f"{lc['gap_median']:.2f}, 90th percentile {lc['gap_p90']:.1f} dead times")
    if s["reset"]:
        print("(a reset pixel: after a release its events leave the crossings' instants, so the lost "
              "crossings above are not meaningful; the window counts below are)")
    print(f"{args.windows} windows, {tab['active']:.0f} active pixel-windows, {tab['wrong']:.1%} "
          "with a wrong count\n")
    print("| censoring rule | wrong counts not marked | active pixel-windows censored |")
    print("|---|---|---|")
    ref = tab["rules"]["default"]
    for k, (missed, cens) in tab["rules"].items():
        print(f"| {k}{' (reference)' if k == 'default' else ''} | {missed:.1%} ({missed / ref[0]:.2f}x) "
              f"| {cens:.1%} ({cens / ref[1]:.2f}x) |")
    print("\n| uncensored counts | mean shortfall (crossings) | mean absolute error |")
    print("|---|---|---|")
    for k, (bias, mae) in tab["corrections"].items():
        print(f"| {k}{' (reference)' if k == 'none' else ''} | {bias:.3f} | {mae:.3f} |")
    print("\n| emitted count predicted from the true log intensity | mean absolute error, active | "
          "excess, active | mean absolute error, lost crossings | excess, lost crossings |")
    print("|---|---|---|---|---|")
    for k, v in tab["predictions"].items():
        ref_mark = " (reference)" if k == "ΔL / θ" else ""
        print(f"| {k}{ref_mark} | {v['active'][0]:.3f} | {v['active'][1]:+.3f} | {v['lost'][0]:.3f} "
              f"| {v['lost'][1]:+.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
