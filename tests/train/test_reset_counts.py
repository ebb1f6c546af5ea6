"""A reset pixel's events counted as the crossings they stand for in training and in EDI, as the
calibration counted them (``events.reset_weights``; :func:`fusiongs.train.trainer.reset_event_weights`,
:func:`fusiongs.events.thresholds.calibration_event_weights`)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from fusiongs.events.dead_time import reset_weights
from fusiongs.events.thresholds import SensorThresholds
from fusiongs.io.scene_io import load_scene
from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene
from fusiongs.train.data import prepare_data
from fusiongs.train.trainer import reset_event_weights

CPU = torch.device("cpu")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("reset") / "scene"
    cfg = SimConfig(preset="wall", width=32, height=24, duration=0.15, frames=2, novel=0,
                    dvs_rate_hz=2000.0, blur_samples=4, supersample=1, seed=3,
                    dvs=DVSParams(refractory_s=4e-4, refractory_reset=True))
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, root, overwrite=True)
    return load_scene(root)


@pytest.fixture(scope="module")
def data(scene):
    return prepare_data(scene, CPU, True)


def _theta(**details) -> SensorThresholds:
    th = SensorThresholds.uniform(0.2, 0.25)
    return SensorThresholds(th.channels, th.theta_pos, th.theta_neg, th.std_pos, th.std_neg, True,
                            "test", details)


def test_only_a_reset_calibration_weighs_the_events(data):
    assert reset_event_weights(data, _theta(), CPU) is None
    assert reset_event_weights(data, _theta(pixel_model="step (auto)", dead_time_us=400.0), CPU) is None
    assert reset_event_weights(data, _theta(pixel_model="reset", dead_time_us=0.0), CPU) is None
    th = _theta(pixel_model="reset (auto)", dead_time_us=400.0, reset_weight_cap=3.0, reset_burst_end=True)
    w = reset_event_weights(data, th, CPU)
    assert w.dtype == torch.float32 and w.device == CPU and w.shape == (len(data.events),)
    np.testing.assert_array_equal(w.numpy(), reset_weights(data.events, 400.0, 3.0, burst_end=True))
    assert float(w.max()) > 1.0 and float(w.max()) <= 3.0 + 8.0 / 6.0 + 1e-5


def test_a_calibration_from_before_the_burst_end_keeps_its_weights(data):
    """A reset calibration without ``reset_burst_end`` was estimated without that term, and is
    counted without it."""
    th = _theta(pixel_model="reset (auto)", dead_time_us=400.0, reset_weight_cap=3.0)
    w = reset_event_weights(data, th, CPU)
    np.testing.assert_array_equal(w.numpy(), reset_weights(data.events, 400.0, 3.0, burst_end=False))
    assert float(w.max()) <= 3.0


def test_weighted_counts_in_every_window_and_their_cumulative_sums(data):
    data.event_weight = reset_event_weights(data, _theta(pixel_model="reset", dead_time_us=400.0), CPU)
    try:
        t0, t1 = data.t_range
        times = [t0, t0 + 0.3 * (t1 - t0), t0 + 0.55 * (t1 - t0), t1]
        counts, _ = data.cumulative_counts(times, CPU)
        w = data.event_weight.numpy()
        for a, b in itertools.combinations(range(len(times)), 2):
            got = data.count_maps(times[a], times[b], CPU)
            want = data.events.count_maps(int(round(times[a] * 1e6)), int(round(times[b] * 1e6)), w)
            np.testing.assert_allclose(got.numpy(), want, rtol=1e-5, atol=1e-4)
            torch.testing.assert_close(counts[b] - counts[a], got.reshape(2, -1), rtol=1e-5, atol=1e-3)
        plain = data.events.count_maps(int(round(t0 * 1e6)), int(round(t1 * 1e6)))
        assert float(counts[-1].sum()) > plain.sum()  # fast events stand for more than one crossing
    finally:
        data.event_weight = None


@pytest.mark.parametrize("details, field", [
    ({"pixel_model": "reset", "dead_time_us": "400"}, "dead_time_us"),
    ({"pixel_model": "reset", "dead_time_us": float("nan")}, "dead_time_us"),
    ({"pixel_model": "reset", "dead_time_us": -5.0}, "dead_time_us"),
    ({"pixel_model": "reset", "dead_time_us": 400.0, "reset_weight_cap": "x"}, "reset_weight_cap"),
    ({"pixel_model": "reset", "dead_time_us": 400.0, "reset_weight_cap": 0.5}, "reset_weight_cap"),
    ({"pixel_model": "reset", "dead_time_us": 400.0, "reset_burst_end": "yes"}, "reset_burst_end"),
    ({"pixel_model": "reset", "dead_time_us": 400.0, "reset_burst_end": 1}, "reset_burst_end"),
])
def test_a_reset_calibration_from_elsewhere_with_a_bad_number_is_a_named_error(data, details, field):
    from fusiongs.errors import InputError

    with pytest.raises(InputError, match=field):
        reset_event_weights(data, _theta(**details), CPU)


def test_edi_counts_a_reset_pixels_events_as_the_calibration_did(scene):
    from fusiongs.edi import edi_deblur, edi_scene

    th = _theta(pixel_model="reset (auto)", dead_time_us=400.0, reset_weight_cap=3.0, reset_burst_end=True)
    got = edi_scene(scene, th, n_samples=8)
    w = reset_weights(scene.events, 400.0, 3.0, burst_end=True)
    fs, lin = scene.frames, scene.frames.to_linear()
    want = np.stack([edi_deblur(lin[i], scene.events, float(fs.t_start[i]), float(fs.t_end[i]), th, 8, w)
                     for i in range(len(fs))])
    np.testing.assert_array_equal(got, want)
    plain = edi_scene(scene, th, n_samples=8, reset_weights=False)
    np.testing.assert_array_equal(plain, edi_scene(scene, _theta(pixel_model="step (auto)",
                                                                 dead_time_us=400.0), n_samples=8))
    np.testing.assert_array_equal(plain, edi_scene(scene, (0.2, 0.25), n_samples=8))
    assert float(np.abs(got - plain).max()) > 1e-3  # the weights reach the images


def test_edi_refuses_a_reset_calibration_with_a_bad_dead_time(scene):
    from fusiongs.edi import edi_scene
    from fusiongs.errors import InputError

    with pytest.raises(InputError, match="dead_time_us"):
        edi_scene(scene, _theta(pixel_model="reset", dead_time_us="400"), n_samples=4)


def test_a_calibration_file_with_a_bad_reset_dead_time_is_refused_naming_the_file(tmp_path):
    from fusiongs.errors import InputError
    from fusiongs.events.thresholds import read_calibration, write_calibration

    path = write_calibration(tmp_path / "calibration.json",
                             _theta(pixel_model="reset (auto)", dead_time_us="400"))
    with pytest.raises(InputError, match=r"calibration\.json: details\.dead_time_us"):
        read_calibration(path)
    good = write_calibration(tmp_path / "good.json", _theta(pixel_model="reset", dead_time_us=400.0))
    assert read_calibration(good)[0].details["dead_time_us"] == 400.0
    flag = write_calibration(tmp_path / "flag.json", _theta(pixel_model="reset", dead_time_us=400.0,
                                                            reset_burst_end="yes"))
    with pytest.raises(InputError, match=r"flag\.json: details\.reset_burst_end"):
        read_calibration(flag)
