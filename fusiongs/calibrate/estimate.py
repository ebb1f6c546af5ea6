"""Estimate an event sensor's ON / OFF contrast thresholds per colour channel from frames and events.

The estimator is the multiple-frame consistency of EDI (Pan et al., CVPR 2019 Sec. 4; mEDI, TPAMI
2020) with the two polarities kept apart, as docs/method.md section 4 asks. For frames ``i`` and ``j``
with exposures ``[s, e]`` and linear sensor intensities ``S`` (the pixel's own CFA channel, or the
Rec.601 luminance for a grey sensor), EDI gives the sharp mid-exposure intensity
``L_i = S_i / R_i(theta)``, ``R_i = mean_k exp(theta_+ n_+(t_k) - theta_- n_-(t_k))`` with ``n``
the event counts from mid-exposure to ``t_k``. Between the two mid-exposures the events say

    ``log L_j - log L_i = theta_+ N_+ - theta_- N_- + b_ij``

with ``b_ij`` a per-pair offset (a change of exposure or gain between frames, the common drift of
leak and noise events). Every pair with ``j - i <= max_gap`` is used: longer baselines carry more
events per pixel, so the quantisation of the counts matters less.

This is a regression on event counts that are themselves noisy: per-pixel threshold spread and
background activity attenuate a least-squares or L1 fit toward zero (measured on tuning scenes:
down to -40 %), and fitting in count units instead overshoots. The fit therefore uses instrumental
variables (:func:`fusiongs.calibrate.fit.iv_thresholds`): the counts of the pixel's
same-channel neighbours over the same pair see nearly the same log change but carry independent
noise. Two indicator regressors absorb the part of a threshold that a pixel's reference level had
already covered at the first frame. A coarse L1 grid search gives the starting point.

Why two unknowns: with ``theta_+ != theta_-`` texture that moves back and forth makes the net
count ``N_+ - N_-`` drift while the log intensity returns to its start; one symmetric threshold can
only absorb that drift by shrinking (docs/method.md section 4). Gates: refractory losses undercount
fast edges, so a pixel is left out of a pair when one of its neighbours has two events closer than
twice the sensor's dead time (the floor of the inter-event interval histogram) inside it: an edge
that fast loses events at the pixel too, and may leave it a single event, which no interval can
show. The pixel's own intervals are not used: a gate on them selects the pixel's pairs by its own
counts (a pair whose count fell short of its change has fewer close events, so it is kept more
often), which biases the fit high even on a sensor without dead time (tuning seed 75: +10 to +24 %
against -16 to -7 % with the neighbours' gate; twins of tuning 319 and 456 without a dead time:
+82 and +96 % with the own gate, -14 and +7 % with none).
Saturated and near-black pixels (quantised, compressed by the log offset of the sensor) are left
out; hot pixels are spatial outliers of the event count. The uncertainty is a bootstrap over
spatial tiles.

A DVS pixel held in reset during its dead time (Lichtsteiner et al., IEEE JSSC 2008) loses all
the change of its blind time, not only the events: every event on a fast edge stands for more
than one threshold, and pixels a few dead times apart lose 20-50 % of their change, which the gate
does not reach. Under that pixel model each event counts ``Δt / (Δt - d)`` crossings, and the last
event of a burst also the change expected in the blind time after it
(:func:`fusiongs.events.dead_time.reset_weights`), in every count below, ``d`` the onset of the
intervals (:func:`fusiongs.events.dead_time.interval_floor`). The intervals alone cannot tell such a
pixel from one whose level keeps every crossing (a scene's fastest edge also makes a floor, and a
reset pixel on sharp edges also makes a step), so with frames and an onset ``pixel_model="auto"``
asks the frames: the coefficient of the crossings the reset weights add, in the consistency
equation beside the plain counts, is 1 for a reset pixel and 0 for the other
(:func:`fusiongs.calibrate.pixel_model.excess_coefficient`, one value pooled over channels), and the
reset model is kept above 0.5. On the 173x130 tuning scenes, with the weights that count a burst's
end, it is 0.50-1.46 on 11 of the 12 reset-pixel scenes (0.32 on the
twelfth, which keeps the step model and reads +6.7 %) and -2.6-0.49 on 46 of the 47
simulator's-pixel scenes where it could be measured (8.5 on dark 333: a failed test, see
``excess_max``); without the burst's end, 62, 81 and 482 of the latter measured
0.59-0.63. The scenes simulated without a dead time keep the step model. An earlier rule
kept the model whose fit correlated better with the frames; but weighted counts are noisier, which
lowers the correlation even where they are right.

Threshold spread: every fit that adds up pixels' moments weighs a pixel by its event count, i.e.
by ``1 / theta_p``, and so measures the harmonic mean of the pixels' thresholds, below their mean
by a factor ``E[theta] E[1 / theta] ~ exp(var log theta)``. The variance is measured from the
events (:func:`fusiongs.events.dead_time.threshold_spread`: a pixel's count over its neighbours', in
the two halves of the recording) and the estimate multiplied by that factor, per polarity.

Without frames only the ON/OFF ratio is observable: over a recording the log intensities a sensor
sees end about where they started on average over pixels, so ``theta_- / theta_+ = sum N_+ /
sum N_-`` (per channel, hot pixels left out); the common scale is then an assumption. A single
frame does not make it observable either: the EDI sharpness criterion of one frame
(:func:`fusiongs.edi.estimate_theta`, Pan et al. CVPR 2019) rises with the threshold on the
sweep's scenes and picked the largest candidate on 13 of 16 tuning scenes (1.5-5.3x the truth),
so one frame is treated as none for the scale.

Known errors: 11 of 60 fresh test scenes have an estimate more than 10 % off
(6 of them among 12 scenes drawn in the corner of thresholds near 0.1 with dead times near 1 ms,
where the refractory gate leaves almost nothing). All 11 are flagged: the 8 where the gate fell
back to the pixel's own gate, to no gate, or to an uncertain fit, and the 3 where it kept less
than ``min_gate_keep`` of the pixel pairs. A flagged estimate carries a
larger systematic uncertainty and a warning (``systematic_fallback``; ``systematic_own_gate``
where the pixel's own gate was used, whose fit is biased high by its selection and low by the
losses it cannot see). Three causes are known:
the reference level's lag (depth and gallery scenes read +2..+5 %), the gate keeping only slow
pixel pairs (long-dead-time walls read low), and the pixel's own gate in dark colour scenes.
benchmarks/RESULTS.md ("What was tried and not adopted", "Known limits") lists every remedy
measured and refuted so far; look there before trying one. What the corner lacks is known:
a gate on the image's true speed at each pixel (an oracle from the simulator's log intensity,
the "true-rate gate" of a study script kept in git history) puts all 39 corner tuning scenes within
10 % (rms log error 0.027 against 0.097), so the error is which pixel pairs the gate keeps, and a
millisecond-scale speed that no pixel's own counts carry would mend it; neither the frames (with
optical flow) nor the frames-only warm-up's renders give it well enough.
"""

