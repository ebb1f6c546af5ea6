"""The coarse warm-up: renders at 1/f resolution against frames block-averaged in linear light."""

from __future__ import annotations

import math

import pytest
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import ConfigError
from fusiongs.frames.response import linear_to_srgb, srgb_to_linear
from fusiongs.pipeline.deblur import resolve_config
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.train.data import coarse_camera, downsample_frames, prepare_data
from fusiongs.train.state import build_state
from fusiongs.train.step import training_step
from fusiongs.train.trainer import _coarse, build_trajectory, train

BASE = ["init.n_points=200", "blur.n_samples=3", "events.warmup=3", "events.pixels=128",
        "optim.iterations=6", "densify.enabled=false", "output.progress=false",
        "output.checkpoint_every=0", "optim.refine_poses=false", "threshold.estimate=false"]


@pytest.fixture(scope="module")
def scene():
    cfg = SimConfig(preset="boxes", width=25, height=18, duration=0.1, frames=2, exposure=0.03,
                    dvs_rate_hz=500.0, blur_samples=4, supersample=1, novel=1, seed=3)
    return run_simulation(cfg).scene


def test_downsample_averages_blocks_in_linear_light():
    lin = torch.rand(2, 6, 7, 3)
    frames = linear_to_srgb(lin)
    small = downsample_frames(frames, "srgb", 2)
    assert small.shape == (2, 3, 3, 3)  # the odd last column is dropped
    want = lin[:, 0:2, 2:4].mean(dim=(1, 2))  # block (row 0, column 1)
    torch.testing.assert_close(srgb_to_linear(small[:, 0, 1]), want, atol=1e-5, rtol=1e-5)


def test_coarse_camera_maps_points_to_half_the_pixel_coordinates():
    cam = PinholeCamera(173, 130, 150.0, 151.0, 86.3, 64.9)
    half = coarse_camera(cam, 2)
    assert (half.width, half.height) == (86, 65)
    x = torch.tensor([0.3, -0.2, 2.0])
    full_px = (cam.K() @ x)[:2] / x[2]
    half_px = (half.K() @ x)[:2] / x[2]
    torch.testing.assert_close(half_px, full_px / 2)


def test_coarse_step_renders_small_and_refuses_events(scene, generator):
    cfg = resolve_config(None, BASE)
    data = prepare_data(scene, torch.device("cpu"), True)
    state = build_state(data, scene.poses.c2w, build_trajectory(scene, cfg),
                        cfg, torch.device("cpu"))
    res = training_step(state, data, cfg, 0, 0.0, generator, coarse=2)
    assert res.renders.shape[1:3] == (9, 12)
    assert math.isfinite(float(res.loss.detach()))
    res.loss.backward()
    assert state.model.means.grad is not None and state.model.means.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="without events"):
        training_step(state, data, cfg, 0, 0.1, generator, coarse=2)


def test_coarse_steps_use_their_own_number_of_exposure_samples(scene, generator):
    cfg = resolve_config(None, BASE + ["blur.n_samples=7", "blur.coarse_n_samples=3"])
    data = prepare_data(scene, torch.device("cpu"), True)
    state = build_state(data, scene.poses.c2w, build_trajectory(scene, cfg),
                        cfg, torch.device("cpu"))
    assert training_step(state, data, cfg, 0, 0.0, generator, coarse=2).renders.shape[0] == 3
    assert training_step(state, data, cfg, 0, 0.0, generator, coarse=1).renders.shape[0] == 7


def test_coarse_schedule_ends_at_its_iteration_or_when_events_start(scene):
    data = prepare_data(scene, torch.device("cpu"), True)
    cfg = resolve_config(None, BASE + ["blur.coarse_until=5", "blur.coarse_factor=2"])
    assert _coarse(cfg, data, 0, 0.0) == 2 and _coarse(cfg, data, 4, 0.0) == 2
    assert _coarse(cfg, data, 5, 0.0) == 1
    assert _coarse(cfg, data, 2, 0.1) == 1  # events on: full resolution
    assert _coarse(resolve_config(None, BASE + ["blur.coarse_until=0"]), data, 0, 0.0) == 1


def test_training_with_a_coarse_warmup_runs(scene, tmp_path):
    cfg = resolve_config(None, BASE + ["blur.coarse_until=3"])
    tr = train(scene, cfg, tmp_path)
    assert all(math.isfinite(v) for v in tr.history.loss)
    assert all(math.isfinite(v) for v in tr.history.event[3:])


@pytest.mark.parametrize("key", ["blur.coarse_factor=0", "blur.n_samples=0", "blur.crop=[8,40]",
                                 "blur.coarse_n_samples=0"])
def test_bad_blur_settings_are_refused(key):
    with pytest.raises(ConfigError, match=key.split("=")[0]):
        resolve_config(None, [key])


def test_a_crop_renders_exactly_that_part_of_the_full_image(generator):
    from fusiongs.render import rasterize
    from fusiongs.train.crop import Crop

    cam = PinholeCamera(40, 30, 35.0, 36.0, 20.3, 14.8)
    crop = Crop(9, 6, 24, 18, cam.width, cam.height)
    n = 60  # Gaussians centred inside the crop's view (no Jacobian clamping at its borders)
    uv = torch.rand(n, 2, generator=generator) * torch.tensor([20.0, 14.0]) + torch.tensor([11.0, 8.0])
    z = 2.0 + torch.rand(n, generator=generator)
    means = torch.stack([(uv[:, 0] - cam.cx) / cam.fx * z, (uv[:, 1] - cam.cy) / cam.fy * z, z], -1)
    quats = torch.nn.functional.normalize(torch.randn(n, 4, generator=generator), dim=-1)
    scales = 0.02 + 0.08 * torch.rand(n, 3, generator=generator)
    opac, cols = 0.2 + 0.7 * torch.rand(n, generator=generator), torch.rand(n, 3, generator=generator)
    view = torch.eye(4)[None]

    def render(c: PinholeCamera) -> torch.Tensor:
        return rasterize(means, quats, scales, opac, cols, view, c.K()[None], c.width, c.height,
                         backend="cpu")[0][0]

    full, part = render(cam), render(crop.camera(cam))
    torch.testing.assert_close(part, crop.images(full), atol=1e-6, rtol=1e-5)
    pix = torch.tensor([0, 17, 24 * 18 - 1])
    torch.testing.assert_close(part.reshape(-1, 3)[pix], full.reshape(-1, 3)[crop.full_index(pix)])


@pytest.mark.parametrize("mode", ["grey", "mask", "demosaic"])
def test_training_on_crops_runs_with_events(tmp_path, mode):
    cfa = None if mode == "grey" else "RGGB"
    sim = SimConfig(preset="boxes", width=32, height=24, duration=0.1, frames=2, exposure=0.03,
                    dvs_rate_hz=500.0, blur_samples=4, supersample=1, novel=1, seed=4, cfa=cfa)
    colour = [] if mode == "grey" else [f"events.colour_mode={mode}"]
    cfg = resolve_config(None, BASE + colour + ["blur.crop=[20,16]", "threshold.grid=[2,2]"])
    tr = train(run_simulation(sim).scene, cfg, tmp_path)
    assert all(math.isfinite(v) for v in tr.history.loss)
    assert all(math.isfinite(v) for v in tr.history.event[3:])
