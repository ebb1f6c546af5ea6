"""The threshold estimator of ``fusiongs calibrate`` and the command itself."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fusiongs.calibrate.data import refractory_mask
from fusiongs.calibrate.estimate import estimate_thresholds
from fusiongs.calibrate.options import CalibrateOptions
from fusiongs.calibrate.pool import discrepant_channels, shrink_channels
from fusiongs.cli import main
from fusiongs.errors import InputError
from fusiongs.events.dead_time import IntervalFloor, dead_time_us, interval_floor, located_step_us
from fusiongs.events.dead_time import spatial_hot_pixels as hot_pixels
from fusiongs.events.stream import EventStream
from fusiongs.events.thresholds import SensorThresholds, read_calibration, write_calibration
from fusiongs.frames.frameset import FrameSet
from fusiongs.io.scene import Scene
from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene


def _small(cfa, on, off, seed=1, **dvs):
    params = dict(theta_on=on, theta_off=off, theta_sigma=0.02, refractory_s=2e-4, ba_rate_hz=0.5)
    params.update(dvs)
    cfg = SimConfig(preset="wall", width=80, height=60, duration=0.5, frames=6, exposure=0.04, cfa=cfa,
                    dvs_rate_hz=1000.0, blur_samples=8, supersample=1, novel=0, seed=seed,
                    dvs=DVSParams(**params))
    return run_simulation(cfg)


@pytest.fixture(scope="module")
def grey_asym():
    return _small(None, 0.2, 0.35)


@pytest.fixture(scope="module")
def rggb_asym():
    return _small("RGGB", 0.4, 0.25, seed=2)


@pytest.fixture(scope="module")
def grey_dir(tmp_path_factory, grey_asym):
    root = tmp_path_factory.mktemp("calib") / "scene"
    write_simulated_scene(grey_asym.scene, grey_asym.gt, root, stats=grey_asym.stats)
    return root


def _rel(est, true):
    return np.abs(np.asarray(est) / true - 1.0)


# Small scenes (80x60, 6 frames) hold ~25x fewer residuals than a 173x130, 12-frame one: 15 % here.
@pytest.mark.parametrize("case", ["grey_asym", "rggb_asym"])
def test_on_and_off_thresholds_are_recovered_separately(case, request):
    res = request.getfixturevalue(case)
    th = estimate_thresholds(res.scene.frames, res.scene.events)
    on, off = res.stats["theta_on"], res.stats["theta_off"]
    assert th.channels == (("grey",) if res.scene.events.cfa is None else ("R", "G", "B"))
    assert np.all(_rel(th.theta_pos, on) < 0.15), th.theta_pos
    assert np.all(_rel(th.theta_neg, off) < 0.15), th.theta_neg
    # The ratio is what a symmetric estimate cannot give: it must lean the right way.
    assert np.all((th.theta_neg > th.theta_pos) == (off > on))
    assert np.all(np.isfinite(th.std_pos)) and np.all(th.std_pos > 0)
    assert th.scale_known
    if len(th.channels) == 3:  # the channels agree here: none is widened as an outlier
        assert th.details["channel_outliers"] == [[], []]


def test_without_frames_only_the_ratio_is_measured(grey_asym):
    ev = grey_asym.scene.events
    th = estimate_thresholds(FrameSet.empty(ev.height, ev.width), ev, CalibrateOptions(unknown_scale=0.3))
    assert not th.scale_known and "ratio" in th.method
    assert np.isclose(np.sqrt(th.theta_pos * th.theta_neg), 0.3).all()  # the assumed scale
    ratio = th.theta_neg / th.theta_pos
    assert abs(ratio[0] / (0.35 / 0.2) - 1) < 0.25, ratio


def test_one_frame_measures_the_ratio_and_assumes_the_scale(grey_asym):
    """One frame does not fix the scale (its EDI sharpness estimate is only recorded): the result
    is that of no frames, the assumed scale with the events' ON/OFF ratio, and says so."""
    fs = grey_asym.scene.frames
    ev = grey_asym.scene.events
    one = FrameSet(fs.images[:1], fs.t_start[:1], fs.t_end[:1], fs.names[:1], fs.response)
    opts = CalibrateOptions(unknown_scale=0.3)
    th = estimate_thresholds(one, ev, opts)
    assert not th.scale_known and th.method.startswith("one frame") and "assumed" in th.method
    assert 0.02 <= th.details["single_frame_sharpness"] <= 0.8
    none = estimate_thresholds(FrameSet.empty(ev.height, ev.width), ev, opts)
    np.testing.assert_allclose(th.theta_pos, none.theta_pos)
    np.testing.assert_allclose(th.theta_neg, none.theta_neg)


