"""benchmarks/bench_calibrate_gate.py: the estimator with the refractory gate of another stream."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import fusiongs.eval.calibrate as calibrate
from benchmarks.bench_calibrate_gate import (
    estimate_with_gate,
    gate_mask,
    instrument_gated_pairs,
    main,
    own_gate_on_instrument,
    true_rate_fast,
)
from fusiongs.eval.calibrate import CalibrateOptions, estimate_thresholds
from fusiongs.eval.calibrate_data import count_inputs, frame_pairs, gate_inputs, saturated, sensor_intensity
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


def _channel_inputs(scene, opts):
    fr, ev = scene.frames, scene.events
    lin = fr.to_linear()
    sens = sensor_intensity(lin, ev.cfa)
    counts, between, _ = count_inputs(fr, ev, opts, None)
    _, fast, _ = gate_inputs(fr, ev, opts, 600.0)
    frame_ok = (sens > 0.03 * np.quantile(sens, 0.99)) & ~saturated(lin, opts)
    return sens, counts, between, fast, frame_ok


def test_instrument_gated_pairs_fit_a_neighbour_gated_by_the_instrument(scene):
    """Every entry is (A, a same-channel neighbour B of it): A's counts as the regressor, B's as
    the instrument, left out exactly where B has fast events in a spanned gap or A is dark or
    saturated; A's own fast events gate nothing."""
    ev = scene.events
    h, w = ev.height, ev.width
    sens, counts, between, fast, frame_ok = _channel_inputs(scene, STEP)
    assert fast.any() and not fast.all()
    rng = np.random.default_rng(0)
    pix = np.sort(rng.choice(h * w, 400, replace=False))
    data = instrument_gated_pairs(sens, counts, between, pix, fast, frame_ok, h, w, 1, 16, 3)
    pairs = frame_pairs(len(scene.frames), 3)
    a_pix, b_pix = [], []
    for dy, dx in ((1, 0), (-1, 0), (0, 1), (0, -1)):  # the brute-force entry list
        for b in pix:
            y, x = divmod(int(b), w)
            if 0 <= y + dy < h and 0 <= x + dx < w:
                a_pix.append((y + dy) * w + x + dx)
                b_pix.append(int(b))
    assert data.dn.shape[-1] == len(a_pix) < 4 * pix.size  # border pixels have fewer neighbours
    for e in rng.choice(len(a_pix), 60, replace=False):
        a, b = a_pix[e], b_pix[e]
        for q, (i, j) in enumerate(pairs):
            np.testing.assert_array_equal(data.dn[q, :, e].numpy(), between[i:j, :, a].sum(0))
            np.testing.assert_array_equal(data.z[q, :, e].numpy(), between[i:j, :, b].sum(0))
            inside = np.abs(counts[i][..., a]).sum() + np.abs(counts[j][..., a]).sum()
            moved = inside + between[i:j, :, a].sum()
            want = frame_ok[i, a] and frame_ok[j, a] and not fast[i:j, b].any() and moved > 0
            assert bool(data.valid[q, e]) == want
    want_log = np.log(np.maximum(sens[:, a_pix], 1e-12)).astype(np.float32)
    np.testing.assert_array_equal(data.log_s.numpy(), want_log)


def test_the_own_gate_on_the_instrument_is_swapped_in_and_undone(scene):
    """Under the own gate the swapped pairs change the fit (more pairs kept: the fitted pixel's
    fast pairs stay in); with the gate off nothing changes; prepare_channel is restored."""
    own = replace(STEP, refractory_self=True, refractory_radius=0)
    saved = calibrate.prepare_channel
    plain = estimate_thresholds(scene.frames, scene.events, own)
    off = estimate_thresholds(scene.frames, scene.events, replace(own, refractory_gate=0.0))
    with own_gate_on_instrument(scene.events.height, 1):
        moved = estimate_thresholds(scene.frames, scene.events, own)
        still_off = estimate_thresholds(scene.frames, scene.events, replace(own, refractory_gate=0.0))
    assert calibrate.prepare_channel is saved
    assert moved.details["per_channel"][0]["refractory_gate"] == "pixel"
    assert moved.details["per_channel"][0]["kept"] > plain.details["per_channel"][0]["kept"]
    assert moved.theta_pos[0] != plain.theta_pos[0]
    np.testing.assert_array_equal(still_off.theta_pos, off.theta_pos)
    np.testing.assert_array_equal(still_off.theta_neg, off.theta_neg)


