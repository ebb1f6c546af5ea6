"""The float32 SIMD compositing kernels against the scalar kernels and the float64 reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fusiongs.render import _cpu_kernels as K
from fusiongs.render import _cpu_simd as S
from fusiongs.render import rasterize
from fusiongs.render._boxes import pixel_boxes, sorted_visible
from fusiongs.render.cpu import CompositeCPU, _use_simd
from tests.reference.render import render_reference
from tests.render.scenes import make_scene


def _screen_scene(C: int, N: int, W: int, H: int, D: int, seed: int):
    """Dense screen-space Gaussians (σ 0.7-5 px, opacity up to 0.99) over and across the borders."""
    g = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)
    means2d = (r(C, N, 2) * 1.2 - 0.1) * torch.tensor([W, H], dtype=torch.float64)
    sx, sy = 0.7 + 4.3 * r(C, N), 0.7 + 4.3 * r(C, N)
    rho = 1.6 * (r(C, N) - 0.5)
    cxx, cyy, cxy = sx * sx, sy * sy, rho * sx * sy
    det = cxx * cyy - cxy * cxy
    conics = torch.stack([cyy / det, -cxy / det, cxx / det], -1)
    opac = 0.05 + 0.94 * r(C, N)
    extent = torch.sqrt(2 * torch.log(opac * 255)).clamp(max=3.33)
    radii = torch.stack([torch.ceil(extent * sx), torch.ceil(extent * sy)], -1).to(torch.int32)
    colors = r(C, N, D)
    depths = r(C, N)
    # float32-representable inputs, so that the float32 and float64 paths see the same numbers
    f32 = lambda t: t.to(torch.float32).to(torch.float64)
    return f32(means2d), f32(conics), f32(colors), f32(opac), depths, radii


def _composite(inputs, dtype, W, H):
    means2d, conics, colors, opac, depths, radii = inputs
    cam, gid, off = sorted_visible(depths, radii)
    box = pixel_boxes(means2d[cam, gid], radii[cam, gid], W, H)
    leaves = [t.to(dtype).clone().requires_grad_(True) for t in (means2d, conics, colors, opac)]
    img, alpha = CompositeCPU.apply(*leaves, gid, box, off, W, H)
    g = torch.Generator().manual_seed(5)
    w_img = torch.randn(img.shape, generator=g, dtype=torch.float64).to(dtype)
    w_alpha = torch.randn(alpha.shape, generator=g, dtype=torch.float64).to(dtype)
    ((img * w_img).sum() + (alpha * w_alpha).sum()).backward()
    return img.detach().double(), alpha.detach().double(), [t.grad.double() for t in leaves]


CASES = {
    "narrower_than_a_lane_block": dict(C=2, N=60, W=7, H=9, D=3, seed=0),
    "width_not_a_multiple_of_16": dict(C=2, N=300, W=37, H=13, D=3, seed=1),
    "one_channel": dict(C=1, N=200, W=40, H=10, D=1, seed=2),
    "five_channels_wide": dict(C=2, N=400, W=70, H=8, D=5, seed=3),
}


@pytest.mark.parametrize("name", list(CASES))
def test_float32_simd_matches_float64_scalar_kernels(name):
    """Images, alphas and every gradient of the float32 SIMD path equal the float64 scalar path
    up to float32 rounding."""
    case = CASES[name]
    W, H = case["W"], case["H"]
    inputs = _screen_scene(**case)
    img32, alpha32, grads32 = _composite(inputs, torch.float32, W, H)
    img64, alpha64, grads64 = _composite(inputs, torch.float64, W, H)
    torch.testing.assert_close(img32, img64, atol=2e-6, rtol=1e-5)
    torch.testing.assert_close(alpha32, alpha64, atol=2e-6, rtol=1e-5)
    for what, a, b in zip(("means2d", "conics", "colors", "opacities"), grads32, grads64):
        assert torch.isfinite(a).all(), what
        err = float((a - b).norm() / b.norm())
        assert err < 2e-5, f"{what}: relative error {err:.2e}"


def test_dense_case_hits_the_stop_transmittance_and_the_borders():
    """The scene of the parity test does exercise early stopping and border-cut Gaussians."""
    case = CASES["width_not_a_multiple_of_16"]
    inputs = _screen_scene(**case)
    _, alpha, _ = _composite(inputs, torch.float32, case["W"], case["H"])
    assert (alpha > 1 - 2e-4).any()
    m, radii = inputs[0], inputs[5]
    assert ((m[..., 0] - radii[..., 0] < 0) | (m[..., 0] + radii[..., 0] > case["W"])).any()


def _kernel_inputs(case):
    means2d, conics, colors, opac, depths, radii = _screen_scene(**case)
    W, H = case["W"], case["H"]
    cam, gid, off = sorted_visible(depths, radii)
    box = pixel_boxes(means2d[cam, gid], radii[cam, gid], W, H).numpy()
    f = lambda t: np.ascontiguousarray(t.numpy().astype(np.float32))
    arrs = (f(means2d[..., 0]), f(means2d[..., 1]), f(conics[..., 0]), f(conics[..., 1]),
            f(conics[..., 2]), f(opac))
    row_off, rows, entry_row0 = K.row_lists(box, off.numpy(), H)
    return gid.numpy(), box, off.numpy(), row_off, rows, entry_row0, arrs, f(colors)


def test_simd_forward_matches_the_scalar_float32_kernel_and_last_entries():
    """Same dtype, same inputs: the SIMD forward gives the scalar kernel's images, final
    transmittance and last contributing entry per pixel."""
    case = CASES["width_not_a_multiple_of_16"]
    W, H, C, D = case["W"], case["H"], case["C"], case["D"]
    ids, box, off, row_off, rows, _, arrs, col = _kernel_inputs(case)
    outs = []
    for simd in (False, True):
        img = np.zeros((C, H, W, D), np.float32)
        tfin = np.empty((C, H, W), np.float32)
        last = np.empty((C, H, W), np.int64)
        if simd:
            pk, limk = S.pack_entries(ids, off, *arrs, S.alpha_limits(arrs[5]), col)
            S.forward(box, row_off, rows, pk, limk, H, W, img, tfin, last)
        else:
            K.forward(ids, box, row_off, rows, *arrs, col, H, W, img, tfin, last)
        outs.append((img, tfin, last))
    np.testing.assert_allclose(outs[1][0], outs[0][0], atol=1e-6)
    np.testing.assert_allclose(outs[1][1], outs[0][1], atol=1e-6)
    assert (outs[1][2] == outs[0][2]).mean() > 0.999  # a rounding tie may move one pixel's stop


def test_exp_neg_f32_is_float32_accurate():
    s = np.linspace(0.0, 80.0, 200_001, dtype=np.float32)

    from numba import njit

    @njit
    def run(v):
        out = np.empty_like(v)
        for i in range(v.size):
            out[i] = S.exp_neg_f32(v[i])
        return out

    ref = np.exp(-s.astype(np.float64))
    rel = np.abs(run(s).astype(np.float64) - ref) / ref
    assert rel.max() < 2e-7
    assert run(np.zeros(1, np.float32))[0] == 1.0


def test_alpha_limits_equal_the_scalar_kernel_formula():
    op = np.array([[1 / 255, 0.01, 0.5, 0.999]], np.float32)
    want = [2.0 * math.log(float(o) / K.ALPHA_T) * (1 + 1e-6) + 1e-6 for o in op[0]]
    np.testing.assert_allclose(S.alpha_limits(op)[0], want, rtol=1e-12)


def test_simd_kernels_are_used_for_float32_only():
    assert _use_simd(np.dtype(np.float32), 10)
    assert not _use_simd(np.dtype(np.float64), 10)
    assert not _use_simd(np.dtype(np.float32), 2**31)


@pytest.mark.parametrize("sh_degree", [None, 1])
def test_float32_rasterize_matches_the_float64_dense_reference(sh_degree):
    """End to end in float32 (projection included) against the float64 dense reference."""
    scene = make_scene(n=60, n_cams=2, width=29, height=21, sh_degree=sh_degree, seed=8, scale=0.3)
    names = ("means", "quats", "scales", "opacities", "colors", "viewmats")

    def run(fn, dtype, **kw):
        ins = {k: scene[k].to(dtype).clone().requires_grad_(True) for k in names}
        img, alpha, *_ = fn(*[ins[k] for k in names], scene["Ks"].to(dtype), scene["width"],
                            scene["height"], sh_degree=sh_degree, **kw)
        g = torch.Generator().manual_seed(2)
        w = torch.randn(img.shape, generator=g, dtype=torch.float64).to(dtype)
        ((img * w).sum() + alpha.sum()).backward()
        return img.detach().double(), {k: ins[k].grad.double() for k in names}

    img32, g32 = run(rasterize, torch.float32, backend="cpu")
    img64, g64 = run(render_reference, torch.float64)
    torch.testing.assert_close(img32, img64, atol=1e-4, rtol=1e-3)
    for k in names:
        err = float((g32[k] - g64[k]).norm() / g64[k].norm())
        assert err < 1e-3, f"{k}: relative error {err:.2e}"
