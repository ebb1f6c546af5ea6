"""The peers of event-only reconstruction: the leaky-integrator floor and the grey ceiling."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from fusiongs.eval.event_floor import grey_ceiling, leaky_integrator_floor
from fusiongs.frames.image_io import read_image, write_png
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene


@pytest.fixture(scope="module")
def colour_wall(tmp_path_factory):
    """A 32x24 wall with colour posters, 0.15 s of grey events, no frames, 2 requested instants."""
    cfg = SimConfig(preset="wall", width=32, height=24, duration=0.15, frames=0, novel=2,
                    dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=4)
    res = run_simulation(cfg)
    root = tmp_path_factory.mktemp("floor")
    write_simulated_scene(res.scene, res.gt, root, overwrite=True)
    return root


def test_the_floor_is_scored_after_the_fit(colour_wall):
    floor = leaky_integrator_floor(colour_wall)
    assert 8.0 < floor["psnr"] < 40.0 and -1.0 <= floor["ssim"] <= 1.0


def test_the_grey_ceiling_binds_on_colour_truth_and_not_on_grey_truth(colour_wall, tmp_path):
    ceiling = grey_ceiling(colour_wall)
    # the posters' hues are lost in grey: the fit cannot bring them back, yet grey keeps the structure
    assert leaky_integrator_floor(colour_wall)["psnr"] < ceiling["psnr"] < 45.0
    grey = tmp_path / "grey"
    shutil.copytree(colour_wall, grey)
    for png in (grey / "gt").glob("*.png"):
        img = read_image(png)
        write_png(png, np.repeat(img.mean(axis=-1, keepdims=True), 3, axis=-1))
    assert grey_ceiling(grey)["psnr"] > 45.0  # a grey truth is its own luminance up to rounding


def test_the_floor_of_a_scene_with_a_frame_takes_its_instants_in_time_order(tmp_path):
    """A scene with frames lists its deblur views before the novel ones (out of time order); the
    high-pass filter reads out in time order, so the floor sorts the instants first."""
    cfg = SimConfig(preset="wall", width=32, height=24, duration=0.15, frames=1, novel=2,
                    dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=4)
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, tmp_path, overwrite=True)
    times = [r.t for r in res.scene.renders]
    assert times != sorted(times)  # the case this test is about
    floor = leaky_integrator_floor(tmp_path)
    assert 8.0 < floor["psnr"] < 40.0
