"""Held-out frames (docs/method.md §6a): index rule, event counts, carrying with events, sharpness."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.edi import event_count_samples
from fusiongs.errors import InputError
from fusiongs.eval.holdout import (
    carried_exposure,
    carry_linear,
    compare_sharpness,
    event_counts_at,
    frame_subset,
    heldout_summary,
    holdout_indices,
    kept_neighbours,
    nearest_kept,
    parse_holdout,
    tenengrad,
)
from fusiongs.events.cfa import cfa_channel_index
from fusiongs.events.stream import EventStream
from fusiongs.events.thresholds import SensorThresholds
from fusiongs.frames.frameset import FrameSet


def _stream(t_s, x, y, p, width, height, cfa=None) -> EventStream:
    t_us = np.round(np.asarray(t_s, np.float64) * 1e6)
    return EventStream.create(t_us, np.asarray(x), np.asarray(y), np.asarray(p), width, height, cfa,
                              sort=True)


def _ramp_events(rates: np.ndarray, theta: float, t_end: float) -> EventStream:
    """Events of a log-intensity ramp ``log L(t) = log L0 + r t`` per pixel (``rates`` ``[H, W]``
    in log units per second), fired at every crossing of a multiple of ``theta`` from ``t = 0``."""
    h, w = rates.shape
    ts, xs, ys, ps = [], [], [], []
    for yy in range(h):
        for xx in range(w):
            r = rates[yy, xx]
            if r == 0:
                continue
            tn = np.arange(1, int(abs(r) * t_end / theta) + 1) * theta / abs(r)
            ts.append(tn)
            xs.append(np.full(tn.size, xx))
            ys.append(np.full(tn.size, yy))
            ps.append(np.full(tn.size, 1 if r > 0 else -1))
    return _stream(np.concatenate(ts), np.concatenate(xs), np.concatenate(ys), np.concatenate(ps), w, h)


def test_carry_follows_a_log_intensity_ramp_forward_and_backward():
    theta = 0.01
    rates = np.array([[3.0, -2.0, 0.5, 0.0], [-4.0, 1.0, 0.0, 6.0]])
    l0 = np.array([[0.2, 0.5, 0.3, 0.7], [0.6, 0.1, 0.4, 0.05]])[..., None]
    events = _ramp_events(rates, theta, 0.3)
    truth = lambda t: l0 * np.exp(rates[..., None] * t)  # noqa: E731
    t_ref = 0.15
    times = np.array([0.01, 0.05, 0.149, 0.16, 0.2, 0.27])  # before and after t_ref
    counts = event_counts_at(events, t_ref, times)
    assert counts.shape == (6, 2, 2, 4) and counts[:3].max() <= 0 <= counts[3:].min()
    carried = carry_linear(truth(t_ref), counts, theta, None)
    for k, t in enumerate(times):
        # events quantise the ramp: the carried log intensity is within one threshold of the truth
        err = np.abs(np.log(carried[k]) - np.log(truth(t)))
        assert err.max() <= theta * 1.001, (t, err.max())
    # the exposure mean, in linear light, matches the truth's mean over the same instants
    from fusiongs.losses.blur import exposure_instants

    inst = exposure_instants(0.2, 0.25, 7).numpy()
    mean_truth = np.mean([truth(t) for t in inst], axis=0)
    pred = carried_exposure(truth(t_ref), events, t_ref, 0.2, 0.25, 7, theta)
    np.testing.assert_allclose(pred, mean_truth, rtol=theta * 1.01)


def test_carry_is_exact_for_the_steps_the_events_encode_on_a_colour_sensor(rng):
    """Per-channel ON/OFF thresholds on an RGGB sensor: a raw pixel's log intensity steps by its own
    channel's theta at each of its events; carrying reproduces it exactly at every instant."""
    h, w, cfa = 6, 8, "RGGB"
    th = SensorThresholds(("R", "G", "B"), np.array([0.2, 0.25, 0.1]), np.array([0.3, 0.15, 0.4]),
                          np.full(3, np.nan), np.full(3, np.nan))
    n = 400
    ev = _stream(np.sort(rng.uniform(0, 1, n)), rng.integers(0, w, n), rng.integers(0, h, n),
                 rng.choice([-1, 1], n), w, h, cfa)
    ch = cfa_channel_index(cfa, h, w)
    log0 = rng.uniform(-2, 0, (h, w))

    def raw_truth(t: float) -> np.ndarray:  # log intensity of each raw pixel at t (events t_e < t)
        sel = ev.t < t * 1e6
        up = np.zeros((h, w))
        np.add.at(up, (ev.y[sel], ev.x[sel]), np.where(ev.p[sel] > 0, th.theta_pos[ch[ev.y[sel], ev.x[sel]]],
                                                       -th.theta_neg[ch[ev.y[sel], ev.x[sel]]]))
        return log0 + up

    t_ref = 0.5
    rgb = np.repeat(np.exp(raw_truth(t_ref))[..., None], 3, axis=-1)  # own channel = raw value
    times = [0.1234567, 0.31, 0.5, 0.77, 0.9999]
    carried = carry_linear(rgb, event_counts_at(ev, t_ref, times), th, cfa)
    assert carried.shape == (5, h, w, 3)
    yy, xx = np.mgrid[:h, :w]
    for k, t in enumerate(times):
        np.testing.assert_allclose(np.log(carried[k][yy, xx, ch]), raw_truth(t), atol=1e-9)