def test_no_events_is_a_named_error(grey_asym):
    ev = grey_asym.scene.events
    with pytest.raises(InputError, match="events"):
        estimate_thresholds(grey_asym.scene.frames, EventStream.empty(ev.width, ev.height))


def test_dead_time_is_the_floor_of_the_interval_histogram():
    rng = np.random.default_rng(0)
    # 200 pixels firing bursts with intervals >= 500 µs, plus sparse noise at any interval.
    t = np.concatenate([np.cumsum(500 + rng.exponential(300, 400)) for _ in range(200)])
    pix = np.repeat(np.arange(200), 400)
    noise_t = rng.uniform(0, t.max(), 2000)
    noise_p = rng.integers(0, 200, 2000)
    tt, pp = np.concatenate([t, noise_t]), np.concatenate([pix, noise_p])
    order = np.argsort(tt, kind="stable")
    ev = EventStream.create(np.rint(tt[order]), pp[order] % 20, pp[order] // 20, np.ones(tt.size), 20, 10)
    assert 420 <= dead_time_us(ev) <= 500
    flat = np.sort(rng.uniform(0, 1e6, 20000))
    ev0 = EventStream.create(np.rint(flat), rng.integers(0, 20, flat.size), rng.integers(0, 10, flat.size),
                             np.ones(flat.size), 20, 10)
    assert dead_time_us(ev0) < 100  # Poisson intervals: no refractory floor to find


def _bursts_and_noise(n_noise: int, rng: np.random.Generator, floor_us: float = 500.0,
                      mean_extra_us: float = 300.0, per_pixel: int = 300) -> EventStream:
    """200 pixels whose own events keep >= ``floor_us`` apart, plus noise events at any interval."""
    t = np.concatenate([np.cumsum(floor_us + rng.exponential(mean_extra_us, per_pixel)) for _ in range(200)])
    pix = np.repeat(np.arange(200), per_pixel)
    noise_t, noise_p = rng.uniform(0, t.max(), n_noise), rng.integers(0, 200, n_noise)
    tt, pp = np.concatenate([t, noise_t]), np.concatenate([pix, noise_p])
    order = np.argsort(tt, kind="stable")
    return EventStream.create(np.rint(tt[order]), pp[order] % 20, pp[order] // 20, np.ones(tt.size), 20, 10)


def test_a_floor_of_the_intervals_far_beyond_any_dead_time_is_not_one():
    """Pixels whose events keep >= 36 ms apart (one texture speed everywhere, as the plane-wave
    scene) have a floor in their intervals but no refractory period."""
    ev = _bursts_and_noise(0, np.random.default_rng(3), floor_us=36_000, mean_extra_us=20_000, per_pixel=60)
    assert 30_000 <= dead_time_us(ev, max_us=1e5) <= 36_000  # the step is there ...
    assert dead_time_us(ev) == 0.0  # ... and is not taken for a dead time
    assert interval_floor(ev) == IntervalFloor(0.0, 0.0)  # nor for a reset pixel's onset


def test_dead_time_is_found_under_heavy_background_activity():
    # Noise that ignores the dead time fills the bins below it (as 3-5 Hz of background activity
    # does on a 173x130 scene): the jump at the floor is ~15x, which a 20x rule missed.
    ev = _bursts_and_noise(6000, np.random.default_rng(1))
    assert dead_time_us(ev, jump=20.0) == 0.0
    assert 420 <= dead_time_us(ev) <= 500


def test_a_dead_time_inside_a_bin_is_found():
    # 957 µs falls inside the 866-1000 µs bin: the step is split over two bins, neither of which
    # alone is both 5x its predecessors and 0.5 % of the intervals (sparse events, as on a scene
    # with large thresholds).
    rng = np.random.default_rng(3)
    t = np.concatenate([np.cumsum(957 + rng.exponential(20000, 300)) for _ in range(200)])
    pix = np.repeat(np.arange(200), 300)
    noise_t, noise_p = rng.uniform(0, t.max(), 3000), rng.integers(0, 200, 3000)
    tt, pp = np.concatenate([t, noise_t]), np.concatenate([pix, noise_p])
    order = np.argsort(tt, kind="stable")
    ev = EventStream.create(np.rint(tt[order]), pp[order] % 20, pp[order] // 20, np.ones(tt.size), 20, 10)
    assert 850 <= dead_time_us(ev) <= 957


@pytest.mark.parametrize("floor_us", [867, 930, 999, 1234])
def test_the_refractory_period_is_located_inside_its_histogram_bin(floor_us):
    """The log bins (866-1000 µs, 1000-1155 µs, ...) only bracket the floor, and the dead time is
    their left edge; the 1 µs change point finds it wherever in its bin it lies, under background
    activity too."""
    ev = _bursts_and_noise(6000, np.random.default_rng(floor_us), floor_us=float(floor_us))
    coarse = dead_time_us(ev)
    assert coarse in np.round(np.geomspace(1.0, 1e5, 81))  # a bin's edge (866, 1000, 1155 µs)
    assert abs(located_step_us(ev, coarse) - floor_us) <= 1
    assert located_step_us(ev, 0.0) == 0.0


def test_a_smooth_rise_of_the_intervals_is_no_dead_time():
    # Gamma-distributed intervals (shape 12) rise 2-6x per bin toward their mode, as a real
    # DAVIS346's do from 1 ms (pixel bandwidth, not a refractory floor): no gate must be set from
    # them. Against the mean of the bins before (not their largest) this rise passes for a jump.
    rng = np.random.default_rng(2)
    t = np.concatenate([np.cumsum(rng.gamma(12.0, 400.0, 300)) for _ in range(200)])
    order = np.argsort(t, kind="stable")
    pix = np.repeat(np.arange(200), 300)[order]
    ev = EventStream.create(np.rint(t[order]), pix % 20, pix // 20, np.ones(t.size), 20, 10)
    assert dead_time_us(ev) == 0.0


def test_the_refractory_gate_looks_at_the_neighbours_not_at_the_pixel():
    fast = np.zeros((2, 5 * 6), bool)
    fast[0, 2 * 6 + 3] = True  # one fast pixel in the first pair
    m = refractory_mask(fast, 5, 6, 1, own=False).reshape(2, 5, 6)
    assert not m[0, 2, 3]  # its own intervals scale with its own threshold: not used
    assert m[0, 1:4, 2:5].sum() == 8 and m.sum() == 8  # its eight neighbours are gated
    both = refractory_mask(fast, 5, 6, 1, own=True).reshape(2, 5, 6)
    assert both[0, 2, 3] and both.sum() == 9
    assert np.array_equal(refractory_mask(fast, 5, 6, 0, own=True), fast)
    assert not refractory_mask(fast, 5, 6, 0, own=False).any()


def test_gates_named_in_the_details_and_the_own_gate_when_the_neighbours_leave_no_measurement(grey_asym):
    sc = grey_asym.scene
    used = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(bootstrap=50))
    assert used.details["dead_time_us"] > 0
    assert [c["refractory_gate"] for c in used.details["per_channel"]] == ["neighbours"]
    # An uncertainty no fit can meet: every channel is fitted again with the pixel's own gate,
    # and the neighbours' fit is kept in the details.
    own = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(
        bootstrap=50, refractory_max_uncertainty=0.0, own_gate_max_spread=10.0))
    ch = own.details["per_channel"][0]
    assert ch["refractory_gate"].startswith("pixel") and ch["neighbour_gate_fit"]["theta_pos"] > 0
    # ...unless the thresholds spread more than own_gate_max_spread allows: the own gate's fit
    # reads high there, so the uncertain neighbours' fit is kept as it is
    kept = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(
        bootstrap=50, refractory_max_uncertainty=0.0, own_gate_max_spread=0.5))
    assert kept.details["per_channel"][0]["refractory_gate"].startswith("neighbours (uncertain")
    assert np.allclose(kept.theta_pos, used.theta_pos) and np.allclose(kept.theta_neg, used.theta_neg)
    # the own gate leaves out only the fast pixels, not their neighbours: more pairs in the fit
    assert ch["kept"] > used.details["per_channel"][0]["kept"]
    off = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(refractory_radius=0, bootstrap=0))
    assert [c["refractory_gate"] for c in off.details["per_channel"]] == ["off"]


