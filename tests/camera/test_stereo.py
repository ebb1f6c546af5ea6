"""Plane-sweep stereo against ray-cast truth, and the stereo initialisation of the Gaussians."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.stereo import (
    depth_from_cost,
    far_bound,
    inverse_depth_planes,
    nearest_camera_distance,
    neighbour_indices,
    plane_sweep_cost,
    stereo_points,
    unproject,
)
from fusiongs.errors import ConfigError, InputError
from fusiongs.sim.motion import make_trajectory
from fusiongs.sim.presets import get_preset
from fusiongs.sim.raycast import RayCaster, fov_focal


def _preset_views(name: str, w: int = 64, h: int = 48, n: int = 7):
    """``n`` sharp ray-cast views of a preset's world along its simulated motion."""
    preset = get_preset(name)
    f = fov_focal(w, preset.hfov_deg)
    cam = PinholeCamera(w, h, f, f, w / 2, h / 2)
    traj = make_trajectory(preset.motion, 1.0, np.random.default_rng(0))
    c2w = traj.c2w(np.linspace(0.0, 1.0, n))
    caster = RayCaster(preset.world, cam, 1, 0)
    return cam, c2w, caster, torch.stack([caster.render(m) for m in c2w])


@pytest.fixture(scope="module")
def views():
    """Sharp ray-cast views of the ``boxes`` world along its simulated motion, with true depth."""
    cam, c2w, caster, images = _preset_views("boxes")
    w, h = cam.width, cam.height
    depth = []
    for m in c2w:
        pts = caster.surface_points(m).double()
        w2c = torch.linalg.inv(torch.as_tensor(m, dtype=torch.float64))
        assert pts.shape[0] == w * h  # the box world is closed: every ray hits
        depth.append((pts @ w2c[:3, :3].T + w2c[:3, 3])[:, 2].reshape(h, w))
    return cam, torch.as_tensor(c2w), images, torch.stack(depth).float()


def test_plane_sweep_recovers_true_depth(views):
    cam, c2w, images, depth = views
    planes = inverse_depth_planes(1.0, 12.0, 48)
    cost = plane_sweep_cost(images[3], c2w[3], images[[1, 2, 4, 5]], c2w[[1, 2, 4, 5]], cam, planes)
    assert cost.shape == (48, cam.height, cam.width)
    est, conf = depth_from_cost(cost, planes)
    rel = (est - depth[3]).abs() / depth[3]
    sure = conf >= 0.3
    assert sure.float().mean() > 0.6
    assert rel[sure].median() < 0.05
    assert (rel[sure] < 0.1).float().mean() > 0.8
    # Confidence means something: the confident pixels are better than the rest.
    assert rel[sure].median() <= rel.median()


def test_wrong_poses_give_wrong_depth(views):
    """The test above can fail: swapping the sources' poses breaks the geometry."""
    cam, c2w, images, depth = views
    planes = inverse_depth_planes(1.0, 12.0, 48)
    cost = plane_sweep_cost(images[3], c2w[3], images[[1, 5]], c2w[[5, 1]], cam, planes)
    est, _ = depth_from_cost(cost, planes)
    assert ((est - depth[3]).abs() / depth[3]).median() > 0.1


def test_sub_plane_refinement_finds_a_parabola_minimum():
    planes = inverse_depth_planes(1.0, 4.0, 9)
    inv = 1.0 / planes
    true_inv = 0.5 * (inv[3] + inv[4]) + 0.1 * (inv[4] - inv[3])
    cost = ((inv - true_inv) ** 2).float()[:, None, None].expand(9, 2, 3).contiguous()
    d, conf = depth_from_cost(cost, planes)
    assert torch.allclose(d, torch.full((2, 3), float(1 / true_inv)), rtol=1e-4)
    assert bool((conf > 0.5).all())
    flat, conf_flat = depth_from_cost(torch.ones(9, 2, 3), planes)
    assert bool((conf_flat == 0).all())


