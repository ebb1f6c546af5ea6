"""The numba compositing autograd Function: gradcheck in float64, empty scenes, float32 support."""

from __future__ import annotations

import torch

from fusiongs.render import rasterize
from fusiongs.render._boxes import pixel_boxes, sorted_visible
from fusiongs.render.cpu import CompositeCPU
from tests.render.scenes import make_scene


def _tiny_inputs():
    g = torch.Generator().manual_seed(3)
    C, N, D, W, H = 2, 5, 2, 9, 7
    means2d = torch.rand(C, N, 2, generator=g, dtype=torch.float64) * torch.tensor([W, H])
    a = 0.3 + 0.5 * torch.rand(C, N, generator=g, dtype=torch.float64)
    c = 0.3 + 0.5 * torch.rand(C, N, generator=g, dtype=torch.float64)
    b = 0.2 * (torch.rand(C, N, generator=g, dtype=torch.float64) - 0.5)
    conics = torch.stack([a, b, c], -1)
    colors = torch.rand(C, N, D, generator=g, dtype=torch.float64)
    opac = 0.3 + 0.6 * torch.rand(C, N, generator=g, dtype=torch.float64)
    depths = torch.rand(C, N, generator=g, dtype=torch.float64)
    radii = torch.full((C, N, 2), 4, dtype=torch.int32)
    return means2d, conics, colors, opac, depths, radii, W, H


def test_composite_cpu_function_passes_gradcheck_float64():
    means2d, conics, colors, opac, depths, radii, W, H = _tiny_inputs()
    cam, gid, off = sorted_visible(depths, radii)
    box = pixel_boxes(means2d[cam, gid], radii[cam, gid], W, H)

    def fn(m, con, col, op):
        img, alpha = CompositeCPU.apply(m, con, col, op, gid, box, off, W, H)
        return img, alpha

    inputs = tuple(t.clone().requires_grad_(True) for t in (means2d, conics, colors, opac))
    assert torch.autograd.gradcheck(fn, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)


def test_scene_with_everything_culled_renders_background_and_zero_gradients():
    scene = make_scene(n=5, n_cams=1, seed=2, behind=5)
    bg = torch.tensor([[0.2, 0.4, 0.6]], dtype=torch.float64)
    for backend in ("torch", "cpu"):
        means = scene["means"].clone().requires_grad_(True)
        img, alpha, meta = rasterize(means, scene["quats"], scene["scales"], scene["opacities"],
                                     scene["colors"], scene["viewmats"], scene["Ks"], scene["width"],
                                     scene["height"], backgrounds=bg, backend=backend)
        assert (meta.radii == 0).all()
        torch.testing.assert_close(img, bg[:, None, None, :].expand_as(img))
        assert (alpha == 0).all()
        img.sum().backward()
        assert (means.grad == 0).all()


def test_cpu_backend_keeps_float32_dtype():
    scene = make_scene(n=20, n_cams=1, seed=1, dtype=torch.float32)
    means = scene["means"].clone().requires_grad_(True)
    img, alpha, meta = rasterize(means, scene["quats"], scene["scales"], scene["opacities"],
                                 scene["colors"], scene["viewmats"], scene["Ks"], scene["width"],
                                 scene["height"], backend="cpu")
    assert img.dtype == alpha.dtype == torch.float32
    img.sum().backward()
    assert means.grad.dtype == torch.float32 and means.grad.abs().sum() > 0


def _three_camera_grads(monkeypatch, skip: bool, dtype, w_scale: tuple[float, float, float]):
    import fusiongs.render.cpu as cpu

    if not skip:
        monkeypatch.setattr(cpu, "row_ends", lambda row_off, idle, height: row_off[1:].copy())
    scene = make_scene(n=40, n_cams=3, seed=4, dtype=dtype)
    leaves = [scene[k].clone().requires_grad_(True) for k in ("means", "scales", "colors")]
    img, alpha, meta = rasterize(leaves[0], scene["quats"], leaves[1], scene["opacities"], leaves[2],
                                 scene["viewmats"], scene["Ks"], scene["width"], scene["height"],
                                 backend="cpu")
    g = torch.Generator().manual_seed(9)
    per_camera = torch.tensor(w_scale, dtype=dtype)[:, None, None, None]  # 0: the loss ignores it
    w = torch.randn(img.shape, generator=g, dtype=dtype) * per_camera
    wa = torch.randn(alpha.shape, generator=g, dtype=dtype) * per_camera
    ((img * w).sum() + (alpha * wa).sum()).backward()
    return [t.grad for t in leaves] + [meta.means2d.grad]


def test_cameras_without_gradient_are_skipped_with_the_same_gradients(monkeypatch):
    """A camera whose outputs the loss does not use gives zero gradients either way: skipping its
    rows in the backward pass changes nothing, in float64 and float32, for any camera."""
    for dtype in (torch.float64, torch.float32):
        for scale in ((1.0, 0.0, 1.0), (0.0, 1.0, 1.0), (1.0, 1.0, 0.0), (0.0, 0.0, 1.0)):
            with monkeypatch.context() as m:
                ref = _three_camera_grads(m, False, dtype, scale)
            got = _three_camera_grads(monkeypatch, True, dtype, scale)
            for a, b in zip(got, ref):
                assert torch.equal(a, b)
            assert any(a.abs().sum() > 0 for a in got)


def test_row_ends_empty_only_the_idle_cameras_rows():
    import numpy as np

    from fusiongs.render.cpu import _idle_cameras, row_ends

    H = 3
    row_off = np.array([0, 2, 5, 5, 7, 8, 12, 13, 13, 16], np.int64)  # 3 cameras x 3 rows
    for idle in ([False, True, False], [True, False, False], [False, False, True]):
        end = row_ends(row_off, np.array(idle), H)
        for t in range(9):
            n = end[t] - row_off[t]
            assert n == (0 if idle[t // H] else row_off[t + 1] - row_off[t])
    assert (row_ends(row_off, np.zeros(3, bool), H) == row_off[1:]).all()
    v = np.zeros((3, 2, 2, 1))
    v[2, 1, 1, 0] = np.nan
    va = np.zeros((3, 2, 2))
    va[0, 0, 0] = -1e-30
    assert _idle_cameras(v, va).tolist() == [False, True, False]