def test_threshold_spread_is_measured_and_undone(grey_asym):
    sc = grey_asym.scene
    th = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(bootstrap=0))
    no = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(bootstrap=0, spread_correction=False))
    sp = th.details["threshold_spread"]
    assert all(f >= 1.0 for f in sp["factor"])
    assert np.allclose(th.theta_pos, no.theta_pos * sp["factor"][0])
    assert np.allclose(th.theta_neg, no.theta_neg * sp["factor"][1])
    assert "threshold_spread" not in no.details


def test_a_poorly_measured_channel_borrows_from_the_others():
    theta = np.array([0.142, 0.124, 0.041])
    std = np.array([0.004, 0.004, 0.016])  # the third channel: 39 % uncertain
    out, sd = shrink_channels(theta, std, 0.05)
    assert np.allclose(out[:2], theta[:2], rtol=0.06)  # well-measured channels keep their values
    assert 0.12 < out[2] < 0.14  # the uncertain one moves to the common value
    assert sd[2] < std[2] and np.all(sd > 0)
    # precise, different channels are left apart
    out2, _ = shrink_channels(np.array([0.30, 0.36]), np.array([0.001, 0.001]), 0.05)
    assert np.allclose(out2, [0.30, 0.36], rtol=0.005)
    # no uncertainty at all: the common value
    out3, _ = shrink_channels(np.array([0.2, 0.3]), np.array([np.nan, 0.003]), 0.05)
    assert np.allclose(out3, 0.3, rtol=1e-6)


