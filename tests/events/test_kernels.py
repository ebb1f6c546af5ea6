"""The one-pass event kernels against their numpy specification (tests/reference/event_kernels.py)."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.events.dead_time import dead_time_us, fast_event_counts
from fusiongs.events.stats import _median_interval, fast_event_mask, time_gaps
from fusiongs.events.stream import EventStream
from tests.reference import event_kernels as ref


def _stream(n: int, seed: int, w: int = 7, h: int = 5, span: int = 20_000) -> EventStream:
    """Random events on a small sensor: many same-pixel pairs, repeated timestamps."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, span, n)).astype(np.int64)
    return EventStream(t, rng.integers(0, w, n).astype(np.uint16), rng.integers(0, h, n).astype(np.uint16),
                       rng.choice(np.array([-1, 1], np.int8), n), w, h)


@pytest.mark.parametrize("seed", range(4))
def test_count_maps_match_the_bincount(seed):
    ev = _stream(3000, seed)
    np.testing.assert_array_equal(ev.count_maps(), ref.count_maps(ev))
    i0, i1 = ev.index_range(5000, 12000)
    np.testing.assert_array_equal(ev.count_maps(5000, 12000), ref.count_maps(ev, i0, i1))
    np.testing.assert_array_equal(ev.pixel_counts(), ref.count_maps(ev).sum(0))
    assert ev.count_maps(7, 7).sum() == 0


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("gap", [0.5, 1.0, 37.0, 250.5])
def test_fast_events_match_the_sorted_pixel_intervals(seed, gap):
    ev = _stream(3000, seed)
    np.testing.assert_array_equal(fast_event_mask(ev, gap), ref.fast_event_mask(ev, gap))
    edges = np.array([-5, 0, 3000, 3001, 9000, 15000], np.int64)
    np.testing.assert_array_equal(fast_event_counts(ev, gap, edges), ref.fast_event_counts(ev, gap, edges))


def test_interval_histogram_matches_numpy_and_the_dead_time_is_unchanged():
    from fusiongs.events._kernels import interval_histogram

    ev = _stream(20000, 3, span=400_000)
    edges = np.unique(np.round(np.geomspace(1.0, 1e5, 81)))
    h, n = interval_histogram(ev.t, ev.x, ev.y, ev.width, ev.height * ev.width, edges)
    h_ref, n_ref = ref.interval_histogram(ev, edges)
    np.testing.assert_array_equal(h, h_ref)
    assert n == n_ref
    # the closed last bin of np.histogram: an interval equal to the last edge counts
    last = EventStream(np.array([0, int(edges[-1])], np.int64), np.zeros(2, np.uint16),
                       np.zeros(2, np.uint16), np.ones(2, np.int8), 1, 1)
    h, n = interval_histogram(last.t, last.x, last.y, 1, 1, edges)
    assert h[-1] == 1 and n == 1
    assert dead_time_us(ev) == 0.0