def test_event_counts_at_agrees_with_the_edi_counts_at_mid_exposure(rng):
    n = 3000
    ev = _stream(np.sort(rng.uniform(0, 0.1, n)), rng.integers(0, 9, n), rng.integers(0, 7, n),
                 rng.choice([-1, 1], n), 9, 7)
    s, e, m = 0.02, 0.07, 9
    ts = s + (np.arange(m) + 0.5) / m * (e - s)
    np.testing.assert_array_equal(event_counts_at(ev, 0.5 * (s + e), ts), event_count_samples(ev, s, e, m))


def test_carry_without_events_keeps_the_image():
    img = np.full((3, 4, 3), 0.25)
    ev = EventStream.empty(4, 3)
    np.testing.assert_allclose(carried_exposure(img, ev, 0.1, 0.2, 0.3, 5, (0.2, 0.2)), img)


@pytest.mark.parametrize("n, k, expected", [
    (10, 2, [1, 3, 5, 7]),      # 9 is the last frame: kept
    (9, 2, [1, 3, 5, 7]),
    (10, 3, [2, 5, 8]),
    (4, 3, [2]),
    (3, 3, []),                 # 2 is the last frame
    (2, 2, []),
    (5, 0, []),
])
def test_holdout_indices_follow_the_rule(n, k, expected):
    got = holdout_indices(n, k).tolist()
    assert got == expected
    assert 0 not in got and n - 1 not in got
    assert all(i % k == k - 1 for i in got)
    assert all(b - a >= 2 for a, b in zip(got, got[1:]))  # never two held-out frames side by side


def test_parse_holdout_accepts_off_and_k_of_at_least_two():
    assert parse_holdout(None) == 0 and parse_holdout("0") == 0 and parse_holdout(0) == 0
    assert parse_holdout("2") == 2 and parse_holdout(5) == 5
    for bad in ("1", 1, "-2", "x", "2.5", True):
        with pytest.raises(InputError, match="--holdout"):
            parse_holdout(bad)


def test_neighbours_nearest_and_subset():
    kept = [0, 2, 3, 5]
    assert kept_neighbours(kept, 1) == (0, 2) and kept_neighbours(kept, 4) == (3, 5)
    assert kept_neighbours([1, 2], 0) == (None, 1) and kept_neighbours([1, 2], 3) == (2, None)
    mids = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.5])
    assert nearest_kept(mids, kept, 1) == 0  # tie between 0 and 2: the earlier frame
    assert nearest_kept(mids, kept, 4) == 3
    fs = FrameSet(np.arange(6, dtype=np.float32).reshape(6, 1, 1, 1) / 10, mids - 0.1, mids + 0.1,
                  tuple(f"{i:06d}" for i in range(6)), "linear")
    sub = frame_subset(fs, kept)
    assert sub.names == ("000000", "000002", "000003", "000005") and len(fs) == 6
    np.testing.assert_allclose(sub.images[:, 0, 0, 0], [0.0, 0.2, 0.3, 0.5])
    np.testing.assert_allclose(sub.t_start, mids[kept] - 0.1)


def test_tenengrad_prefers_sharp_edges_and_summary_skips_missing():
    sharp = np.zeros((16, 16, 3))
    sharp[:, 8:] = 1.0
    blurry = np.repeat(np.repeat(np.clip((np.arange(16) - 4) / 8, 0, 1)[None, :, None], 16, 0), 3, 2)
    assert tenengrad(sharp) > 2 * tenengrad(blurry) > 0
    assert tenengrad(np.full((8, 8, 1), 0.5)) == 0.0
    s = compare_sharpness({"a": {"deblur_1": sharp, "novel_x": blurry}, "b": {"novel_x": blurry}})
    assert set(s) == {"a"} and s["a"]["n"] == 1
    m = heldout_summary({"f1": {"fusiongs": 30.0, "nearest": 20.0, "edi_carried": None},
                         "f2": {"fusiongs": 32.0, "nearest": 22.0, "edi_carried": 25.0}})
    assert m["fusiongs"] == {"psnr": 31.0, "n": 2} and m["edi_carried"] == {"psnr": 25.0, "n": 1}