def test_unproject_inverts_projection():
    cam = PinholeCamera(8, 6, 10.0, 11.0, 4.2, 2.9)
    c2w = torch.eye(4, dtype=torch.float64)
    c2w[:3, 3] = torch.tensor([0.5, -1.0, 2.0])
    depth = torch.rand(6, 8) + 1
    x = unproject(depth, c2w, cam).double() - c2w[:3, 3]
    u = cam.fx * x[..., 0] / x[..., 2] + cam.cx
    v = cam.fy * x[..., 1] / x[..., 2] + cam.cy
    assert torch.allclose(u, torch.arange(8.0).double() + 0.5, atol=1e-4)
    assert torch.allclose(v, (torch.arange(6.0).double() + 0.5)[:, None].expand(6, 8), atol=1e-4)
    assert torch.allclose(x[..., 2], depth.double(), atol=1e-5)


def test_stereo_points_are_on_surfaces_with_their_pixel_colour(views):
    cam, c2w, images, depth = views
    xyz, rgb, conf = stereo_points(images, c2w, cam, 1.0, 12.0, n_planes=32, min_confidence=0.3)
    assert xyz.shape[0] == rgb.shape[0] == conf.shape[0] > 0.5 * images.shape[0] * cam.height * cam.width
    assert bool((conf >= 0.3).all())
    # Points re-project into view 3 at the true surface depth, or behind it (occluded there).
    w2c = torch.linalg.inv(c2w[3].double())
    p = xyz.double() @ w2c[:3, :3].T + w2c[:3, 3]
    u = (cam.fx * p[:, 0] / p[:, 2] + cam.cx).floor().long()
    v = (cam.fy * p[:, 1] / p[:, 2] + cam.cy).floor().long()
    ok = (p[:, 2] > 0) & (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
    rel = (p[ok, 2] - depth[3][v[ok], u[ok]].double()) / p[ok, 2]
    assert rel.abs().median() < 0.05
    assert (rel < -0.1).float().mean() < 0.1  # in front of the visible surface: wrong
    assert set(rgb.reshape(-1).tolist()) <= set(images.reshape(-1).tolist())


def test_views_without_parallax_give_no_points(views):
    cam, c2w, images, _ = views
    static = c2w[:1].expand(4, 4, 4).clone()  # a camera on a tripod: one pose for every frame
    xyz, rgb, conf = stereo_points(images[:4], static, cam, 1.0, 12.0, n_planes=8)
    assert xyz.shape == (0, 3) and rgb.shape == (0, images.shape[-1]) and conf.shape == (0,)
    # six views, the last one moved: with sources up to 3 apart, views 0 and 1 have only static
    # sources and give nothing; views 2-5 give every pixel (no confidence cut)
    mixed = c2w[:1].expand(6, 4, 4).clone()
    mixed[5] = c2w[5]
    xyz2, _, _ = stereo_points(images[:6], mixed, cam, 1.0, 12.0, n_planes=8, min_confidence=0.0)
    assert xyz2.shape[0] == 4 * cam.height * cam.width


def test_neighbours_stay_inside():
    assert neighbour_indices(5, 0, (-2, -1, 1, 2)) == [1, 2]
    assert neighbour_indices(5, 4, (-2, -1, 1, 2)) == [2, 3]
    assert neighbour_indices(5, 2, (0, 1, 1)) == [3]


@pytest.mark.parametrize("kwargs, field", [
    (dict(near=3.0, far=2.0), "near/far"),
    (dict(n_planes=1), "n_planes"),
    (dict(min_confidence=1.0), "min_confidence"),
])
def test_bad_stereo_arguments_name_the_field(views, kwargs, field):
    cam, c2w, images, _ = views
    args = dict(near=1.0, far=12.0, n_planes=8, min_confidence=0.3) | kwargs
    with pytest.raises(InputError, match=field):
        stereo_points(images[:2], c2w[:2], cam, **args)


def test_bad_images_name_the_field(views):
    cam, c2w, images, _ = views
    with pytest.raises(InputError, match="at least 2"):
        stereo_points(images[:1], c2w[:1], cam, 1.0, 12.0)
    with pytest.raises(InputError, match="images poses"):
        stereo_points(images[:3], c2w[:2], cam, 1.0, 12.0)
    with pytest.raises(InputError, match="window"):
        plane_sweep_cost(images[0], c2w[0], images[1:2], c2w[1:2], cam, inverse_depth_planes(1, 2, 4), 4)


def test_stereo_init_of_the_trainer(views):
    """``init.method = stereo`` keeps at most stereo_share of n_points from stereo, coloured."""
    from fusiongs.train.settings import DeblurConfig, InitSettings
    from fusiongs.train.state import initial_gaussians

    cam, c2w, images, _ = views

    class Data:
        camera = cam

    cfg = DeblurConfig(init=InitSettings(method="stereo", n_points=1000, stereo_share=0.75,
                                         stereo_planes=16))
    model, far = initial_gaussians(Data, c2w.float(), cfg, torch.Generator().manual_seed(0), images)
    assert model.n == 1000
    colours = model.base_colors()
    grey = (colours - 0.5).abs().amax(1) < 1e-6
    assert int(grey.sum()) >= 250 - 5 and int((~grey).sum()) > 700
    with pytest.raises(ConfigError, match="init.method"):
        initial_gaussians(Data, c2w[:1].float(), cfg, torch.Generator(), images[:1])
    bad_near = DeblurConfig(init=InitSettings(method="stereo", depth_min=0.0))
    with pytest.raises(ConfigError, match="init.depth_min"):
        initial_gaussians(Data, c2w.float(), bad_near, torch.Generator(), images)
    with pytest.raises(ConfigError, match="init.stereo_share"):
        InitSettings(stereo_share=1.5)


def test_auto_init_is_stereo_with_two_frames_and_random_otherwise(views):
    from fusiongs.train.settings import DeblurConfig, InitSettings
    from fusiongs.train.state import initial_gaussians

    cam, c2w, images, _ = views

    class Data:
        camera = cam

    def grey_share(method, n_images):
        cfg = DeblurConfig(init=InitSettings(method=method, n_points=400, stereo_planes=8))
        imgs = images[:n_images] if n_images else None
        m, _ = initial_gaussians(Data, c2w[:max(n_images, 1)].float(), cfg,
                              torch.Generator().manual_seed(0), imgs)
        return float(((m.base_colors() - 0.5).abs().amax(1) < 1e-6).float().mean())

    assert grey_share("auto", 3) < 0.5       # stereo: coloured surface points
    assert grey_share("auto", 1) == 1.0      # one frame: random grey points
    assert grey_share("auto", 0) == 1.0      # no frames (event-only)
    assert grey_share("random", 3) == 1.0


def test_far_bound_is_a_margin_over_a_high_quantile_of_the_distances():
    centres = torch.zeros(2, 3)

    def bound(points, least, most):
        return far_bound(nearest_camera_distance(points, centres), least, most)

    xyz = torch.zeros(1000, 3)
    xyz[:, 2] = torch.arange(1, 1001, dtype=torch.float32) / 10  # distances 0.1 .. 100
    assert bound(xyz, 1.0, 1e4) == pytest.approx(1.25 * 90.0, rel=1e-3)
    assert bound(xyz, 1.0, 50.0) == 50.0                 # at most `most`
    assert bound(xyz, 200.0, 1e4) == 200.0               # at least `least`
    assert bound(torch.zeros(0, 3), 12.0, 1e4) == 12.0   # no points: `least`
    xyz[-50:, 2] = 1e6  # a few matches at the end of the sweep do not move it
    assert bound(xyz, 1.0, 1e7) == pytest.approx(1.25 * 90.0, rel=1e-3)


def test_the_far_bound_reaches_a_far_wall_from_the_stereo_points():
    """The ``depth`` world has a wall at 40 m behind near posts: with ``far_from_stereo`` the far
    bound (random points, scene extent) covers the wall; the configured 12 m does not, and a
    shallow world (``boxes``, within 12 m of the camera) keeps the configured bound."""
    from fusiongs.train.settings import DeblurConfig, InitSettings
    from fusiongs.train.state import initial_gaussians

    def init(name, far_from_stereo):
        cam, c2w, _, images = _preset_views(name)

        class Data:
            camera = cam

        cfg = DeblurConfig(init=InitSettings(method="stereo", n_points=1000,
                                             far_from_stereo=far_from_stereo))
        model, far = initial_gaussians(Data, torch.as_tensor(c2w).float(), cfg,
                                       torch.Generator().manual_seed(0), images)
        centres = torch.as_tensor(c2w)[:, :3, 3].float()
        return far, torch.cdist(model.means.detach(), centres).amin(1), model.means.detach()

    far, dist, _ = init("depth", True)
    assert 40.0 <= far <= 100.0
    assert float(dist.max()) < far * 1.5 and float((dist > 30).float().mean()) > 0.2
    far, dist, _ = init("depth", False)
    assert far == 12.0 and float(dist.max()) < 12.0 * 1.5  # frusta corners reach sqrt(3) x depth
    far, _, means = init("boxes", True)
    assert far == 12.0  # and then the same Gaussians as without the option
    assert torch.equal(means, init("boxes", False)[2])


def test_wide_frames_are_swept_at_a_coarser_resolution_on_the_same_surfaces():
    """``init.stereo_max_width``: frames wider than it are block-averaged before the sweep (an HD
    sensor's sweep cost minutes and gigabytes); the points still lie on the true surfaces."""
    from fusiongs.train.settings import DeblurConfig, InitSettings
    from fusiongs.train.state import initial_gaussians, stereo_factor

    assert [stereo_factor(w, 400) for w in (173, 346, 400, 401, 1280)] == [1, 1, 1, 2, 4]
    assert stereo_factor(1280, 0) == 1
    cam, c2w, caster, images = _preset_views("boxes", w=128, h=96)
    truth = torch.cat([caster.surface_points(m) for m in c2w]).float()

    class Data:
        camera = cam

    def stereo_means(max_width):
        cfg = DeblurConfig(init=InitSettings(method="stereo", n_points=1000, stereo_share=1.0,
                                             stereo_max_width=max_width, far_from_stereo=False))
        model, _ = initial_gaussians(Data, torch.as_tensor(c2w).float(), cfg,
                                     torch.Generator().manual_seed(0), images)
        coloured = (model.base_colors() - 0.5).abs().amax(1) > 1e-6
        return model.means.detach()[coloured]

    full, coarse = stereo_means(0), stereo_means(64)
    assert coarse.shape[0] > 500
    scale = float(torch.cdist(full, torch.as_tensor(c2w)[:, :3, 3].float()).amin(1).median())
    for pts in (full, coarse):  # both on the surfaces, to within a few % of the typical depth
        assert float(torch.cdist(pts, truth).amin(1).median()) < 0.03 * scale
    with pytest.raises(ConfigError, match="init.stereo_max_width"):
        InitSettings(stereo_max_width=-1)


@pytest.mark.parametrize("sources, channels",
                         [([1, 2, 4, 5], 3), ([2, 4, 5], 3), ([4], 3), ([1, 2, 4, 5, 6], 1)])
def test_plane_sweep_cost_matches_its_plain_reference(views, sources, channels):
    """The fast cost (float32 planes, one channel for grey-as-RGB, the best sources by a sorting
    network) against the plain float64 form of :mod:`tests.reference.stereo`, on real views
    with true poses and on grey images stored as RGB; planes out to far beyond the scene so that
    sources lose the point (inf) at some pixels."""
    from tests.reference.stereo import plane_sweep_cost as reference

    cam, c2w, images, _ = views
    images = images[..., :1].expand(-1, -1, -1, 3) if channels == 1 else images
    planes = inverse_depth_planes(0.3, 200.0, 24)
    fast = plane_sweep_cost(images[3], c2w[3], images[sources], c2w[sources], cam, planes)
    slow = reference(images[3], c2w[3], images[sources], c2w[sources], cam, planes)
    finite = torch.isfinite(slow)
    assert not finite.all() and finite.any()
    assert (torch.isfinite(fast) == finite).float().mean() > 0.999  # a point exactly on a border may flip
    both = finite & torch.isfinite(fast)
    torch.testing.assert_close(fast[both], slow[both], rtol=1e-4, atol=2e-5)
    d_fast, c_fast = depth_from_cost(fast, planes)
    d_slow, c_slow = depth_from_cost(slow, planes)
    assert torch.isclose(d_fast, d_slow, rtol=1e-3).float().mean() > 0.99  # the same arg-min planes
    assert torch.isclose(c_fast, c_slow, atol=1e-3).float().mean() > 0.99


@pytest.mark.parametrize("n", [1, 2, 3, 5, 6, 8, 9])
def test_smallest_mean_is_the_mean_of_the_sorted_head(n):
    from fusiongs.camera.stereo import smallest_mean

    g = torch.Generator().manual_seed(n)
    x = torch.rand(n, 7, 11, generator=g)
    x[torch.rand(n, 7, 11, generator=g) < 0.2] = float("inf")
    for keep in range(1, n + 1):
        torch.testing.assert_close(smallest_mean(x, keep), x.sort(0).values[:keep].mean(0))
