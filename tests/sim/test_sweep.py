"""The sensor and scene sweep: draws in range, both asymmetries, disjoint splits, known truth."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.sim.simulate import run_simulation
from fusiongs.sim.sweep import (
    SCENE_RANGE,
    SENSOR_RANGE,
    SPLITS,
    TEST_SEEDS,
    TUNING_SEEDS,
    draw_sensor,
    sweep_scene_config,
)
from fusiongs.sim.write import write_simulated_scene


def _inside(v, lo_hi):
    return lo_hi[0] <= v <= lo_hi[1]


def test_sensor_draws_stay_in_range_and_are_asymmetric_both_ways():
    r = SENSOR_RANGE
    draws = [draw_sensor(s) for s in [*TUNING_SEEDS, *TEST_SEEDS]]
    for d in draws:
        assert _inside(d.theta_on, r.theta) and _inside(d.theta_off, r.theta)
        assert _inside(d.theta_off / d.theta_on, (r.ratio[0] - 1e-9, r.ratio[1] + 1e-9))
        assert _inside(d.theta_sigma, r.theta_sigma) and _inside(d.refractory_s, r.refractory_s)
        assert _inside(d.ba_rate_hz, r.ba_rate_hz) and _inside(d.hot_pixel_fraction, r.hot_pixel_fraction)
        assert _inside(d.hot_pixel_rate_hz, r.hot_pixel_rate_hz) and _inside(d.leak_rate_hz, r.leak_rate_hz)
        assert d.theta_gradient == 0.0
    ratio = np.array([d.theta_off / d.theta_on for d in draws])
    theta = np.array([d.theta_on for d in draws] + [d.theta_off for d in draws])
    assert (ratio < 0.7).sum() > 10 and (ratio > 1.4).sum() > 10
    assert theta.min() < 0.13 and theta.max() > 0.5  # the whole range is visited
    assert draw_sensor(7) == draw_sensor(7) and draw_sensor(7) != draw_sensor(8)


def test_scene_configs_cover_every_choice_and_keep_the_drawn_thresholds():
    cfgs = [sweep_scene_config(s, "tuning") for s in TUNING_SEEDS]
    assert {c.preset for c in cfgs} == set(SCENE_RANGE.presets)
    assert {c.cfa for c in cfgs} == {None, "RGGB"} and {c.frame_response for c in cfgs} == {"srgb", "linear"}
    for s, c in zip(TUNING_SEEDS, cfgs):
        assert c.events_target is None and c.seed == s and c.dvs == draw_sensor(s)
        assert 0.02 <= c.exposure <= 0.08 and 0.6 <= c.motion_scale <= 1.3
        assert c.duration == 1.0 and c.frames == 12
    assert sweep_scene_config(1003, "test") == sweep_scene_config(1003, "test")


def test_splits_are_disjoint_and_a_seed_of_the_other_split_is_refused():
    assert not set(SPLITS["tuning"]) & set(SPLITS["test"])
    with pytest.raises(InputError, match="seed"):
        sweep_scene_config(1000, "tuning")
    with pytest.raises(InputError, match="seed"):
        sweep_scene_config(5, "test")
    for bad in (-1, 1000, 2000, 2.0, True, "3"):
        with pytest.raises(InputError, match="seed"):
            sweep_scene_config(bad, "tuning")
    with pytest.raises(InputError, match="split"):
        sweep_scene_config(5, "train")


def test_a_sweep_scene_records_its_true_sensor_in_sim_json(tmp_path):
    cfg = sweep_scene_config(1001, "test")
    tiny = dataclasses.replace(cfg, width=32, height=24, duration=0.12, frames=2,
                               exposure=min(cfg.exposure, 0.05), dvs_rate_hz=400.0, blur_samples=4,
                               supersample=1, novel=1)
    res = run_simulation(tiny)
    write_simulated_scene(res.scene, res.gt, tmp_path / "s", stats=res.stats)
    sim = json.loads((tmp_path / "s" / "gt" / "sim.json").read_text())
    d = cfg.dvs
    assert sim["theta_on"] == d.theta_on and sim["theta_off"] == d.theta_off
    assert sim["threshold_scale"] == 1.0 and sim["theta_sigma"] == d.theta_sigma
    for key in ("refractory_s", "ba_rate_hz", "hot_pixel_fraction", "hot_pixel_rate_hz", "leak_rate_hz"):
        assert sim[key] == getattr(d, key)
    assert sim["preset"] == cfg.preset and sim["cfa"] == cfg.cfa
    assert sim["frame_response"] == cfg.frame_response and sim["motion_scale"] == cfg.motion_scale
    assert sim["config"]["dvs"]["theta_on"] == d.theta_on and "events" in sim and "blur_px" in sim