def test_a_channel_that_disagrees_with_the_others_takes_their_value():
    # blue fitted on few pairs of a dark scene: half the others' value, with a small bootstrap std
    theta = np.array([0.142, 0.136, 0.072])
    std = np.array([0.004, 0.005, 0.003])
    wide = discrepant_channels(theta, std, 0.05, 2.0)
    assert np.array_equal(wide[:2], std[:2]) and wide[2] > 0.5 * theta[2]
    out, _ = shrink_channels(theta, wide, 0.05)
    assert np.allclose(out, 0.139, rtol=0.04)
    plain, _ = shrink_channels(theta, std, 0.05)
    assert plain[2] < 0.125  # without the widening the blue channel stays far below
    # two channels, channels within the prior, or k = 0: nothing widened
    assert np.array_equal(discrepant_channels(theta[1:], std[1:], 0.05, 2.0), std[1:])
    close = np.array([0.140, 0.150, 0.145])
    assert np.array_equal(discrepant_channels(close, np.full(3, 0.005), 0.05, 2.0), np.full(3, 0.005))
    assert np.array_equal(discrepant_channels(theta, std, 0.05, 0.0), std)


def test_channels_that_all_disagree_are_drawn_to_their_median():
    # a dark scene with a long dead time (tuning seed 211, ON): red +70 %, green and blue -3 / -7 %
    # of the truth 0.224, each with a bootstrap std of a few percent; no two channels "agree"
    # under their stds, and the precision-weighted pooling alone would keep red far off
    theta = np.array([0.380, 0.217, 0.207])
    std = np.array([0.012, 0.008, 0.009])
    wide = discrepant_channels(theta, std, 0.05, 2.0)
    assert wide[0] > 0.4 * theta[0] and np.array_equal(wide[1:], std[1:])
    out, _ = shrink_channels(theta, wide, 0.05)
    assert np.all(np.abs(out / 0.224 - 1) < 0.10)
    plain, _ = shrink_channels(theta, std, 0.05)
    assert plain[0] > 0.28
    # precise channels far apart: the outer two are widened, the median one kept
    apart = np.array([0.30, 0.36, 0.43])
    w2 = discrepant_channels(apart, np.full(3, 0.001), 0.05, 2.0)
    assert w2[1] == 0.001 and w2[0] > 0.1 * apart[0] and w2[2] > 0.1 * apart[2]


def test_hot_pixels_are_spatial_outliers(grey_asym):
    ev = grey_asym.scene.events
    hot = hot_pixels(ev)
    assert hot.sum() < 0.002 * hot.size  # a clean sensor has (almost) none
    extra_t = np.linspace(ev.t[0], ev.t[-1], 3000).astype(np.int64)
    t = np.concatenate([ev.t, extra_t])
    x = np.concatenate([ev.x, np.full(3000, 7)])
    y = np.concatenate([ev.y, np.full(3000, 5)])
    p = np.concatenate([ev.p, np.ones(3000, np.int8)])
    o = np.argsort(t, kind="stable")
    ev2 = EventStream.create(t[o], x[o], y[o], p[o], ev.width, ev.height)
    assert hot_pixels(ev2).reshape(ev.height, ev.width)[5, 7]


