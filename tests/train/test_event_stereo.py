"""Event-only initialisation: plane-sweep stereo on the HPF images of the events (no frames)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from fusiongs.camera.stereo import stereo_points
from fusiongs.io.scene_io import load_scene
from fusiongs.pipeline.deblur import resolve_config
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene
from fusiongs.train.data import event_stereo_images, prepare_data
from fusiongs.train.state import EVENT_ONLY_VIEWS, initial_gaussians
from fusiongs.train.trainer import build_trajectory, frame_colour, init_images


@pytest.fixture(scope="module", params=[None, "RGGB"], ids=["grey", "rggb"])
def wall_events(request, tmp_path_factory):
    """The ``wall`` preset without frames: a brick wall with posters 5 m away, a panel at 3.2 m."""
    cfg = SimConfig(preset="wall", width=64, height=48, duration=0.3, frames=0, novel=0, cfa=request.param,
                    dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=2)
    res = run_simulation(cfg)
    root = tmp_path_factory.mktemp("wall_events")
    write_simulated_scene(res.scene, res.gt, root, overwrite=True)
    return load_scene(root)


def test_the_hpf_images_are_unit_range_and_flat_where_nothing_fired(wall_events):
    ev = wall_events.events
    imgs = event_stereo_images(ev, (float(ev.t[0]) * 1e-6, float(ev.t[-1]) * 1e-6), 5, 0.05, 0.22,
                               colour=ev.cfa is not None)
    assert imgs.shape == (5, 48, 64, 1) and imgs.dtype == torch.float32
    assert float(imgs.min()) >= 0.0 and float(imgs.max()) <= 1.0
    assert torch.all(imgs[0] == 0.5)  # the first instant: nothing has fired yet
    assert float(imgs[1:].std()) > 0.05  # then the edges' trails


def test_stereo_on_event_images_puts_the_points_on_the_surfaces(wall_events):
    # Every surface of this scene lies 3.2-5 m from the camera path (z of the camera ~0). The
    # random initialisation of the event-only config puts 13 % of its points within 2.6-6.2 m
    # (±20 % of those depths); the stereo points measured 73 % (the trails of the HPF images widen
    # the spread behind the edges), the initial Gaussians with their random share 68 %.
    cfg = resolve_config("event_only", [])
    data = prepare_data(wall_events, torch.device("cpu"), True)
    images = init_images(wall_events, data, cfg)
    assert images is not None and images.shape[0] == EVENT_ONLY_VIEWS
    with torch.no_grad():
        c2w = build_trajectory(wall_events, cfg).c2w(
            torch.linspace(data.t_range[0], data.t_range[1], EVENT_ONLY_VIEWS, dtype=torch.float64)).float()
    xyz, _, _ = stereo_points(images, c2w, data.camera, cfg.init.depth_min, cfg.init.depth_max,
                              min_confidence=cfg.init.stereo_min_confidence)
    z = xyz[:, 2].numpy()
    assert len(z) > 2000, len(z)
    inside = np.mean((z > 2.6) & (z < 6.2))
    assert inside > 0.6, inside
    # the trainer's initialisation keeps them (with random points for the untextured rest)
    model, _ = initial_gaussians(data, c2w, cfg, torch.Generator().manual_seed(0), images)
    zm = model.means[:, 2].detach().numpy()
    assert model.n == cfg.init.n_points and np.mean((zm > 2.6) & (zm < 6.2)) > 0.5


def test_random_initialisation_without_frames_uses_no_images(wall_events):
    cfg = resolve_config("event_only", ["init.method=random"])
    data = prepare_data(wall_events, torch.device("cpu"), True)
    assert init_images(wall_events, data, cfg) is None
    with torch.no_grad():
        c2w = build_trajectory(wall_events, cfg).c2w(
            torch.linspace(data.t_range[0], data.t_range[1], EVENT_ONLY_VIEWS, dtype=torch.float64)).float()
    model, _ = initial_gaussians(data, c2w, cfg, torch.Generator().manual_seed(0), None)
    zm = model.means[:, 2].detach().numpy()
    assert np.mean((zm > 2.6) & (zm < 6.2)) < 0.3  # the contrast the stereo test above relies on


def test_a_single_frame_starts_from_the_events_stereo_and_two_frames_from_the_frames(tmp_path):
    """One frame cannot be matched against another, so a one-frame scene starts like an event-only
    one (the events' HPF images at EVENT_ONLY_VIEWS instants, posed over the whole recording);
    with two frames the EDI frames are matched; ``init.method=random`` uses no images."""
    from fusiongs.train.state import build_state, event_stereo_start

    def scene(frames):
        cfg = SimConfig(preset="wall", width=48, height=36, duration=0.3, frames=frames, novel=0,
                        dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=2)
        res = run_simulation(cfg)
        root = tmp_path / f"f{frames}"
        write_simulated_scene(res.scene, res.gt, root, overwrite=True)
        return load_scene(root)

    cfg = resolve_config("event_only", [])
    one = scene(1)
    data = prepare_data(one, torch.device("cpu"), True)
    assert event_stereo_start(data, cfg)
    images = init_images(one, data, cfg)
    assert images is not None and images.shape[0] == EVENT_ONLY_VIEWS
    traj = build_trajectory(one, cfg)
    state = build_state(data, None, traj, cfg, torch.device("cpu"), init_images=images)
    zm = state.model.means[:, 2].detach().numpy()
    assert np.mean((zm > 2.6) & (zm < 6.2)) > 0.5  # on the surfaces, as without frames
    assert not event_stereo_start(data, resolve_config("event_only", ["init.method=random"]))
    two = scene(2)
    data2 = prepare_data(two, torch.device("cpu"), True)
    assert not event_stereo_start(data2, cfg)
    assert init_images(two, data2, cfg).shape[0] == 2
    # the stereo points have the EDI frames' colours
    assert frame_colour(two, data2, resolve_config("event_only", ["init.start_colour=frame"])) is None


def test_a_single_frame_gives_the_first_gaussians_its_mean_colour(tmp_path):
    """Grey events carry no colour and the band loss no level: a one-frame scene's first Gaussians
    start from the frame's mean linear colour (``init.start_colour=auto``, the default, with grey
    events: random points exactly, the HPF-stereo points scaled to it, colour learning rates scaled
    by its level) instead of grey 0.5; colour events start grey. Without frames, or with two,
    nothing changes."""
    from fusiongs.train.state import build_state, event_stereo_start
    from fusiongs.train.trainer import _optimizers, colour_lr_scale

    cfg_sim = SimConfig(preset="gallery", width=48, height=36, duration=0.3, frames=1, novel=0,
                        dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=3)
    res = run_simulation(cfg_sim)
    write_simulated_scene(res.scene, res.gt, tmp_path / "one", overwrite=True)
    one = load_scene(tmp_path / "one")
    data = prepare_data(one, torch.device("cpu"), True)
    assert frame_colour(one, data, resolve_config("event_only", ["init.start_colour=grey"])) is None
    cfg = resolve_config("event_only", [])  # the default: the frame's colour
    fill = frame_colour(one, data, cfg)
    want = np.asarray(one.frames.to_linear(), np.float64).reshape(-1, 3).mean(axis=0)
    assert fill is not None and fill.shape == (3,) and fill.dtype == torch.float32
    np.testing.assert_allclose(fill.numpy(), want, rtol=1e-5)
    assert float(np.ptp(want)) > 0.1 * float(want.mean()) and abs(float(want.mean()) - 0.5) > 0.05  # not grey
    traj = build_trajectory(one, cfg)
    grey = build_state(data, None, traj, cfg, torch.device("cpu"), init_images=init_images(one, data, cfg))
    tinted = build_state(data, None, traj, cfg, torch.device("cpu"),
                         init_images=init_images(one, data, cfg, fill), fill=fill)
    c_grey = grey.model.base_colors().detach()
    c = tinted.model.base_colors().detach()
    n_rand = cfg.init.n_points - int(round(cfg.init.stereo_share * cfg.init.n_points))
    torch.testing.assert_close(c[-n_rand:], fill.expand(n_rand, 3), rtol=1e-5, atol=1e-6)  # the random share
    torch.testing.assert_close(c_grey[-n_rand:], torch.full((n_rand, 3), 0.5), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(c.mean(0).numpy(), want, rtol=0.15)  # the stereo points too, on average
    assert frame_colour(one, data, resolve_config("event_only", ["init.method=random",
                                                                 "init.start_colour=frame"])) is None
    # an Adam step changes log intensity as much as from grey: the colour rates scale with the level
    assert colour_lr_scale(None) == 1.0
    scale = colour_lr_scale(fill)
    assert scale == pytest.approx(float(want.mean()) / 0.5, rel=1e-5)
    lrs = {g["name"]: g["lr"] for g in _optimizers(tinted, cfg, 10.0, scale)["gaussians"].param_groups}
    assert lrs["sh0"] == pytest.approx(cfg.optim.lr_colors * scale)
    # colour events see each channel's changes: auto (the default) starts them grey, frame forces it
    rggb = run_simulation(replace(cfg_sim, cfa="RGGB"))
    write_simulated_scene(rggb.scene, rggb.gt, tmp_path / "rggb", overwrite=True)
    one_c = load_scene(tmp_path / "rggb")
    data_c = prepare_data(one_c, torch.device("cpu"), True)
    assert data_c.cfa_index is not None and event_stereo_start(data_c, cfg)
    assert frame_colour(one_c, data_c, cfg) is None
    forced = frame_colour(one_c, data_c, resolve_config("event_only", ["init.start_colour=frame"]))
    assert forced is not None and forced.shape == (3,)