from __future__ import annotations

import numpy as np

from fusiongs.calibrate.data import (
    channel_pixels,
    count_inputs,
    gate_inputs,
    pixel_channels,
    prepare_channel,
    saturated,
    sensor_intensity,
    tile_ids,
)
from fusiongs.calibrate.fit import search_both
from fusiongs.calibrate.options import OWN_GATE_FALLBACK, PIXEL_MODELS, RATIO_SOURCES, CalibrateOptions
from fusiongs.calibrate.pixel_model import excess_test
from fusiongs.calibrate.pool import discrepant_channels, shrink_channels
from fusiongs.edi import estimate_theta
from fusiongs.errors import InputError, is_finite_number
from fusiongs.events.dead_time import (
    interval_floor,
    located_step_us,
    reset_weights,
    spatial_hot_pixels,
    threshold_spread,
)
from fusiongs.events.stream import EventStream
from fusiongs.events.thresholds import GREY_CHANNELS, RGB_CHANNELS, SensorThresholds
from fusiongs.frames.frameset import FrameSet


def _unreliable(res: dict, opts: CalibrateOptions) -> bool:
    """The fit failed, or (with a bootstrap) either threshold's relative std exceeds
    ``opts.refractory_max_uncertainty`` or is unknown."""
    if res.get("iv", "").startswith("failed"):
        return True
    if opts.bootstrap <= 0:
        return False
    rel = [res[f"std_{k}"] / res[f"theta_{k}"] for k in ("pos", "neg")]
    return not all(np.isfinite(r) and r <= opts.refractory_max_uncertainty for r in rel)


def _pair_gap(opts: CalibrateOptions) -> int:
    """The longest frame baseline a channel's pair data holds: the IV fit's ``max_gap``, or the
    round trips' ``round_trip_max_gap`` when the ratio comes from them (the fit takes its own
    pairs out of those)."""
    return max(opts.max_gap, opts.round_trip_max_gap) if opts.ratio != "iv" else opts.max_gap


