"""The DVS pixel model: parity with a per-pixel reference, threshold accounting, timing, noise."""

from __future__ import annotations

import math

import numpy as np
import torch

from fusiongs.sim import dvs


def pixel_segments(logs, times, i, drift=None):
    """``(t0, t1, a, b)`` of pixel ``i`` per render step: its log intensity at both ends, a leak
    ``drift`` added to the signal (``drift * (t - t0)``, the same as lowering the reference)."""
    for k in range(logs.shape[0] - 1):
        a, b = float(logs[k, i]), float(logs[k + 1, i])
        if drift is not None:
            a += drift[i] * (times[k] - times[0])
            b += drift[i] * (times[k + 1] - times[0])
        yield float(times[k]), float(times[k + 1]), a, b


def reference_dvs(logs, times, th_on, th_off, refractory, drift=None, ref0=None):
    """Slow, obviously-correct model: every pixel, every step, one crossing at a time. A leak
    ``drift`` lowers the reference by ``drift * (t - t0)``: the same as raising the signal."""
    events = []
    for i in range(logs.shape[1]):
        ref, t_last = float(logs[0, i] if ref0 is None else ref0[i]), -math.inf
        for t0, t1, a, b in pixel_segments(logs, times, i, drift):
            dt = t1 - t0
            while True:
                if b - ref >= th_on[i]:
                    sign, th = 1, th_on[i]
                elif ref - b >= th_off[i]:
                    sign, th = -1, th_off[i]
                else:
                    break
                ref += sign * th
                tau = t0 + min(max((ref - a) / (b - a), 0.0), 1.0) * dt
                if tau - t_last >= refractory - 1e-12:
                    events.append((int(np.rint(tau * 1e6)), i, sign))
                    t_last = tau
    return sorted(events)


def _random_logs(rng, steps=40, pixels=30):
    # Smooth random walks with occasional jumps of several thresholds in one step.
    jumps = (rng.random((steps, pixels)) < 0.05) * rng.normal(0, 1.2, (steps, pixels))
    inc = rng.normal(0, 0.12, size=(steps, pixels)) + jumps
    return np.concatenate([np.zeros((1, pixels)), np.cumsum(inc, axis=0)]).astype(np.float32) - 2.0


def test_vectorised_events_equal_the_per_pixel_reference(rng):
    logs = _random_logs(rng)
    times = np.linspace(0.0, 0.04, logs.shape[0])
    th_on, th_off = dvs.pixel_thresholds(dvs.DVSParams(), logs.shape[1], rng)
    for refractory in (0.0, 300e-6):
        t, pix, p = dvs.dvs_events(logs, times, th_on, th_off, refractory)
        fast = sorted(zip(t.tolist(), pix.tolist(), p.tolist()))
        assert fast == reference_dvs(logs, times, th_on, th_off, refractory)
        assert np.all(np.diff(t) >= 0)


def test_leak_drift_and_initial_reference_equal_the_per_pixel_reference(rng):
    logs = _random_logs(rng)
    times = np.linspace(0.0, 0.04, logs.shape[0])
    params = dvs.DVSParams(leak_rate_hz=200.0)  # fast leak: several leak events in 40 ms
    th_on, th_off = dvs.pixel_thresholds(params, logs.shape[1], rng)
    drift, phase = dvs.leak_drift(params, th_on, rng)
    ref0 = logs[0] - phase * th_on
    for refractory in (0.0, 300e-6):
        t, pix, p = dvs.dvs_events(logs, times, th_on, th_off, refractory, drift=drift, ref0=ref0)
        fast = sorted(zip(t.tolist(), pix.tolist(), p.tolist()))
        assert fast == reference_dvs(logs, times, th_on, th_off, refractory, drift, ref0)


