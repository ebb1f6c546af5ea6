"""Stream warnings: time gaps and hot pixels."""

from __future__ import annotations

import numpy as np

from fusiongs.events.stats import frames_outside_events, hot_pixels, stream_warnings, time_gaps
from fusiongs.events.stream import EventStream


def test_time_gaps_use_the_larger_of_relative_and_absolute_thresholds():
    t = np.concatenate([np.arange(0, 1000, 10), [200_000], 200_000 + np.arange(0, 1000, 10)])
    start, length, thr = time_gaps(t)
    assert thr == 50_000 and start.tolist() == [990] and length.tolist() == [199_010]
    sparse = np.arange(0, 10_000_000, 100_000)  # median 100 ms -> threshold 1 s
    assert time_gaps(np.append(sparse, 12_000_000))[0].tolist() == [9_900_000]


def test_hot_pixels_exceed_twenty_times_the_median_active_count():
    counts = np.zeros((4, 5), np.int64)
    counts[0, :4] = 2
    counts[1, 1] = 41
    counts[2, 2] = 40
    yx, n, med = hot_pixels(counts)
    assert med == 2.0 and yx.tolist() == [[1, 1]] and n.tolist() == [41]


def test_warnings_report_gaps_and_hot_pixels():
    n = 400
    rng = np.random.default_rng(0)
    t = np.sort(rng.integers(0, 100_000, n))
    t[n // 2:] += 500_000
    x, y = rng.integers(0, 20, n), rng.integers(0, 20, n)
    x[:100], y[:100] = 3, 4
    s = EventStream.create(t, x, y, np.ones(n, int), 20, 20)
    w = stream_warnings(s)
    assert any("time gap" in m for m in w) and any("(x=3, y=4)" in m for m in w)


def test_frames_outside_events():
    assert frames_outside_events(np.array([0, 10, 90]), np.array([5, 20, 120]), 2, 100).tolist() == [0, 2]


def _moving_grating(theta_sigma: float, seed: int = 0):
    """A grating translating across a 40x30 grey sensor for 1 s (every pixel sweeps the same
    phases, so its counts differ from its neighbours' only by its threshold), through the DVS
    model with per-pixel thresholds of the given spread."""
    from fusiongs.sim.dvs import DVSParams, dvs_events, pixel_thresholds

    w, h, k = 40, 30, 800
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, k + 1)
    x, y = np.meshgrid(np.arange(w), np.arange(h))
    u = (x[None] - 57.0 * t[:, None, None] + 0 * y[None]) / 10.0  # 5.7 periods pass every pixel
    logs = (0.8 * np.sin(2 * np.pi * u) + 0.3 * np.sin(2 * np.pi * 2 * u)).reshape(k + 1, -1)
    on, off = pixel_thresholds(DVSParams(theta_on=0.2, theta_off=0.25, theta_sigma=theta_sigma,
                                         theta_min=0.05), w * h, rng)
    tt, pix, p = dvs_events(logs.astype(np.float32), t, on, off, 0.0)
    ev = EventStream.create(tt, pix % w, pix // w, p, w, h)
    return ev, np.array([np.var(np.log(on)), np.var(np.log(off))])


def test_threshold_spread_measures_the_pixels_mismatch():
    from fusiongs.events.dead_time import threshold_spread

    ev, true_var = _moving_grating(0.04)
    var, n = threshold_spread(ev, np.zeros(ev.height * ev.width, bool))
    assert np.all(n > 1000)
    # (the reversal dead zone ties a pixel's OFF count to its ON threshold a little: OFF ~ +15 %)
    assert np.all(np.abs(var / true_var - 1) < 0.2), (var, true_var)
    ev0, _ = _moving_grating(0.0)
    var0, _ = threshold_spread(ev0, np.zeros(ev0.height * ev0.width, bool))
    assert np.all(var0 < 0.1 * true_var), var0
    # too few events to tell: no correction rather than a guess
    few = ev.slice_time(0, 20_000)
    var_few, n_few = threshold_spread(few, np.zeros(few.height * few.width, bool))
    assert np.all(var_few == 0) and np.all(n_few < 200)