def _failed(res: dict) -> bool:
    """The fit gave no positive solution, or no finite estimate."""
    vals = [res.get(k) for k in ("theta_pos", "theta_neg")]
    return res.get("iv", "").startswith("failed") or not all(v is not None and np.isfinite(v) for v in vals)


def _gate_name(opts: CalibrateOptions, gap: float) -> str:
    if gap <= 0 or (opts.refractory_radius <= 0 and not opts.refractory_self):
        return "off"
    if opts.refractory_radius <= 0:
        return "pixel"
    return "pixel and neighbours" if opts.refractory_self else "neighbours"


def _check_inputs(frames: FrameSet, events: EventStream) -> None:
    if events is None or len(events) == 0:
        raise InputError("calibrate", "events", "a scene with events (thresholds are measured from them)",
                         "no events")
    if len(frames) and frames.images.shape[1:3] != (events.height, events.width):
        raise InputError("calibrate", "frames", f"frames of the event sensor's size {events.width}x"
                         f"{events.height}", f"{frames.images.shape[2]}x{frames.images.shape[1]}")


def _model_fit(frames: FrameSet, lin: np.ndarray | None, events: EventStream, hot: np.ndarray,
               chan: np.ndarray, names: tuple[str, ...], opts: CalibrateOptions, reset: bool,
               dead: float) -> dict:
    """The event balance and (two frames or more) the per-channel consistency fits under one pixel
    model: ``reset`` weighs every event by :func:`~fusiongs.events.dead_time.reset_weights` with the
    dead time ``dead`` (µs; also the refractory gate's unit). Returns the fits, the threshold
    spread and the mean over channels of the fits' agreement (-inf without frames)."""
    rng = np.random.default_rng(opts.seed)
    weights = (reset_weights(events, dead, opts.reset_weight_cap, opts.reset_burst_end)
               if reset and dead > 0 else None)
    ratio = _balance_ratio(events, chan, hot, len(names), opts, rng, weights)
    if lin is None:
        return {"ratio": ratio, "dead": dead, "agreement": -np.inf}
    sens = sensor_intensity(lin, events.cfa)
    counts, between, neigh = count_inputs(frames, events, opts, weights)
    gap, fast, bad_pair = gate_inputs(frames, events, opts, dead)
    sat = saturated(lin, opts)
    var, n_spread = threshold_spread(events, hot, weights=weights)
    spread_small = bool(np.all(np.exp(var) <= opts.own_gate_max_spread))
    out_p, out_n, sd_p, sd_n, per = [], [], [], [], []
    for c in range(len(names)):
        sel, frame_ok = channel_pixels(sens, sat, between, chan, hot, c, names[c], opts, rng)
        data = prepare_channel(sens, counts, between, sel, bad_pair, frame_ok, events.width, opts.tile,
                               _pair_gap(opts), neigh)
        gate = _gate_name(opts, gap)
        fallback = False
        keep = None
        if gate != "off":
            ungated = prepare_channel(sens, counts, between, sel, np.zeros_like(bad_pair), frame_ok,
                                      events.width, opts.tile, _pair_gap(opts), neigh)
            keep = int(data.valid.sum()) / max(int(ungated.valid.sum()), 1)
        if gate != "off" and int(data.valid.sum()) < opts.min_pixels:
            # Every pixel's events come closer than the gap: no refractory floor can be told from
            # the signal's own intervals, so the gate would leave nothing to fit.
            data = ungated
            gate = "off (it left no pixel pairs)"
            fallback = True
        if int(data.valid.sum()) < opts.min_pixels:
            raise InputError("calibrate", "frames", f"at least {opts.min_pixels} usable pixel pairs "
                             f"of channel {names[c]} between the frames (neither saturated nor dark)",
                             f"{int(data.valid.sum())}")
        res = search_both(data, opts, rng)
        if gate == "neighbours" and _unreliable(res, opts) and not (_failed(res) or spread_small):
            gate = "neighbours (uncertain; the pixel's own gate reads high at this spread)"
            fallback = True
        elif gate == "neighbours" and _unreliable(res, opts):
            # A dark scene's events sit on fast edges and every pixel near one is gated: what is
            # left carries too little signal to measure anything, so the pixel's own gate is used
            # (only at small spread, or when the fit failed: see own_gate_max_spread).
            near = {k: res.get(k) for k in ("theta_pos", "theta_neg", "std_pos", "std_neg")}
            data = prepare_channel(sens, counts, between, sel, fast, frame_ok, events.width,
                                   opts.tile, _pair_gap(opts), neigh)
            res = search_both(data, opts, rng)
            gate = OWN_GATE_FALLBACK
            fallback = True
            res["neighbour_gate_fit"] = near
        out_p.append(res["theta_pos"])
        out_n.append(res["theta_neg"])
        sd_p.append(res["std_pos"])
        sd_n.append(res["std_neg"])
        per.append({k: res.get(k) for k in ("pixels", "residuals", "kept", "agreement", "log_units",
                                            "count_units", "round_trip")}
                   | {"refractory_gate": gate, "gate_fallback": fallback,
                      "gate_keep": keep, "gate_sparse": keep is not None and keep < opts.min_gate_keep,
                      "neighbour_gate_fit": res.get("neighbour_gate_fit")})
    agreement = [c["agreement"] for c in per if c.get("agreement") is not None
                 and np.isfinite(c["agreement"])]
    return {"ratio": ratio, "dead": dead, "gap": gap, "per": per, "var": var, "n_spread": n_spread,
            "tp": out_p, "tn": out_n, "sp": sd_p, "sn": sd_n,
            "agreement": float(np.mean(agreement)) if agreement else -np.inf}


