"""benchmarks/bench_calibrate_gate.py: the estimator with the refractory gate of another stream."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import fusiongs.eval.calibrate as calibrate
from benchmarks.bench_calibrate_gate import estimate_with_gate, main
from fusiongs.eval.calibrate import CalibrateOptions, estimate_thresholds
from fusiongs.events.stream import EventStream
from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.simulate import SimConfig, run_simulation

STEP = CalibrateOptions(pixel_model="step", bootstrap=0)


@pytest.fixture(scope="module")
def scene():
    dvs = DVSParams(theta_on=0.2, theta_off=0.3, theta_sigma=0.02, refractory_s=6e-4, ba_rate_hz=0.2)
    cfg = SimConfig(preset="wall", width=96, height=72, duration=0.5, frames=6, exposure=0.04,
                    dvs_rate_hz=1000.0, blur_samples=8, supersample=1, novel=0, seed=4, dvs=dvs)
    return run_simulation(cfg).scene


def test_own_gate_reproduces_the_estimator_and_is_undone(scene):
    saved = calibrate.gate_inputs, calibrate.interval_floor
    own = estimate_with_gate(scene.frames, scene.events, scene.events, STEP)
    plain = estimate_thresholds(scene.frames, scene.events, STEP)
    np.testing.assert_array_equal(own.theta_pos, plain.theta_pos)
    np.testing.assert_array_equal(own.theta_neg, plain.theta_neg)
    assert own.details["dead_time_us"] > 0
    assert own.details["per_channel"][0]["refractory_gate"] == "neighbours"
    assert (calibrate.gate_inputs, calibrate.interval_floor) == saved


def test_a_gate_without_dead_time_keeps_every_pair(scene):
    """A gate stream whose intervals show no dead time gates nothing: the fit is the one with the
    gate off, on the fitted stream's counts (the gate really comes from the other stream)."""
    ev = scene.events
    n = 50  # one slow pixel: no refractory floor in its intervals
    quiet = EventStream.create(np.arange(n, dtype=np.int64) * 9_000, np.zeros(n, np.int64),
                               np.zeros(n, np.int64), np.ones(n, np.int64), ev.width, ev.height)
    other = estimate_with_gate(scene.frames, ev, quiet, STEP)
    off = estimate_thresholds(scene.frames, ev, replace(STEP, refractory_gate=0.0))
    gated = estimate_thresholds(scene.frames, ev, STEP)
    np.testing.assert_array_equal(other.theta_pos, off.theta_pos)
    assert other.details["per_channel"][0]["kept"] > gated.details["per_channel"][0]["kept"]


def test_the_dead_time_can_come_from_a_third_stream(scene):
    """``floor_events`` sets the dead time, ``gate_events`` the fast events: the quiet stream has no
    floor of its own (gate off), and with the scene's floor its own gate still leaves every pair
    (the fit is the gate-off one), under the scene's dead time and the own gate's name."""
    ev = scene.events
    own = replace(STEP, refractory_self=True, refractory_radius=0)
    n = 50
    quiet = EventStream.create(np.arange(n, dtype=np.int64) * 9_000, np.zeros(n, np.int64),
                               np.zeros(n, np.int64), np.ones(n, np.int64), ev.width, ev.height)
    alone = estimate_with_gate(scene.frames, ev, quiet, own)
    floored = estimate_with_gate(scene.frames, ev, quiet, own, floor_events=ev)
    scene_own = estimate_thresholds(scene.frames, ev, own)
    assert alone.details["per_channel"][0]["refractory_gate"] == "off"
    assert floored.details["per_channel"][0]["refractory_gate"] == "pixel"
    assert floored.details["dead_time_us"] == scene_own.details["dead_time_us"] > 0
    np.testing.assert_array_equal(floored.theta_pos, alone.theta_pos)
    assert floored.details["per_channel"][0]["kept"] > scene_own.details["per_channel"][0]["kept"]


def test_a_gate_of_another_size_is_refused(scene):
    ev = scene.events
    small = EventStream.create(np.array([0, 5000]), np.array([0, 0]), np.array([0, 0]), np.array([1, 1]),
                               ev.width - 1, ev.height)
    with pytest.raises(ValueError, match="gate's stream"):
        estimate_with_gate(scene.frames, ev, small, STEP)
    with pytest.raises(ValueError, match="dead time's stream"):
        estimate_with_gate(scene.frames, ev, ev, STEP, floor_events=small)


def test_the_gate_follows_the_other_streams_fast_events(scene):
    """The gate stream is the scene's own left half: the same dead time, but no fast events on the
    right half, so more pixel pairs are kept there than under the scene's own gate."""
    ev = scene.events
    left = ev.x < ev.width // 2
    half = EventStream.create(ev.t[left], ev.x[left], ev.y[left], ev.p[left], ev.width, ev.height)
    other = estimate_with_gate(scene.frames, ev, half, STEP)
    own = estimate_thresholds(scene.frames, ev, STEP)
    assert other.details["dead_time_us"] == own.details["dead_time_us"] > 0
    assert other.details["per_channel"][0]["kept"] > own.details["per_channel"][0]["kept"]


def test_a_scene_without_truth_is_refused_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path / "recording"), "--twins", str(tmp_path / "twins")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "recording" in err and "gt/sim.json" in err
