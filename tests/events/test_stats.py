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