def estimate_thresholds(frames: FrameSet, events: EventStream,
                        opts: CalibrateOptions | None = None) -> SensorThresholds:
    """ON / OFF thresholds per channel of an event sensor, with uncertainties.

    Args:
        frames: the scene's frames (possibly blurry; any response, linearised here). Two or more
            give the consistency estimate; one or none give only the ON/OFF ratio
            (``scale_known`` False, the scale ``opts.unknown_scale``).
        events: the time-sorted stream of the same pixel grid.
        opts: settings (:class:`CalibrateOptions`).

    Returns:
        :class:`SensorThresholds` with ``channels`` ``("grey",)`` or ``("R", "G", "B")``.
    """
    opts = opts or CalibrateOptions()
    if opts.ratio not in RATIO_SOURCES:
        raise InputError("calibrate", "ratio", f"one of {', '.join(RATIO_SOURCES)}", repr(opts.ratio))
    for name in ("ratio_switch", "systematic", "systematic_fallback", "systematic_own_gate",
                 "min_gate_keep"):
        v = getattr(opts, name)
        if not (is_finite_number(v) and v >= 0):
            raise InputError("calibrate", name, "a finite number >= 0", repr(v))
    _check_inputs(frames, events)
    if opts.pixel_model not in PIXEL_MODELS:
        raise InputError("calibrate", "pixel_model", f"one of {', '.join(PIXEL_MODELS)}",
                         repr(opts.pixel_model))
    cut = opts.excess_cut
    if not is_finite_number(cut):
        raise InputError("calibrate", "excess_cut", "a finite number", repr(cut))
    top = opts.excess_max
    # finite: it is written to calibration.json, which is strict JSON
    if not (is_finite_number(top) and top > cut):
        raise InputError("calibrate", "excess_max", f"a finite number above excess_cut ({cut})",
                         repr(top))
    if not isinstance(opts.reset_burst_end, bool):
        raise InputError("calibrate", "reset_burst_end", "true or false", repr(opts.reset_burst_end))
    n = opts.excess_min_pairs
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise InputError("calibrate", "excess_min_pairs", "a positive integer", repr(n))
    hot = spatial_hot_pixels(events, opts.hot_factor, opts.hot_floor)
    chan = pixel_channels(events)
    names = GREY_CHANNELS if events.cfa is None else RGB_CHANNELS
    floor = interval_floor(events, opts.dead_time_jump)
    lin = frames.to_linear() if len(frames) >= 2 else None
    test = None
    if opts.pixel_model != "auto":
        model = opts.pixel_model
    elif floor.onset_us > 0 and lin is not None:  # the frames tell the two pixels apart
        test = excess_test(frames, lin, events, hot, chan, names, opts,
                            max(floor.onset_us, floor.step_us))
        beta = test["coefficient"]
        model = "reset" if beta is not None and cut < beta <= top else "step"
    else:
        model = "step"
    try:
        fit = _model_fit(frames, lin, events, hot, chan, names, opts, model == "reset",
                         floor.onset_us if model == "reset" else floor.step_us)
    except InputError:
        if test is None or model == "step":
            raise
        model = "step"  # the reset model's gate left a channel without pixel pairs
        fit = _model_fit(frames, lin, events, hot, chan, names, opts, False, floor.step_us)
    ratio = fit["ratio"]
    details = {"hot_pixels": int(hot.sum()), "events": int(len(events)), "frames": int(len(frames)),
               "ratio_from_event_balance": [r["ratio"] for r in ratio], "dead_time_us": fit["dead"],
               "pixel_model": model + (" (auto)" * (opts.pixel_model == "auto")),
               "pixel_model_test": test,
               "interval_floor_us": {"step": floor.step_us, "onset": floor.onset_us},
               # the sensor's refractory period; dead_time_us (a histogram bin's edge) stays the
               # gates' and deblur's unit (stats.located_step_us: in this one they did worse)
               "refractory_period_us": (located_step_us(events, fit["dead"]) if model == "step"
                                        else fit["dead"])}
    if model == "reset":
        details["reset_weight_cap"] = opts.reset_weight_cap
        details["reset_burst_end"] = opts.reset_burst_end
    if len(frames) < 2:
        return _without_pairs(frames, events, names, ratio, opts, details)
    per, var, n_spread = fit["per"], fit["var"], fit["n_spread"]
    details.update({"refractory_gap_us": fit["gap"], "per_channel": per, "n_samples": opts.n_samples})
    tp, sp, tn, sn = (np.array(fit[k]) for k in ("tp", "sp", "tn", "sn"))
    failed = failed_channels(tp, tn, opts.theta_range)
    if failed.all():
        details["per_channel"] = per
        details["consistency_fit"] = {"theta_pos": tp.tolist(), "theta_neg": tn.tolist(),
                                      "failed": "every channel's estimate is outside the searched range"}
        return _without_pairs(frames, events, names, ratio, opts, details,
                              "the frames' consistency fit failed on every channel: ")
    for c in np.flatnonzero(failed):  # it takes the other channels' value in the pooling
        per[c]["failed"] = f"estimate {tp[c]:.3g} / {tn[c]:.3g} outside the searched range"
        sp[c] = sn[c] = np.inf
    if opts.spread_correction:
        fac = np.exp(var)
        tp, sp, tn, sn = tp * fac[0], sp * fac[0], tn * fac[1], sn * fac[1]
        details["threshold_spread"] = {"log_variance": var.tolist(), "pixels": n_spread.tolist(),
                                       "factor": fac.tolist()}
    if len(names) > 1 and opts.channel_prior > 0:
        details["per_channel_unpooled"] = {k: [float(x) if np.isfinite(x) else None for x in v]
                                           for k, v in (("theta_pos", tp), ("theta_neg", tn),
                                                        ("std_pos", sp), ("std_neg", sn))}
        wide_p = discrepant_channels(tp, sp, opts.channel_prior, opts.channel_outlier)
        wide_n = discrepant_channels(tn, sn, opts.channel_prior, opts.channel_outlier)
        details["channel_outliers"] = [[names[c] for c in np.flatnonzero(w > s)]
                                       for w, s in ((wide_p, sp), (wide_n, sn))]
        tp, sp = shrink_channels(tp, wide_p, opts.channel_prior)
        tn, sn = shrink_channels(tn, wide_n, opts.channel_prior)
    # The bootstrap sees the tiles' scatter, not the fit's biases: add the systematic part.
    details["std_bootstrap"] = {"std_pos": [float(v) for v in sp], "std_neg": [float(v) for v in sn]}
    fell = [names[c] for c, p in enumerate(per) if p["gate_fallback"]]
    own = [names[c] for c, p in enumerate(per) if p["refractory_gate"] == OWN_GATE_FALLBACK]
    sparse = [names[c] for c, p in enumerate(per) if p["gate_sparse"] and not p["gate_fallback"]]
    systematic = ((opts.systematic_own_gate if own else opts.systematic_fallback) if fell or sparse
                  else opts.systematic)
    details["systematic"] = systematic
    if fell:
        via = f"; the pixel's own gate on {', '.join(own)}" if own else ""
        details.setdefault("warnings", []).append(
            f"the refractory gate left too few pixel pairs to measure on channel(s) {', '.join(fell)} "
            f"(dead time {fit['dead']:.0f} µs{via}): such estimates are often more than 10 % off (on "
            f"the simulator's sweep 15 of 27 scenes; see docs/calibration.md, section 'Known limits'), so "
            f"their uncertainty carries {100 * systematic:g} % (else {100 * opts.systematic:g} %)")
    if sparse:
        least = min(p["gate_keep"] for p in per if p["gate_sparse"] and not p["gate_fallback"])
        details.setdefault("warnings", []).append(
            f"the refractory gate kept only {100 * least:.1f} % of the pixel pairs on channel(s) "
            f"{', '.join(sparse)} (dead time {fit['dead']:.0f} µs; below {100 * opts.min_gate_keep:g} % "
            f"the estimates are often more than 10 % off; see docs/calibration.md, section "
            f"'Known limits'), so their uncertainty carries {100 * systematic:g} % "
            f"(else {100 * opts.systematic:g} %)")
    sp, sn = (np.where(np.isfinite(sd), np.hypot(sd, systematic * th), np.nan)
              for sd, th in ((sp, tp), (sn, tn)))
    return SensorThresholds(names, tp, tn, sp, sn, True,
                            f"mEDI consistency, {opts.units} fit (ON/OFF per channel)"
                            + {"iv": "", "round_trip": ", ratio from round trips",
                               "auto": ", ratio from round trips where they disagree"}[opts.ratio],
                            details)