def test_signed_threshold_sum_tracks_log_change_within_one_threshold(rng):
    # Without refractory losses the reference level stays within (-theta_off, theta_on) of the
    # signal, so sum(p * theta_p) differs from the total log change by less than one threshold.
    logs = _random_logs(rng, steps=200, pixels=50)
    times = np.linspace(0.0, 0.2, logs.shape[0])
    th_on, th_off = dvs.pixel_thresholds(dvs.DVSParams(), logs.shape[1], rng)
    _, pix, p = dvs.dvs_events(logs, times, th_on, th_off, 0.0)
    on = np.bincount(pix[p > 0], minlength=50)
    off = np.bincount(pix[p < 0], minlength=50)
    change = logs[-1].astype(np.float64) - logs[0]
    err = on * th_on - off * th_off - change
    assert np.all(err <= th_off + 1e-6) and np.all(err >= -th_on - 1e-6)
    assert on.sum() > 100 and off.sum() > 100


def test_ramp_gives_evenly_spaced_interpolated_timestamps():
    # log rises by 1.0 over one 1 ms step: 4 ON events at threshold 0.25, at 0.25, 0.5, 0.75, 1 ms.
    logs = np.array([[0.0], [1.0]], dtype=np.float32)
    t, _, p = dvs.dvs_events(logs, np.array([0.0, 1e-3]), np.array([0.25]), np.array([0.2]), 0.0)
    assert t.tolist() == [250, 500, 750, 1000] and p.tolist() == [1, 1, 1, 1]
    # A 400 µs refractory period keeps every second one.
    t, _, _ = dvs.dvs_events(logs, np.array([0.0, 1e-3]), np.array([0.25]), np.array([0.2]), 400e-6)
    assert t.tolist() == [250, 750]


def test_count_events_matches_the_event_model_without_refractory(rng):
    logs = _random_logs(rng)
    th_on, th_off = dvs.pixel_thresholds(dvs.DVSParams(), logs.shape[1], rng)
    t, _, _ = dvs.dvs_events(logs, np.linspace(0, 0.04, logs.shape[0]), th_on, th_off, 0.0)
    assert dvs.count_events(logs, th_on, th_off) == t.size


def test_threshold_mismatch_has_the_configured_spread(rng):
    on, off = dvs.pixel_thresholds(dvs.DVSParams(theta_on=0.3, theta_off=0.2, theta_sigma=0.03), 20000, rng)
    assert abs(on.mean() - 0.3) < 2e-3 and abs(off.mean() - 0.2) < 2e-3
    assert abs(on.std() - 0.03) < 2e-3


def test_background_activity_rate_and_polarity_balance(rng):
    t, pix, p = dvs.background_activity(2.0, 1000, 0.0, 5.0, rng)
    assert abs(t.size - 10000) < 500  # Poisson, sd 100
    assert np.all(np.diff(t) >= 0) and t.min() >= 0 and t.max() <= 5_000_000
    assert pix.min() >= 0 and pix.max() < 1000 and abs((p > 0).mean() - 0.5) < 0.03


def test_grey_sensor_uses_rec601_and_colour_sensor_one_channel_per_pixel():
    rgb = torch.zeros(2, 2, 3)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 0.5, 0.25, 0.125
    grey = dvs.sensor_log(rgb, None, 1e-3)
    assert np.allclose(grey, np.log(0.299 * 0.5 + 0.587 * 0.25 + 0.114 * 0.125 + 1e-3))
    raw = dvs.sensor_log(rgb, "RGGB", 1e-3).reshape(2, 2)
    expected = np.log(np.array([[0.5, 0.25], [0.25, 0.125]]) + 1e-3)
    assert np.allclose(raw, expected)


def test_threshold_gradient_varies_thresholds_from_left_to_right():
    import numpy as np

    from fusiongs.sim.dvs import DVSParams, pixel_thresholds

    p = DVSParams(theta_sigma=0.0, theta_gradient=0.4)
    on, off = pixel_thresholds(p, 4 * 10, np.random.default_rng(0), width=10)
    on = on.reshape(4, 10)
    assert np.allclose(on[:, 0], 0.25 * 0.6) and np.allclose(on[:, -1], 0.25 * 1.4)
    assert np.all(np.diff(on, axis=1) > 0)
    flat, _ = pixel_thresholds(DVSParams(theta_sigma=0.0), 40, np.random.default_rng(0), width=10)
    assert np.allclose(flat, 0.25)
