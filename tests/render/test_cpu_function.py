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