def failed_channels(theta_pos: np.ndarray, theta_neg: np.ndarray, theta_range: tuple[float, float]
                    ) -> np.ndarray:
    """``[C]`` bool: a channel's fit failed, i.e. either estimate is not finite or lies more than a
    factor 2 outside ``theta_range`` (the IV solve is unconstrained: a dark channel with a few
    dozen pixel pairs came out at 40 or 6e6 on test seed 1099)."""
    lo, hi = theta_range
    ok = [np.isfinite(v) & (v >= 0.5 * lo) & (v <= 2.0 * hi) for v in (theta_pos, theta_neg)]
    return ~(ok[0] & ok[1])


def _balance_ratio(events: EventStream, chan: np.ndarray, hot: np.ndarray, n_ch: int,
                   opts: CalibrateOptions, rng: np.random.Generator,
                   weights: np.ndarray | None = None) -> list[dict]:
    """Per channel ``theta_- / theta_+ = sum N_+ / sum N_-`` with a tile-bootstrap uncertainty
    (``N`` the events' ``weights`` summed when given)."""
    cm = events.count_maps(weights=weights).reshape(2, -1).astype(np.float64)
    tid = tile_ids(np.arange(cm.shape[1]), events.width, opts.tile)
    out = []
    for c in range(n_ch):
        sel = (chan == c) & ~hot
        on = np.bincount(tid[sel], cm[0, sel], minlength=tid.max() + 1)
        off = np.bincount(tid[sel], cm[1, sel], minlength=tid.max() + 1)
        ratio = float(on.sum() / off.sum()) if off.sum() > 0 else float("nan")
        std = float("nan")
        if opts.bootstrap > 0 and on.size >= 4 and off.sum() > 0:
            wts = rng.multinomial(on.size, np.full(on.size, 1.0 / on.size), size=opts.bootstrap)
            std = float(np.std((wts @ on) / np.maximum(wts @ off, 1.0)))
        out.append({"ratio": ratio, "std": std})
    return out