def test_calibration_file_round_trip_and_errors(tmp_path):
    th = SensorThresholds(("R", "G", "B"), np.array([0.2, 0.3, 0.4]), np.array([0.25, 0.35, 0.45]),
                          np.full(3, 0.01), np.full(3, np.nan), True, "test")
    path = write_calibration(tmp_path / "c.json", th, scene="x")
    back, doc = read_calibration(path)
    np.testing.assert_allclose(back.as_array(), th.as_array())
    assert np.isnan(back.std_neg).all() and doc["scene"] == "x"
    (tmp_path / "bad.json").write_text(json.dumps({"format": "fusiongs-calibration", "thresholds": {
        "channels": ["grey"], "theta_pos": [0.2], "theta_neg": [-1]}}))
    with pytest.raises(InputError, match="theta_neg"):
        read_calibration(tmp_path / "bad.json")
    (tmp_path / "other.json").write_text("{}")
    with pytest.raises(InputError, match="format"):
        read_calibration(tmp_path / "other.json")
    with pytest.raises(InputError, match="grey"):
        th.for_sensor(None)


def test_cli_writes_calibration_and_prints_json(grey_dir, tmp_path, capsys):
    out = tmp_path / "c.json"
    assert main(["calibrate", str(grey_dir), "-o", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    th = doc["thresholds"]
    assert th["channels"] == ["grey"] and len(th["theta_pos"]) == 1 and len(th["theta_neg"]) == 1
    assert doc["truth"]["theta_pos"] == [pytest.approx(0.2)]
    assert read_calibration(out)[0].theta_pos[0] == pytest.approx(th["theta_pos"][0])
    assert main(["calibrate", str(grey_dir), "-o", str(tmp_path / "d")]) == 0
    text = capsys.readouterr().out
    assert "theta_on" in text and "err on" in text and (tmp_path / "d" / "calibration.json").is_file()
    assert "dead time" in text  # what decides the censored counts of deblur
    assert "threshold spread over pixels" in text  # the correction of the harmonic mean is shown


def test_edi_accepts_the_calibration_file(grey_dir, tmp_path):
    cal = tmp_path / "c.json"
    write_calibration(cal, SensorThresholds.uniform(0.2, 0.35, None))
    assert main(["edi", str(grey_dir), "-o", str(tmp_path / "a"), "--calibration", str(cal)]) == 0
    assert main(["edi", str(grey_dir), "-o", str(tmp_path / "b"), "--theta", "0.2", "0.35"]) == 0
    for f in sorted((tmp_path / "a").glob("*.png")):
        assert f.read_bytes() == (tmp_path / "b" / f.name).read_bytes()


def _scene_dir(tmp_path: Path, scene: Scene, name: str) -> Path:
    import dataclasses

    root = tmp_path / name
    write_simulated_scene(dataclasses.replace(scene, renders=()), {}, root)
    return root


def test_cli_bad_input_is_one_line_exit_2(grey_asym, tmp_path, capsys):
    import dataclasses

    sc = grey_asym.scene
    no_events = dataclasses.replace(sc, events=EventStream.empty(sc.camera.width, sc.camera.height))
    fs = sc.frames
    one = dataclasses.replace(sc, frames=FrameSet(fs.images[:1], fs.t_start[:1], fs.t_end[:1],
                                                  fs.names[:1], fs.response))
    no_frames = dataclasses.replace(sc, frames=FrameSet.empty(sc.camera.height, sc.camera.width))
    d = _scene_dir(tmp_path, no_events, "noev")
    code = main(["calibrate", str(d), "-o", str(tmp_path / "x.json")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "events" in err and len(err.splitlines()) == 1
    assert main(["calibrate", str(_scene_dir(tmp_path, one, "one")), "-o", str(tmp_path / "o.json")]) == 0
    assert read_calibration(tmp_path / "o.json")[0].method.startswith("one frame")
    assert "common scale" in capsys.readouterr().err
    nof = _scene_dir(tmp_path, no_frames, "nof")
    assert main(["calibrate", str(nof), "-o", str(tmp_path / "n.json")]) == 0
    captured = capsys.readouterr()
    assert "common scale" in captured.err
    assert not read_calibration(tmp_path / "n.json")[0].scale_known


def test_a_busy_sensor_where_every_pixel_fires_in_every_pair_calibrates(tmp_path, capsys):
    """Dense events (every pixel fires ON and OFF between every two frames) leave the IV fit's
    indicator regressors constant: they are dropped instead of making the system singular (a
    1e8-event 1280x720 scene raised torch's LinAlgError), and the thresholds come out right."""
    from fusiongs.sim.plane_wave import PlaneWave, write_plane_wave_scene

    pw = PlaneWave(events=600_000, width=64, height=48, duration=3.0, frames=6, exposure=0.02)
    write_plane_wave_scene(pw, tmp_path / "busy")
    assert main(["calibrate", str(tmp_path / "busy"), "-o", str(tmp_path / "c.json"), "--json"]) == 0
    th = json.loads(capsys.readouterr().out)["thresholds"]
    for v in th["theta_pos"] + th["theta_neg"]:
        assert abs(v / pw.theta - 1) < 0.1


def test_a_gate_that_would_leave_no_pixel_pairs_is_switched_off(tmp_path):
    """One amplitude everywhere: every pixel's intervals share a floor that reads as a dead time,
    and twice it covers all of them. The gate then left nothing and the estimate fell silently to
    the search's lower bound (0.03 for 0.2); now the gate is switched off and says so."""
    from fusiongs.io.scene_io import load_scene
    from fusiongs.sim.plane_wave import PlaneWave, write_plane_wave_scene

    pw = PlaneWave(events=600_000, width=64, height=48, duration=3.0, frames=6, exposure=0.02,
                   amplitude_spread=0.0)
    write_plane_wave_scene(pw, tmp_path / "regular")
    scene = load_scene(tmp_path / "regular")
    est = estimate_thresholds(scene.frames, scene.events)
    assert est.details["dead_time_us"] > 0
    assert est.details["per_channel"][0]["refractory_gate"].startswith("off")
    for v in (*est.theta_pos, *est.theta_neg):
        assert abs(v / pw.theta - 1) < 0.1


def test_a_channel_whose_fit_fails_takes_the_others_value_and_all_failing_falls_back(rggb_asym,
                                                                                     monkeypatch):
    import fusiongs.calibrate.estimate as cal
    from fusiongs.calibrate.estimate import failed_channels

    lo_hi = CalibrateOptions().theta_range
    bad = failed_channels(np.array([0.1, 0.2, np.nan, 0.3]), np.array([0.2, 40.0, 0.2, 0.01]), lo_hi)
    assert bad.tolist() == [False, True, True, True]
    ev, fr = rggb_asym.scene.events, rggb_asym.scene.frames
    real = cal.search_both
    calls = []

    def one_absurd(data, opts, rng):  # the second channel's (G) IV solve runs away
        res = real(data, opts, rng)
        calls.append(1)
        return res | {"theta_neg": 6e6} if len(calls) == 2 else res

    monkeypatch.setattr(cal, "search_both", one_absurd)
    th = estimate_thresholds(fr, ev)
    assert th.scale_known and "failed" in th.details["per_channel"][1]
    assert np.all(_rel(th.theta_neg, 0.25) < 0.15) and np.all(_rel(th.theta_pos, 0.4) < 0.15)
    monkeypatch.setattr(cal, "search_both",
                        lambda data, opts, rng: real(data, opts, rng) | {"theta_pos": 9.0})
    th = estimate_thresholds(fr, ev)
    assert not th.scale_known and th.method.startswith("the frames' consistency fit failed")
    assert np.allclose(np.sqrt(th.theta_pos * th.theta_neg), CalibrateOptions().unknown_scale)


def test_calibration_json_is_strict_json(tmp_path, grey_asym):
    th = estimate_thresholds(grey_asym.scene.frames, grey_asym.scene.events)
    th.details["probe"] = {"std": [float("nan"), float("inf"), 1.0]}
    path = write_calibration(tmp_path / "calibration.json", th)
    text = Path(path).read_text()
    assert "NaN" not in text and "Infinity" not in text

    def refuse(name):
        raise ValueError(name)

    doc = json.loads(text, parse_constant=refuse)
    assert doc["thresholds"]["details"]["probe"]["std"] == [None, None, 1.0]


def test_pixel_models_auto_measures_the_model_and_forced_models_use_their_dead_times(grey_asym):
    """The intervals' onset may be a reset pixel's dead time or only the scene's fastest edge:
    "auto" measures the frames' coefficient on the crossings the reset model adds and keeps the
    model it points to (tests/calibrate/test_pixel_model.py checks that it points right); a forced
    model uses its own dead time and makes no test."""
    sc = grey_asym.scene
    auto = estimate_thresholds(sc.frames, sc.events)
    test = auto.details["pixel_model_test"]
    assert auto.details["interval_floor_us"]["onset"] > 0 and np.isfinite(test["coefficient"])
    kept = "reset" if test["cut"] < test["coefficient"] <= test["max"] else "step"
    assert auto.details["pixel_model"] == f"{kept} (auto)"
    forced = {m: estimate_thresholds(sc.frames, sc.events, CalibrateOptions(pixel_model=m))
              for m in ("step", "reset")}
    assert forced["reset"].details["dead_time_us"] == auto.details["interval_floor_us"]["onset"]
    assert forced["step"].details["dead_time_us"] == auto.details["interval_floor_us"]["step"]
    np.testing.assert_array_equal(auto.theta_pos, forced[kept].theta_pos)
    # a reset pixel's events stand for more than one crossing each: smaller thresholds
    assert np.all(forced["reset"].theta_pos < forced["step"].theta_pos)
    assert forced["reset"].details["pixel_model_test"] is None
    # without frames nothing can tell them apart: the counts are taken as they are
    none = estimate_thresholds(FrameSet.empty(sc.events.height, sc.events.width), sc.events)
    assert none.details["pixel_model"] == "step (auto)" and none.details["pixel_model_test"] is None
    with pytest.raises(InputError, match="pixel_model"):
        estimate_thresholds(sc.frames, sc.events, CalibrateOptions(pixel_model="grid"))


def test_cli_pixel_model(grey_dir, tmp_path, capsys):
    assert main(["calibrate", str(grey_dir), "-o", str(tmp_path / "r.json"), "--pixel-model", "reset"]) == 0
    assert "pixel model: reset" in capsys.readouterr().out
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["thresholds"]["details"]["pixel_model"] == "reset"
    with pytest.raises(SystemExit):
        main(["calibrate", str(grey_dir), "--pixel-model", "grid"])


def test_the_reported_uncertainty_adds_the_systematic_part_to_the_bootstrap(grey_asym):
    sc = grey_asym.scene
    est = estimate_thresholds(sc.frames, sc.events, CalibrateOptions())
    boot = est.details["std_bootstrap"]
    assert est.details["systematic"] == 0.04
    for th, sd, b in ((est.theta_pos, est.std_pos, boot["std_pos"]),
                      (est.theta_neg, est.std_neg, boot["std_neg"])):
        np.testing.assert_allclose(sd, np.hypot(b, 0.04 * th))
        assert (sd > np.asarray(b)).all()
    bare = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(systematic=0.0))
    np.testing.assert_allclose(bare.std_pos, boot["std_pos"])  # the bootstrap alone, as before
    np.testing.assert_allclose(bare.theta_pos, est.theta_pos)  # the estimate itself is untouched
    for bad in (-0.01, float("nan"), "0.04", True):
        with pytest.raises(InputError, match="systematic"):
            estimate_thresholds(sc.frames, sc.events, CalibrateOptions(systematic=bad))


def test_a_gate_that_fell_back_widens_the_uncertainty_and_warns(grey_asym):
    sc = grey_asym.scene
    base = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(bootstrap=50))
    assert not base.details["per_channel"][0]["gate_fallback"] and "warnings" not in base.details
    # No fit meets this uncertainty: the channel falls back to the pixel's own gate (see above).
    own = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(
        bootstrap=50, refractory_max_uncertainty=0.0, own_gate_max_spread=10.0))
    assert own.details["per_channel"][0]["gate_fallback"]
    assert own.details["per_channel"][0]["refractory_gate"].startswith("pixel (")
    assert own.details["systematic"] == 0.20  # the own gate's systematic part, not the 12 %
    boot = own.details["std_bootstrap"]
    np.testing.assert_allclose(own.std_pos, np.hypot(boot["std_pos"], 0.20 * own.theta_pos))
    np.testing.assert_allclose(own.std_neg, np.hypot(boot["std_neg"], 0.20 * own.theta_neg))
    (warning,) = own.details["warnings"]
    assert "channel(s) grey" in warning and "20 %" in warning and "own gate on grey" in warning
    other = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(
        bootstrap=50, refractory_max_uncertainty=0.0, own_gate_max_spread=10.0, systematic_own_gate=0.3))
    assert other.details["systematic"] == 0.3
    np.testing.assert_allclose(other.theta_pos, own.theta_pos)  # the estimate itself is untouched
    np.testing.assert_allclose(other.std_pos, np.hypot(boot["std_pos"], 0.3 * own.theta_pos))
    # the uncertain neighbours' fit kept as it is counts as a fallback too, with its estimate untouched
    kept = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(
        bootstrap=50, refractory_max_uncertainty=0.0, own_gate_max_spread=0.5, systematic_fallback=0.2))
    assert kept.details["per_channel"][0]["gate_fallback"] and kept.details["systematic"] == 0.2
    np.testing.assert_allclose(kept.theta_pos, base.theta_pos)
    assert "own gate" not in kept.details["warnings"][0]
    for name in ("systematic_fallback", "systematic_own_gate"):
        for bad in (-0.01, float("nan"), None):
            with pytest.raises(InputError, match=name):
                estimate_thresholds(sc.frames, sc.events, CalibrateOptions(**{name: bad}))


