"""benchmarks/bench_dead_time_losses.py: lost crossings, unmarked short counts and the rules'
marks, on streams small enough to count by hand."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_dead_time_losses import (
    dead_time_count,
    dilate,
    lost_crossings,
    path_count,
    previous_gap,
    true_fast_steps,
    window_table,
)

R = 150.0  # dead time, µs


def _streams() -> dict:
    """1x3 sensor over 6 ms. Pixel 0: a ramp with crossings every 100 µs, every other one lost
    (its events 200 µs apart: fast, under 2 dead times). Pixel 1: crossings at 0 and 50 µs, the
    second lost, then one at 5000 µs (a loss no short interval shows). Pixel 2: crossings 160 µs
    apart, none lost, all fast."""
    clean_t = [0, 100, 200, 300, 400, 0, 50, 5000, 0, 160, 320]
    clean_i = [0, 0, 0, 0, 0, 1, 1, 1, 2, 2, 2]
    dead_t = [0, 200, 400, 0, 5000, 0, 160, 320]
    dead_i = [0, 0, 0, 1, 1, 2, 2, 2]

    def stream(t, i):
        order = np.argsort(t, kind="stable")
        t, i = np.asarray(t, np.int64)[order], np.asarray(i, np.int64)[order]
        return t, i, np.ones(len(t), np.int8)

    # the true log intensity at 100 µs steps (θ = 0.2): pixel 0 rises one θ a step over 0-500 µs,
    # pixel 1 two θ in its first step and one θ in 5000-5100 µs, pixel 2 0.625 θ a step (one θ per
    # 160 µs, slower than one per dead time: 0.94 θ per 150 µs)
    times = np.arange(61) * 1e-4
    k = np.arange(61)
    logs = np.stack([0.2 * np.minimum(k, 5), 0.4 * (k >= 1) + 0.2 * (k >= 51),
                     0.125 * np.minimum(k, 4)], axis=1)
    th = np.full(3, 0.2)
    return {"width": 3, "height": 1, "dead_us": R, "duration_s": 0.006, "dead": stream(dead_t, dead_i),
            "clean": stream(clean_t, clean_i), "times": times, "logs": logs, "theta": (th, th),
            "true_fast": true_fast_steps(logs, times, th, th, R * 1e-6)}


def test_previous_gap_and_dilate():
    t = np.array([0, 10, 30, 100], np.int64)
    pix = np.array([1, 0, 1, 1])
    assert previous_gap(t, pix)[0].tolist() == [np.inf, np.inf, 30.0, 70.0]
    m = np.zeros((3, 4), bool)
    m[0, 0] = True
    assert dilate(m, 1).sum() == 4 and dilate(m, 0).sum() == 1 and dilate(m, 2).sum() == 9


def test_lost_crossings_and_their_gaps():
    lc = lost_crossings(_streams())
    assert (lc["crossings"], lc["events"], lc["lost"]) == (11, 8, 3)
    # pixel 0's two losses sit between events 200 µs apart (1.33 dead times), pixel 1's between
    # events 5000 µs apart (33 dead times): 2 of 3 have their next event within 2 dead times
    assert abs(lc["next_within_2"] - 2 / 3) < 1e-9
    assert abs(lc["gap_median"] - 200 / R) < 1e-9


def test_window_table_finds_the_unmarked_short_count():
    tab = window_table(_streams(), 200, 0)
    assert 0 < tab["wrong"] < 1
    missed, censored = tab["rules"]["default"]
    # pixel 0's events are 200 µs apart (< 2 dead times: marked); pixel 1's loss is never marked
    # by its own events, only through its neighbours' (pixels 0 and 2, within radius 1)
    assert missed > 0
    assert tab["rules"]["radius 1"][0] < missed and tab["rules"]["radius 1"][1] > censored
    assert tab["corrections"]["none"][0] > 0  # uncensored counts are short on the mean


def test_true_fast_steps_and_the_oracle_rule_marks_every_loss():
    s = _streams()
    fast = np.diff(s["true_fast"], axis=0)  # [steps, pixels] 0/1
    assert fast[:, 0].nonzero()[0].tolist() == [0, 1, 2, 3, 4]
    assert fast[:, 1].nonzero()[0].tolist() == [0, 50]
    assert fast[:, 2].sum() == 0  # 0.94 thresholds per dead time: no loss possible
    tab = window_table(s, 200, 0)
    missed, censored = tab["rules"]["the true rate (oracle)"]
    assert missed == 0  # every window with a lost crossing meets a fast step of its pixel
    assert 0 < censored < 1  # pixel 2's windows are never censored
    assert tab["rules"]["default"][0] > 0  # while the default misses pixel 1's loss


def test_dead_time_count_is_the_plain_change_without_dead_time_and_follows_the_pixel_model():
    from fusiongs.sim import dvs

    la, lb, th = np.array([-5.0, -1.0]), np.array([-1.0, -5.0]), np.full(2, 0.2)
    for pixel in ("reset", "grid"):
        assert np.allclose(dead_time_count(la, lb, 0.01, th, th, 0.0, pixel), [20.0, -20.0])
    # an edge over a pixel: the intensity rises linearly from near black, fastest in log at first
    cases = [(0.002, 0.8, 0.01, 1e-3), (0.8, 0.002, 0.01, 1e-3), (0.05, 0.5, 0.02, 5e-4),
             (0.3, 0.05, 0.004, 9e-4), (0.1, 0.2, 0.01, 1e-3)]
    for i0, i1, dur, dead in cases:
        t = np.linspace(0.0, dur, 4001)
        logs = np.log(i0 + (i1 - i0) * t / dur + 1e-3)[:, None].astype(np.float32)
        one = np.array([0.2])
        emitted = int(dvs.dvs_events(logs, t, one, one, dead)[2].sum())
        grid = float(dead_time_count(logs[:1, 0], logs[-1:, 0], dur, one, one, dead, "grid")[0])
        reset = float(dead_time_count(logs[:1, 0], logs[-1:, 0], dur, one, one, dead, "reset")[0])
        plain = float(logs[-1, 0] - logs[0, 0]) / 0.2
        assert abs(grid - emitted) < 0.6, (i0, i1, grid, emitted)  # the simulator's pixel
        assert abs(reset) <= abs(grid) + 1e-9 and abs(grid) <= abs(plain) + 1e-9
    with pytest.raises(ValueError, match="pixel"):  # an unknown pixel model is refused
        dead_time_count(la, lb, 0.01, th, th, 1e-3, "other")


def test_window_table_predicts_lost_counts_better_with_the_dead_time_law():
    tab = window_table(_streams(), 200, 0)
    plain = tab["predictions"]["ΔL / θ"]["lost"][0]
    grid = tab["predictions"]["dead-time law, grid pixel (the simulator's)"]["lost"][0]
    assert grid <= plain


def test_path_count_is_the_plain_change_without_dead_time_and_follows_the_simulators_pixel():
    from benchmarks.bench_event_only_diagnose import TrueLog
    from fusiongs.sim import dvs

    times = np.linspace(0.0, 0.01, 11)
    rng = np.random.default_rng(0)
    logs = np.cumsum(rng.normal(0.0, 0.3, (11, 4)), axis=0)
    truth, th = TrueLog(times, logs), np.full(4, 0.2)
    for pixel in ("grid", "reset"):
        for renders in (None, 3):
            n = path_count(truth, 0.0013, 0.0087, th, th, 0.0, pixel, renders)
            assert np.allclose(n, (truth.at(0.0087) - truth.at(0.0013)).numpy() / 0.2)
    # ramps in intensity from near black (fastest in log first): the law along the renders the
    # simulator's pixel model saw predicts its emitted count; the two end levels do worse
    for i0, i1, dur, dead in [(0.002, 0.8, 0.01, 1e-3), (0.8, 0.002, 0.01, 1e-3), (0.05, 0.5, 0.02, 5e-4)]:
        t = np.linspace(0.0, dur, 401)
        ramp = np.log(i0 + (i1 - i0) * t / dur + 1e-3)[:, None]
        one = np.array([0.2])
        emitted = int(dvs.dvs_events(ramp.astype(np.float32), t, one, one, dead)[2].sum())
        path = float(path_count(TrueLog(t, ramp), 0.0, dur, one, one, dead, "grid")[0])
        ends = float(dead_time_count(ramp[:1, 0], ramp[-1:, 0], dur, one, one, dead, "grid")[0])
        assert abs(path - emitted) < 1.0, (i0, i1, path, emitted)
        assert abs(path - emitted) <= abs(ends - emitted) + 1e-9
        reset = float(path_count(TrueLog(t, ramp), 0.0, dur, one, one, dead, "reset")[0])
        assert abs(reset) <= abs(path) + 1e-9  # a reset pixel loses at least as much
    with pytest.raises(ValueError, match="pixel"):  # an unknown pixel model is refused
        path_count(truth, 0.0, 0.01, th, th, 1e-3, "other")
    for bad in (0, -2, 2.5):  # no step at all would sum to a silent zero
        with pytest.raises(ValueError, match="renders"):
            path_count(truth, 0.0, 0.01, th, th, 1e-3, "grid", bad)


def test_window_table_predicts_lost_counts_best_along_the_truths_renders():
    tab = window_table(_streams(), 200, 0)
    ends = tab["predictions"]["dead-time law, grid pixel (the simulator's)"]["lost"][0]
    path = tab["predictions"]["law along the truth's renders, grid pixel"]["lost"][0]
    plain = tab["predictions"]["ΔL / θ"]["lost"][0]
    assert path < plain and path <= ends + 1e-9
