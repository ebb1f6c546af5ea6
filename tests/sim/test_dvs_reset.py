"""The reset pixel (``DVSParams.refractory_reset``): parity with a per-pixel reference, the same
events as the default pixel without a refractory period, the changes it loses, and the CLI."""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np
import pytest

from fusiongs.commands import simulate as sim_cmd
from fusiongs.errors import InputError
from fusiongs.sim import dvs
from fusiongs.sim.simulate import SimConfig
from tests.sim.test_dvs import _random_logs, pixel_segments


def reference_reset(logs, times, th_on, th_off, refractory, drift=None, ref0=None):
    """Slow model: every pixel, every step, one event at a time; at the end of the blind time the
    stored level becomes the signal's level at that instant (linear within a step)."""
    events = []
    for i in range(logs.shape[1]):
        ref, release = float(logs[0, i] if ref0 is None else ref0[i]), -math.inf
        for t0, t1, a, b in pixel_segments(logs, times, i, drift):
            slope = (b - a) / (t1 - t0)

            def level(t, a=a, slope=slope, t0=t0):
                return a + slope * (t - t0)

            if release > t1:
                continue
            now = t0
            if release > t0:
                ref, now = level(release), release
            while True:
                if slope > 0 and b - ref >= th_on[i]:
                    sign, tau = 1, t0 + (ref + th_on[i] - a) / slope
                elif slope < 0 and ref - b >= th_off[i]:
                    sign, tau = -1, t0 + (ref - th_off[i] - a) / slope
                else:
                    break
                tau = max(tau, now)
                events.append((int(np.rint(tau * 1e6)), i, sign))
                release = tau + refractory
                if release > t1:
                    break
                ref, now = level(release), release
    return sorted(events)


def _sorted(ev):
    t, pix, p = ev
    return sorted(zip(t.tolist(), pix.tolist(), p.tolist()))


@pytest.mark.parametrize("refractory", [0.0, 300e-6, 1.7e-3])
def test_reset_pixel_equals_the_per_pixel_reference(rng, refractory):
    logs = _random_logs(rng)
    times = np.linspace(0.0, 0.04, logs.shape[0])
    params = dvs.DVSParams(leak_rate_hz=200.0)
    th_on, th_off = dvs.pixel_thresholds(params, logs.shape[1], rng)
    drift, phase = dvs.leak_drift(params, th_on, rng)
    ref0 = logs[0] - phase * th_on
    fast = dvs.dvs_events_reset(logs, times, th_on, th_off, refractory)
    assert _sorted(fast) == reference_reset(logs, times, th_on, th_off, refractory)
    assert np.all(np.diff(fast[0]) >= 0)
    leak = dvs.dvs_events_reset(logs, times, th_on, th_off, refractory, drift=drift, ref0=ref0)
    assert _sorted(leak) == reference_reset(logs, times, th_on, th_off, refractory, drift, ref0)


def test_without_a_refractory_period_the_reset_pixel_is_the_default_pixel(rng):
    logs = _random_logs(rng, steps=200, pixels=50)
    times = np.linspace(0.0, 0.2, logs.shape[0])
    th_on, th_off = dvs.pixel_thresholds(dvs.DVSParams(), logs.shape[1], rng)
    assert _sorted(dvs.dvs_events_reset(logs, times, th_on, th_off, 0.0)) == \
        _sorted(dvs.dvs_events(logs, times, th_on, th_off, 0.0))


def test_reset_pixel_loses_the_change_during_its_blind_time():
    # log rises 1.0 in 1 ms: crossings every 250 µs at θ 0.25. A 400 µs blind time: the default
    # pixel keeps its level on the crossings and fires at 250 and 750 µs; the reset pixel stores
    # the level at 650 µs (0.65) and needs 0.9 for its next event, at 900 µs.
    logs = np.array([[0.0], [1.0]], dtype=np.float32)
    times, th = np.array([0.0, 1e-3]), np.array([0.25])
    assert dvs.dvs_events(logs, times, th, th, 400e-6)[0].tolist() == [250, 750]
    assert dvs.dvs_events_reset(logs, times, th, th, 400e-6)[0].tolist() == [250, 900]
    # an edge from near black: the reset pixel's events are at least one blind time apart
    t = np.linspace(0.0, 0.01, 1001)
    ramp = np.log(0.002 + 0.798 * t / 0.01 + 1e-3)[:, None].astype(np.float32)
    one = np.array([0.2])
    t_reset, _, p_reset = dvs.dvs_events_reset(ramp, t, one, one, 1e-3)
    _, _, p_grid = dvs.dvs_events(ramp, t, one, one, 1e-3)
    assert np.diff(t_reset).min() >= 1000
    assert 0 < p_reset.sum() < p_grid.sum() < (ramp[-1, 0] - ramp[0, 0]) / 0.2


def _args(**kw) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    sim_cmd.add_arguments(parser)
    argv = ["-o", "x"]
    for k, val in kw.items():
        argv += [f"--{k}"] if val is True else [f"--{k}", val]
    return parser.parse_args(argv)


def test_cli_sets_the_reset_pixel_with_and_without_a_sweep_seed():
    assert not sim_cmd.config_from_args(_args()).dvs.refractory_reset
    assert sim_cmd.config_from_args(_args(**{"refractory-reset": True})).dvs.refractory_reset
    swept = sim_cmd.config_from_args(_args(**{"refractory-reset": True, "sweep-seed": "3"}))
    plain = sim_cmd.config_from_args(_args(**{"sweep-seed": "3"}))
    assert swept.dvs.refractory_reset and not plain.dvs.refractory_reset
    assert dataclasses.replace(swept.dvs, refractory_reset=False) == plain.dvs  # nothing else moves


def test_validate_refuses_a_reset_flag_that_is_not_a_bool():
    cfg = SimConfig(dvs=dataclasses.replace(dvs.DVSParams(), refractory_reset="yes"))
    with pytest.raises(InputError, match="refractory_reset"):
        cfg.validate()