def test_a_gate_that_keeps_few_pixel_pairs_widens_the_uncertainty_and_warns(grey_asym):
    sc = grey_asym.scene
    base = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(bootstrap=50))
    ch = base.details["per_channel"][0]
    assert 0.0 < ch["gate_keep"] < 1.0 and not ch["gate_sparse"]  # the gate left some pairs out
    assert base.details["systematic"] == 0.04 and "warnings" not in base.details
    # a bar above what the gate kept: the same estimate, flagged, with the fallback's systematic part
    bar = CalibrateOptions(bootstrap=50, min_gate_keep=min(1.0, 1.01 * ch["gate_keep"]))
    few = estimate_thresholds(sc.frames, sc.events, bar)
    assert few.details["per_channel"][0]["gate_sparse"] and few.details["systematic"] == 0.12
    np.testing.assert_allclose(few.theta_pos, base.theta_pos)
    np.testing.assert_allclose(few.theta_neg, base.theta_neg)
    boot = few.details["std_bootstrap"]
    np.testing.assert_allclose(few.std_pos, np.hypot(boot["std_pos"], 0.12 * few.theta_pos))
    (warning,) = few.details["warnings"]
    assert f"kept only {100 * ch['gate_keep']:.1f} % of the pixel pairs on channel(s) grey" in warning
    assert "12 %" in warning
    # just below what it kept: not flagged
    at = estimate_thresholds(sc.frames, sc.events, replace(bar, min_gate_keep=0.99 * ch["gate_keep"]))
    assert not at.details["per_channel"][0]["gate_sparse"] and at.details["systematic"] == 0.04
    # no gate, nothing to keep or flag
    off = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(refractory_gate=0.0, bootstrap=0,
                                                                     min_gate_keep=1.0))
    assert off.details["per_channel"][0]["gate_keep"] is None and off.details["systematic"] == 0.04
    for bad in (-0.01, float("nan"), None, "0.03"):
        with pytest.raises(InputError, match="min_gate_keep"):
            estimate_thresholds(sc.frames, sc.events, CalibrateOptions(min_gate_keep=bad))


