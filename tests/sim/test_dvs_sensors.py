"""Sensor non-idealities and asymmetric thresholds: hot pixels, leak events, ON/OFF counts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fusiongs.sim import dvs
from fusiongs.sim.motion import Motion
from fusiongs.sim.presets import get_preset
from fusiongs.sim.simulate import run_simulation

from .conftest import tiny_config


def test_hot_pixels_are_the_requested_fraction_each_firing_at_the_rate_with_one_polarity(rng):
    t, pix, p = dvs.hot_pixel_events(0.01, 400.0, 20000, 0.0, 0.5, rng)
    hot = np.unique(pix)
    assert hot.size == dvs.hot_pixel_count(0.01, 20000) == 200
    per_pixel = np.bincount(pix, minlength=20000)[hot]
    assert abs(per_pixel.mean() - 200.0) < 5.0 and per_pixel.min() > 120  # Poisson(200)
    assert np.all(np.diff(t) >= 0) and t.min() >= 0 and t.max() <= 500_000
    assert t.dtype == np.int64 and pix.dtype == np.int64 and p.dtype == np.int8
    for u in hot[:20]:
        assert np.unique(p[pix == u]).size == 1  # polarity fixed per hot pixel
    assert 0.35 < np.mean([p[pix == u][0] > 0 for u in hot]) < 0.65
    empty = dvs.hot_pixel_events(0.0, 400.0, 20000, 0.0, 0.5, rng)
    assert all(a.size == 0 for a in empty)


def test_leak_alone_fires_on_events_at_the_requested_rate_on_a_static_signal(rng):
    params = dvs.DVSParams(theta_on=0.3, theta_off=0.2, leak_rate_hz=4.0)
    n_pix, duration = 3000, 2.0
    logs = np.full((201, n_pix), -1.5, dtype=np.float32)
    times = np.linspace(0.0, duration, 201)
    th_on, th_off = dvs.pixel_thresholds(params, n_pix, rng)
    drift, phase = dvs.leak_drift(params, th_on, rng)
    t, pix, p = dvs.dvs_events(logs, times, th_on, th_off, 0.0, drift=drift, ref0=logs[0] - phase * th_on)
    assert np.all(p == 1)
    assert t.size / (n_pix * duration) == pytest.approx(4.0, rel=0.03)
    # Random initial phases: the first leak events are spread over the first period.
    first = np.array([t[pix == u][0] for u in range(50)])
    assert first.std() > 0.1 * 250_000


def test_leak_in_a_static_simulated_scene_adds_on_events_at_about_the_rate():
    preset = get_preset("wall")
    still = Motion(target=(0.0, 0.0, 60.0), radius=(60.0, 60.0), azimuth_deg=(0.0, 0.0),
                   height=(0.0, 0.0), shake_pos=0.0, shake_rot_deg=0.0)
    static = dataclasses.replace(preset, motion=still)
    quiet = dvs.DVSParams(ba_rate_hz=0.0)
    none = run_simulation(tiny_config(duration=0.5, frames=1, dvs_rate_hz=100.0, dvs=quiet), preset=static)
    assert len(none.scene.events) == 0  # nothing moves: no events without leak
    leaky = dataclasses.replace(quiet, leak_rate_hz=6.0)
    res = run_simulation(tiny_config(duration=0.5, frames=1, dvs_rate_hz=100.0, dvs=leaky), preset=static)
    ev = res.scene.events
    assert np.all(ev.p > 0)
    assert len(ev) / (32 * 24 * 0.5) == pytest.approx(6.0, rel=0.1)
    assert res.stats["leak_rate_hz"] == 6.0


def test_hot_pixels_in_a_simulated_scene_and_their_stats():
    params = dvs.DVSParams(ba_rate_hz=0.0, hot_pixel_fraction=0.02, hot_pixel_rate_hz=2000.0)
    res = run_simulation(tiny_config(dvs=params))
    counts = np.bincount(res.scene.events.y.astype(np.int64) * 32 + res.scene.events.x, minlength=32 * 24)
    busy = np.flatnonzero(counts > 150)  # hot: Poisson(240) in 0.12 s; scene pixels fire far less
    assert busy.size == res.stats["hot_pixels"] == round(0.02 * 32 * 24)
    assert res.stats["events_hot"] > 0.8 * busy.size * 240


@pytest.mark.parametrize("theta_on, theta_off", [(0.15, 0.3), (0.4, 0.2), (0.1, 0.6)])
def test_asymmetric_thresholds_give_on_and_off_counts_of_change_over_threshold(rng, theta_on, theta_off):
    # Every pixel's log intensity ramps up by 8 and back down: N_ON = floor(8 / theta_on) and the
    # way down, from the last ON level, N_OFF = floor(N_ON theta_on / theta_off): N ~ 8 / theta
    # for both polarities, whichever threshold is the larger.
    params = dvs.DVSParams(theta_on=theta_on, theta_off=theta_off, theta_sigma=0.0, refractory_s=0.0)
    n_pix, delta = 400, 8.0
    ramp = np.concatenate([np.linspace(0.0, delta, 51), np.linspace(delta, 0.0, 51)[1:]])
    logs = (ramp[:, None] - 2.0 + 0.05 * rng.random(n_pix)[None]).astype(np.float32)
    th_on, th_off = dvs.pixel_thresholds(params, n_pix, rng)
    _, pix, p = dvs.dvs_events(logs, np.linspace(0.0, 0.1, logs.shape[0]), th_on, th_off, 0.0)
    n_on = np.bincount(pix[p > 0], minlength=n_pix)
    n_off = np.bincount(pix[p < 0], minlength=n_pix)
    tol = 1e-6
    assert np.all((n_on * theta_on <= delta + tol) & (n_on * theta_on > delta - theta_on - tol))
    up = n_on * theta_on
    assert np.all((n_off * theta_off <= up + tol) & (n_off * theta_off > up - theta_off - tol))
    assert delta / n_on.mean() == pytest.approx(theta_on, rel=0.1)
    assert delta / n_off.mean() == pytest.approx(theta_off, rel=0.1)
    assert n_off.mean() / n_on.mean() == pytest.approx(theta_on / theta_off, rel=0.1)


def test_asymmetric_threshold_spread_keeps_the_mean_counts(rng):
    # With a per-pixel spread of 0.05 the mean count still follows the nominal thresholds (up to
    # the convexity of 1 / theta and the clamp at theta_min).
    params = dvs.DVSParams(theta_on=0.5, theta_off=0.25, theta_sigma=0.05, refractory_s=0.0)
    n_pix, delta = 2000, 6.0
    ramp = np.concatenate([np.linspace(0.0, delta, 61), np.linspace(delta, 0.0, 61)[1:]])
    logs = (ramp[:, None] + 0.05 * rng.random(n_pix)[None]).astype(np.float32)
    th_on, th_off = dvs.pixel_thresholds(params, n_pix, rng)
    _, pix, p = dvs.dvs_events(logs, np.linspace(0.0, 0.1, logs.shape[0]), th_on, th_off, 0.0)
    n_on, n_off = (p > 0).sum() / n_pix, (p < 0).sum() / n_pix
    assert n_on * 0.5 / delta == pytest.approx(1.0, abs=0.05)
    assert n_off * 0.25 / delta == pytest.approx(1.0, abs=0.06)
    assert n_off / n_on == pytest.approx(2.0, rel=0.08)
