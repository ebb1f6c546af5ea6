"""rasterize's meta: shapes, dtypes, means2d gradients, culling and backend choice."""

from __future__ import annotations

import pytest
import torch

from fusiongs.render import rasterize
from tests.render.scenes import make_scene

ARGS = ("means", "quats", "scales", "opacities", "colors", "viewmats", "Ks")


@pytest.mark.parametrize("backend", ["torch", "cpu"])
def test_meta_shapes_dtypes_and_means2d_gradient(backend):
    scene = make_scene(n=25, n_cams=2, channels=4, seed=5)
    means = scene["means"].clone().requires_grad_(True)
    args = [means] + [scene[k] for k in ARGS[1:]]
    img, alpha, meta = rasterize(*args, scene["width"], scene["height"], backend=backend)
    C, N, H, W = 2, 25, scene["height"], scene["width"]
    assert img.shape == (C, H, W, 4) and alpha.shape == (C, H, W, 1)
    assert meta.means2d.shape == (C, N, 2) and meta.means2d.dtype == torch.float64
    assert meta.radii.shape == (C, N, 2) and meta.radii.dtype == torch.int32
    assert meta.depths.shape == (C, N) and meta.conics.shape == (C, N, 3)
    assert meta.opacities.shape == (C, N) and meta.colors.shape == (C, N, 4)
    assert (meta.width, meta.height, meta.n_cameras, meta.backend) == (W, H, C, backend)
    assert meta["radii"] is meta.radii  # gsplat-style access
    img.sum().backward()
    grad2d = meta.means2d.grad
    assert grad2d is not None and grad2d.shape == (C, N, 2)
    visible = meta.radii[..., 0] > 0
    assert (grad2d[~visible] == 0).all() and grad2d[visible].abs().sum() > 0


def test_near_and_far_planes_cull_by_camera_depth():
    scene = make_scene(n=25, n_cams=1, seed=6, behind=0)
    args = [scene[k] for k in ARGS]
    depth = (scene["viewmats"][0, :3, :3] @ scene["means"].T + scene["viewmats"][0, :3, 3:]).T[:, 2]
    _, _, meta = rasterize(*args, scene["width"], scene["height"])
    near = float(depth.median())
    _, _, meta_near = rasterize(*args, scene["width"], scene["height"], near_plane=near)
    _, _, meta_far = rasterize(*args, scene["width"], scene["height"], far_plane=near)
    shown = meta.radii[0, :, 0] > 0
    assert ((meta_near.radii[0, :, 0] > 0) == (shown & (depth >= near))).all()
    assert ((meta_far.radii[0, :, 0] > 0) == (shown & (depth <= near))).all()


def test_low_opacity_gaussians_are_culled_and_radius_is_opacity_aware():
    scene = make_scene(n=4, n_cams=1, seed=8, behind=0)
    opac = torch.tensor([1 / 255 * 0.99, 0.02, 0.5, 1.0], dtype=torch.float64)
    quats = torch.tensor([[1.0, 0, 0, 0]] * 4, dtype=torch.float64)
    scales = torch.full((4, 3), 0.1, dtype=torch.float64)
    means = torch.zeros(4, 3, dtype=torch.float64)
    _, _, meta = rasterize(means, quats, scales, opac, scene["colors"], scene["viewmats"], scene["Ks"],
                           scene["width"], scene["height"])
    r = meta.radii[0, :, 0]
    assert r[0] == 0 and 0 < r[1] < r[2] <= r[3]


def test_auto_backend_uses_numba_kernels_for_cpu_tensors():
    scene = make_scene(n=5, n_cams=1)
    _, _, meta = rasterize(*[scene[k] for k in ARGS], scene["width"], scene["height"])
    assert meta.backend == "cpu"