def test_cli_prints_the_calibration_warnings(grey_dir, tmp_path, capsys, monkeypatch):
    import fusiongs.calibrate.estimate as cal

    real = cal.estimate_thresholds
    forced = CalibrateOptions(bootstrap=50, refractory_max_uncertainty=0.0, own_gate_max_spread=10.0)
    monkeypatch.setattr(cal, "estimate_thresholds",
                        lambda frames, events, opts=None: real(frames, events, forced))
    assert main(["calibrate", str(grey_dir), "-o", str(tmp_path / "w.json")]) == 0
    err = capsys.readouterr().err
    assert err.startswith("warning: the refractory gate left too few pixel pairs") and err.count("\n") == 1
    doc = json.loads((tmp_path / "w.json").read_text())
    assert doc["thresholds"]["details"]["warnings"] == [err[len("warning: "):].rstrip("\n")]


def test_a_calibration_file_with_bad_warnings_is_one_line(grey_dir, tmp_path, capsys):
    good = SensorThresholds.uniform(0.2, 0.25, None, "given")
    assert read_calibration(write_calibration(tmp_path / "ok.json", good))[0].details == {}
    for bad in (5, "check it", [1, 2]):
        th = SensorThresholds(good.channels, good.theta_pos, good.theta_neg, good.std_pos, good.std_neg,
                              True, "given", {"warnings": bad})
        path = write_calibration(tmp_path / "bad.json", th)
        with pytest.raises(InputError, match=r"bad\.json: details\.warnings"):
            read_calibration(path)
    code = main(["deblur", str(grey_dir), "-o", str(tmp_path / "run"), "--calibration", str(path),
                 "optim.iterations=2", "output.progress=false"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "details.warnings" in err[0]