def test_true_rate_fast_marks_each_pair_by_its_fastest_interval():
    """Against a loop over pairs, pixels and render intervals: an interval counts for a pair when
    it overlaps the span from the first frame's exposure start to the second's end (frame
    boundaries on render instants included), ON and OFF each against their own threshold."""
    rng = np.random.default_rng(3)
    times = np.arange(61) * 1e-3  # 1 ms renders
    steps = rng.normal(0.0, 0.02, (60, 40))
    steps[rng.random((60, 40)) < 0.02] = 0.3  # a few fast rises
    steps[rng.random((60, 40)) < 0.03] = -0.2  # falls fast for ON, not for OFF (0.36 vs 0.3 / 0.45)
    steps[:, :2] = 0.0
    steps[29, 0] = 0.5  # [29, 30] ms: ends where pair 2's span starts (not in it), inside pair 1's
    steps[24, 1] = -0.5  # [24, 25] ms: starts where pair 0's span ends (not in it)
    logs = np.concatenate([np.zeros((1, 40)), np.cumsum(steps, axis=0)])
    t_start = np.array([0.0, 15.5, 30.0, 45.5]) * 1e-3  # two ends on render instants
    t_end = np.array([4.0, 24.0, 40.0, 50.0]) * 1e-3
    gap_us, on, off, factor = 1800.0, 0.2, 0.3, 1.5
    got = true_rate_fast(times, logs, t_start, t_end, gap_us, on, off, factor)
    want = np.zeros((3, 40), bool)
    for i in range(3):
        a, b = t_start[i], t_end[i + 1]
        for p in range(40):
            for j in range(60):
                if times[j + 1] > a and times[j] < b:
                    r = (logs[j + 1, p] - logs[j, p]) / (times[j + 1] - times[j]) * gap_us * 1e-6
                    want[i, p] |= r > factor * on or -r > factor * off
    assert want.any() and not want.all()
    assert want[:, 0].tolist() == [False, True, False] and want[:, 1].tolist() == [False, True, False]
    np.testing.assert_array_equal(got, want)


def test_gate_mask_swaps_the_gate_in_and_out(scene):
    """A mask that marks nothing fits every pair (the gate-off estimate); the pixel's own fast
    events as the mask give the own gate's estimate; the gate inputs and floor are restored."""
    own = replace(STEP, refractory_self=True, refractory_radius=0)
    saved = calibrate.gate_inputs, calibrate.interval_floor
    off = estimate_thresholds(scene.frames, scene.events, replace(own, refractory_gate=0.0))
    plain = estimate_thresholds(scene.frames, scene.events, own)
    shape = (len(scene.frames) - 1, scene.events.width * scene.events.height)
    with gate_mask(lambda gap: np.zeros(shape, bool)):
        none = estimate_thresholds(scene.frames, scene.events, own)
    with gate_mask(lambda gap: gate_inputs(scene.frames, scene.events, own, gap / own.refractory_gate)[1]):
        same = estimate_thresholds(scene.frames, scene.events, own)
    assert (calibrate.gate_inputs, calibrate.interval_floor) == saved
    np.testing.assert_array_equal(none.theta_pos, off.theta_pos)
    np.testing.assert_array_equal(none.theta_neg, off.theta_neg)
    np.testing.assert_array_equal(same.theta_pos, plain.theta_pos)
    np.testing.assert_array_equal(same.theta_neg, plain.theta_neg)
    assert none.details["per_channel"][0]["kept"] > plain.details["per_channel"][0]["kept"]


def test_a_scene_without_truth_is_refused_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path / "recording"), "--twins", str(tmp_path / "twins")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "recording" in err and "gt/sim.json" in err