@pytest.mark.parametrize("n", [2, 3, 10, 1001])
def test_time_gaps_in_chunks_match_the_whole_diff(n, monkeypatch):
    import fusiongs.events.stats as stats

    monkeypatch.setattr(stats, "CHUNK", 7)  # many chunks, boundaries everywhere
    rng = np.random.default_rng(n)
    t = np.sort(rng.integers(0, 300 * n, n)).astype(np.int64)
    t[n // 2:] += 2_000_000  # one long gap
    dt = np.diff(t)
    assert _median_interval(t) == float(np.median(dt))
    start, length, thr = time_gaps(t, 10.0, 1000)
    i = np.flatnonzero(dt > thr)
    np.testing.assert_array_equal(start, t[i])
    np.testing.assert_array_equal(length, dt[i])


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("window", [(0.001, 0.009), (0.0, 0.02), (0.0071, 0.0072)])
def test_exposure_counts_match_the_bincount(seed, window):
    from fusiongs.edi import event_count_samples

    ev = _stream(4000, seed)
    s, e = window
    m = 9
    s_us, e_us = s * 1e6, e * 1e6
    ts = s_us + (np.arange(m) + 0.5) / m * (e_us - s_us)
    i0, i1 = ev.index_range(int(np.floor(s_us)), int(np.ceil(e_us)) + 1)
    np.testing.assert_array_equal(event_count_samples(ev, s, e, m),
                                  ref.exposure_counts(ev, ts, 0.5 * (s_us + e_us), i0, i1))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("dead", [0.0, 1.0, 40.0, 333.5])
@pytest.mark.parametrize("burst_end", [False, True])
def test_reset_weights_match_the_sorted_pixel_intervals(seed, dead, burst_end):
    from fusiongs.events.dead_time import reset_weights

    ev = _stream(3000, seed)
    w = reset_weights(ev, dead, cap=4.0, burst_end=burst_end)
    assert w.dtype == np.float32 and w.shape == (len(ev),)
    want = ref.reset_weights(ev, dead, 4.0, burst_end) if dead > 0 else np.ones(len(ev))
    np.testing.assert_allclose(w, want, rtol=1e-6)
    if dead > 0:
        top = 4.0 + 15.0 / 8.0 + 1e-5 if burst_end else 4.0  # (w^2 - 1) / (2 w) at the cap
        assert (w >= 1).all() and (w <= top).all() and (w > 1).any()
        plain = reset_weights(ev, dead, cap=4.0, burst_end=False)
        assert (w >= plain).all() and ((w > plain).any() == burst_end)


def test_a_reset_weight_is_the_crossings_at_a_steady_rate():
    """One pixel firing every d + theta / r: each event after the first stands for (theta + r d) /
    theta; the burst's last event adds the blind time after it, (w^2 - 1) / (2 w) on average."""
    from fusiongs.events.dead_time import reset_weights

    d, gap = 500.0, 250.0  # dead time and time to a threshold after the release (µs): r d = 2 theta
    t = np.arange(6, dtype=np.int64) * int(d + gap)
    ev = EventStream(t, np.zeros(6, np.uint16), np.zeros(6, np.uint16), np.ones(6, np.int8), 1, 1)
    np.testing.assert_allclose(reset_weights(ev, d, cap=10.0, burst_end=False), [1, 3, 3, 3, 3, 3])
    np.testing.assert_allclose(reset_weights(ev, d, cap=2.5, burst_end=False), [1, 2.5, 2.5, 2.5, 2.5, 2.5])
    np.testing.assert_allclose(reset_weights(ev, d, cap=10.0), [1, 3, 3, 3, 3, 3 + 8 / 6], rtol=1e-6)
    # a slower event after the burst takes the place of "no next event" in part
    t2 = np.append(t, t[-1] + 3 * int(d))  # w_next = 1.5
    ev2 = EventStream(t2, np.zeros(7, np.uint16), np.zeros(7, np.uint16), np.ones(7, np.int8), 1, 1)
    want = [1, 3, 3, 3, 3, 3 + 8 / 6 - 0.5, 1.5 + 1.25 / 3]
    np.testing.assert_allclose(reset_weights(ev2, d, cap=10.0), want, rtol=1e-6)


def test_reset_weights_count_a_reset_pixels_change_on_ramps_that_stop():
    """The simulator's reset pixel (:func:`fusiongs.sim.dvs.dvs_events_reset`) on ramps of 0.3 to 3
    thresholds a dead time that stop after 2-8 ms: the weighted counts are 8 % short without the
    burst's end, within 3 % with it."""
    from fusiongs.events.dead_time import reset_weights
    from fusiongs.sim.dvs import dvs_events_reset

    rng = np.random.default_rng(0)
    n, d, theta = 4000, 500e-6, 0.2
    times = np.linspace(0.0, 0.1, 2001)
    rate = theta / d * rng.uniform(0.3, 3.0, n)
    stop = 0.01 + rng.uniform(0.002, 0.008, n)
    logs = np.minimum(rate[None] * np.clip(times[:, None] - 0.01, 0, None), (rate * (stop - 0.01))[None])
    t, i, p = dvs_events_reset(logs, times, np.full(n, theta), np.full(n, theta), d)
    ev = EventStream(t, (i % 100).astype(np.uint16), (i // 100).astype(np.uint16), p, 100, n // 100)
    change = float(logs[-1].sum())
    short = reset_weights(ev, d * 1e6, 4.0, burst_end=False).sum() * theta / change - 1
    whole = reset_weights(ev, d * 1e6, 4.0).sum() * theta / change - 1
    assert short < -0.05 and abs(whole) < 0.03


@pytest.mark.parametrize("seed", range(3))
def test_weighted_counts_match_the_bincount(seed):
    from fusiongs.edi import event_count_samples

    ev = _stream(4000, seed)
    w = np.random.default_rng(seed).uniform(1.0, 4.0, len(ev)).astype(np.float32)
    np.testing.assert_allclose(ev.count_maps(weights=w), ref.count_maps(ev, weights=w), rtol=1e-6)
    i0, i1 = ev.index_range(5000, 12000)
    np.testing.assert_allclose(ev.count_maps(5000, 12000, w), ref.count_maps(ev, i0, i1, w), rtol=1e-6)
    np.testing.assert_array_equal(ev.count_maps(weights=np.ones(len(ev))), ev.count_maps())
    s, e, m = 0.001, 0.009, 9
    ts = s * 1e6 + (np.arange(m) + 0.5) / m * (e - s) * 1e6
    i0, i1 = ev.index_range(int(np.floor(s * 1e6)), int(np.ceil(e * 1e6)) + 1)
    got = event_count_samples(ev, s, e, m, w)
    assert got.dtype == np.float32
    want = ref.exposure_counts(ev, ts, 0.5e6 * (s + e), i0, i1, w)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-3)
    with pytest.raises(Exception, match="weights"):
        ev.count_maps(weights=w[:-1])