def _without_pairs(frames: FrameSet, events: EventStream, names: tuple[str, ...], ratio: list[dict],
                   opts: CalibrateOptions, details: dict, why: str = "") -> SensorThresholds:
    """Fewer than two frames (or a consistency fit that failed on every channel, said by ``why``):
    the ON/OFF ratio from the event balance, the common scale assumed.

    One frame's EDI sharpness estimate of the scale (:func:`estimate_theta`) is recorded in the
    details (``single_frame_sharpness``) but not used: it is not reliable (module docstring)."""
    rho = np.array([r["ratio"] for r in ratio])
    rho_sd = np.array([r["std"] for r in ratio])
    if not np.all(np.isfinite(rho) & (rho > 0)):
        raise InputError("calibrate", "events", "both ON and OFF events on every channel", rho.tolist())
    scale = opts.unknown_scale
    method = why + "event balance (ON/OFF ratio only; common scale assumed)"
    if len(frames) == 1:
        method = "one frame: " + method
        details["single_frame_sharpness"] = estimate_theta(
            frames.to_linear()[0], events, float(frames.t_start[0]), float(frames.t_end[0]))
    tp, tn = scale / np.sqrt(rho), scale * np.sqrt(rho)
    sd_rel = 0.5 * rho_sd / rho
    details["assumed_scale"] = scale
    return SensorThresholds(names, tp, tn, tp * sd_rel, tn * sd_rel, False, method, details)
