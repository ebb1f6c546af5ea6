"""Settings of the threshold calibration (:func:`fusiongs.calibrate.estimate.estimate_thresholds`).

Kept apart from the estimator so that every layer can name them without importing it.
"""

from __future__ import annotations

from dataclasses import dataclass

PIXEL_MODELS = ("auto", "step", "reset")  # CalibrateOptions.pixel_model
RATIO_SOURCES = ("iv", "round_trip", "auto")  # CalibrateOptions.ratio
OWN_GATE_FALLBACK = "pixel (the neighbours' gate left no measurement)"  # per_channel refractory_gate

@dataclass(frozen=True)
class CalibrateOptions:
    """Settings of :func:`estimate_thresholds` (defaults chosen on tuning seeds only).

    Attributes:
        n_samples: instants per exposure of the EDI ratio ``R_i``.
        max_pixels: pixels per channel used in the fine search (a seeded random subset).
        min_pixels: fewest usable pixels per channel (fewer is an error).
        coarse_pixels: pixels per channel used in the coarse grid search.
        theta_range: ``(lo, hi)`` thresholds searched (log units).
        coarse_steps: grid points per polarity in the coarse search (geometric spacing).
        refine_levels: refinement rounds (each divides the grid step by 3).
        dark: pixels darker than this fraction of the channel's 99th percentile are left out.
        saturation: linear value at and above which a pixel counts as saturated.
        hot_factor: a pixel is hot when its event count exceeds ``hot_factor`` times the median
            count of its same-channel neighbours plus ``hot_floor``.
        hot_floor: see ``hot_factor``.
        refractory_gate: a pixel is left out of a pair when a pixel within ``refractory_radius``
            has two events closer than this multiple of the estimated dead time inside it (0
            disables the gate). The dead time is the left edge of the interval histogram's bin
            that holds the step, up to 15 % below the sensor's refractory period
            (``details["refractory_period_us"]``, :func:`fusiongs.events.dead_time.located_step_us`);
            with the gate at 2 or 1.75 times the located period instead, 11 of 61 plain tuning
            scenes were outside 10 % against 7.
        refractory_radius: see ``refractory_gate`` (pixels, a square).
        refractory_self: the pixel's own fast events gate it too (off: the gate would select the
            pixel's pairs by its own counts, the regressor of the fit; see the module docstring).
        refractory_max_uncertainty: when the fit with the neighbours' gate fails, or its bootstrap
            uncertainty (relative std of either threshold) exceeds this, the channel is fitted
            again with the pixel's own gate (a dark scene's events sit on fast edges, and the
            neighbours' gate may leave pairs without signal). Tuning scenes: at most 0.06.
        own_gate_max_spread: the refit with the pixel's own gate is made only when the fit failed
            outright or the measured threshold spread is small (``exp(var log theta)`` of both
            polarities at most this): the own gate's fits read high, more so at large spread
            (tuning seed 75; test seed 1076: +84 %); the selection is on the pixel pair's count,
            not on the pixel's threshold. Otherwise the uncertain neighbours' fit is kept.
        dead_time_jump: jump factor of the interval histogram that marks the dead time
            (:func:`fusiongs.events.dead_time.dead_time_us`).
        pixel_model: how the sensor's pixels lose events in their dead time: ``"step"`` (the
            reference level keeps every crossing, the dead time is the step of the interval
            histogram, fast pixel pairs are gated), ``"reset"`` (a DVS pixel held in reset: the
            dead time is the onset of the intervals and every event counts
            :func:`~fusiongs.events.dead_time.reset_weights` crossings, the gate kept), or ``"auto"``:
            with two frames or more and an onset, the frames' coefficient on the crossings the
            reset model adds is measured (:func:`fusiongs.calibrate.pixel_model.excess_coefficient`)
            and the reset model kept when it lies in ``(excess_cut, excess_max]``; otherwise
            ``"step"``.
        excess_cut: the coefficient above which "auto" keeps the reset model: 0.5, halfway between
            the two models' values (1 for a reset pixel, 0 for the other), not tuned.
        excess_max: the coefficient above which the measurement counts as failed and "auto" keeps
            the step model: 2, as far above the reset value as the other model's value lies below
            it. Under either model an extra crossing stands for at most about one threshold (the
            reset pixel's capped weights allow a little more: 0.45-1.76 on 24 reset-pixel
            tuning and test scenes, 0.32-1.47 on 48 such scenes with the burst's end); tuning
            seed 333 (the simulator's pixel, dark RGGB) measured 20.9 (8.5 with the burst's end)
            and read 25 % low with the reset model.
        excess_min_pairs: fewest gated pixel pairs for a channel to enter that measurement.
        reset_weight_cap: the largest weight of one event on a reset pixel.
        reset_burst_end: count the blind time after a burst's last event too
            (:func:`~fusiongs.events.dead_time.reset_weights` ``burst_end``);
            written to calibration.json, where deblur and edi read it.
        channel_prior: expected relative spread of the thresholds between CFA channels; each
            channel's estimate is pooled with the others by its precision
            (:func:`shrink_channels`; 0 keeps every channel on its own).
        channel_outlier: a channel whose estimate lies more than this many combined standard
            deviations (its own and ``channel_prior``) from the channels' median has its
            uncertainty widened to that distance before pooling (0: never); see
            :func:`discrepant_channels`. 2 was chosen on tuning seeds.
        max_gap: frames compared: every pair ``(i, j)`` with ``j - i <= max_gap``.
        ratio: where the ON/OFF ratio comes from with ``units="iv"``: ``"iv"`` (the IV fit's own
            ratio, the default), ``"round_trip"`` (the pixel pairs that came back to their log
            intensity through many events, :func:`fusiongs.calibrate.fit.with_round_trip_ratio`;
            the IV fit's common scale is kept), or ``"auto"`` (the round trips' only where it
            differs from the fit's by more than ``ratio_switch``). Both put 3 of 73 tuning
            scenes outside 10 % against 8, but on fresh test scenes they did worse:
            round trips 1 / 12 against 0 / 12 (1192-1203), auto 2 / 12 against 1 / 12
            (1204-1215). So the default stays the IV fit's. Nor do the
            round trips mend the estimates whose refractory gate fell back: on the 39 corner
            tuning scenes they put 7 outside 10 % against 6: the four fallback
            scenes outside 10 % there are off mostly in the common scale (-42 to +39 %), which
            the round trips keep.
        ratio_switch: with ``ratio="auto"`` the round trips' ratio replaces the fit's only where
            the two differ by more than this (in log ratio); elsewhere the fit's is kept.
        systematic: relative one-sigma uncertainty added in quadrature to each estimate's
            bootstrap standard deviation when frames fix the scale. The tile bootstrap alone
            covered the truth within one / two standard deviations for 33 / 54 % of the 290
            estimates of 73 tuning scenes: it does not see the fit's biases.
            With 0.04 (the value of 0-0.06 whose coverage came nearest 68 / 95 % there): 72 / 94 %;
            on 12 fresh test scenes 71 / 100 %. The bootstrap's own values
            are kept in ``details["std_bootstrap"]``.
        systematic_fallback: the systematic part instead of ``systematic`` when the refractory gate
            fell back on any channel: the neighbours' gate left no pixel pair or no reliable fit, so
            the channel was fitted with the pixel's own gate (then ``systematic_own_gate``), without
            a gate, or kept the uncertain fit (``per_channel[c]["gate_fallback"]``). On 112
            tuning scenes such estimates were off by 0.124 in log (rms; 7 of
            the 19 scenes outside 10 %) against 0.046 (7 of 93) for the others, and 0.12 scored best
            of 0.04-0.20 by the Gaussian log likelihood of the truth (within one / two standard
            deviations: 84 / 96 %; 0.04: 67 / 83 %). On 60 fresh test scenes,
            chosen on none of them, 8 scenes were so estimated and all 8 were more than 10 % off,
            against 3 of the other 52. A warning names the channels.
        systematic_own_gate: the systematic part instead of ``systematic_fallback`` when any
            channel was fitted with the pixel's own gate (``refractory_gate`` "pixel (...)"): that
            gate's fit carries two biases of its own, its selection of the pixel's pairs by the
            pixel's own counts (high, up to +96 % on an ideal twin) and the crossings lost inside
            the pairs it keeps (low), which cancel on some scenes and not on others. On 7
            own-gate tuning scenes (30 estimates, rms log error 0.19; 319 and
            456 +60 to +65 %) 0.20 scored best of 0.04-0.50 by the Gaussian log likelihood of the
            truth (within one / two standard deviations: 83 / 87 %; 0.12: 73 / 87 %). On the 4
            own-gate corner test scenes, chosen on none of them: 65 / 70 % (0.12: 40 / 65 %).
        min_gate_keep: the fewest of a channel's active pixel pairs (a fraction) the refractory
            gate may keep for its fit to count as a plain measurement
            (``per_channel[c]["gate_keep"]``). Below it the channel is flagged
            (``gate_sparse``): its uncertainty carries ``systematic_fallback`` and a warning says
            so; the estimate does not change. Where the gate keeps so little, what it keeps is
            the slow part of a fast scene, whose fit is biased either way. On 85 tuning scenes
            (plain 0-39, the 39 corner scenes, 6 more) 0.03 and 0.04 scored best of 0-0.08 by the
            Gaussian log likelihood of the truth (1.571 against 1.566 without the flag); the
            flag adds one of them (565, -13.1 %), and below 0.03 the gate had already fallen back
            on every other. On the 60 fresh test scenes, chosen on none of this, it
            flags the three failures no fallback flagged (1224, 1228, 1298: keeps of 1.2-2.2 %).
        round_trip_tol: largest EDI log change of a round trip.
        round_trip_min_events: fewest events (both polarities together) in a round trip.
        round_trip_min_pairs: fewest round trips for their ratio to be used (else the IV fit's).
        round_trip_max_gap: frame pairs up to this far apart are searched for round trips (the IV
            fit keeps ``max_gap``).
        iv_offsets: fit the two indicator offsets in the IV model
            (:func:`fusiongs.calibrate.fit.iv_thresholds`).
        trim: residuals farther than this many robust standard deviations from their pair's
            median at the starting fit are left out of the IV fit (0: none are). Off by default:
            the starting fit is attenuated by threshold spread, and trimming around it drops the
            pixels with large thresholds (tuning seed 49: -15 / -19 % trimmed, -4 / -12 % not).
        spread_correction: multiply each polarity's estimate by ``exp(var log theta)`` measured
            from the events (the fit measures the harmonic mean of the pixels' thresholds).
        units: residuals in ``"log"`` units, in ``"count"`` units (events), or ``"both"``: the
            geometric mean of the two estimates (:func:`fusiongs.calibrate.fit.search_both`).
        tile: side in pixels of the bootstrap tiles.
        bootstrap: bootstrap resamples for the uncertainty.
        unknown_scale: geometric mean ``sqrt(theta_+ theta_-)`` assumed when there are no frames.
        seed: seed of the pixel subsets and the bootstrap.
    """

    n_samples: int = 12
    max_pixels: int = 12000
    min_pixels: int = 10
    coarse_pixels: int = 4000
    theta_range: tuple[float, float] = (0.03, 1.5)
    coarse_steps: int = 17
    refine_levels: int = 3
    dark: float = 0.03
    saturation: float = 0.97
    hot_factor: float = 5.0
    hot_floor: float = 20.0
    refractory_gate: float = 2.0
    refractory_radius: int = 1
    refractory_self: bool = False
    refractory_max_uncertainty: float = 0.1
    own_gate_max_spread: float = 1.05
    dead_time_jump: float = 5.0
    pixel_model: str = "auto"
    excess_cut: float = 0.5
    excess_max: float = 2.0
    excess_min_pairs: int = 1000
    reset_weight_cap: float = 4.0
    reset_burst_end: bool = True
    channel_prior: float = 0.05
    channel_outlier: float = 2.0
    max_gap: int = 4
    ratio: str = "iv"
    ratio_switch: float = 0.05
    systematic: float = 0.04
    systematic_fallback: float = 0.12
    systematic_own_gate: float = 0.20
    min_gate_keep: float = 0.03
    round_trip_tol: float = 0.1
    round_trip_min_events: float = 6.0
    round_trip_min_pairs: int = 100
    round_trip_max_gap: int = 11
    units: str = "iv"
    iv_offsets: bool = True
    trim: float = 0.0
    spread_correction: bool = True
    tile: int = 16
    bootstrap: int = 200
    unknown_scale: float = 0.25
    seed: int = 0
