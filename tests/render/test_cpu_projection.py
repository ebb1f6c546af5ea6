"""The numba projection (``fusiongs.render._cpu_projection`` behind ``ProjectCPU``): the same values
and gradients as the pure-torch ``project_gaussians`` (its reference), gradcheck in float64."""

from __future__ import annotations

import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.render.cpu import ProjectCPU, project_cpu
from fusiongs.render.projection import project_gaussians
from tests.render.scenes import make_scene

W, H = 40, 30


def _scene(dtype=torch.float64, n=300, seed=4):
    """Gaussians of every kind the projection meets: behind the camera, beyond the far plane,
    nearly transparent (culled), off-screen with a box that still meets the image (the clamped
    Jacobian), very large, and ordinary ones."""
    s = make_scene(n=n, n_cams=3, width=W, height=H, seed=seed, dtype=dtype, behind=6, scale=0.2)
    g = torch.Generator().manual_seed(seed + 1)
    scales = s["scales"].clone()
    scales[10:40] *= 6.0  # large: boxes reach far past the centre
    means = s["means"].clone()
    means[40:70, 0] += 2.5 + torch.rand(30, generator=g, dtype=dtype)  # off to the side
    means[70:75] = torch.tensor([0.0, 0.0, 60.0], dtype=dtype)  # beyond far = 20 below
    opac = s["opacities"].clone()
    opac[75:85] = 0.002  # below 1/255
    quats = s["quats"].clone()
    quats[85] = torch.tensor([1e-14, 0.0, 0.0, 0.0], dtype=dtype)  # F.normalize's eps
    return means, quats, scales, opac, s["viewmats"], s["Ks"]


def _weighted_sum(p, seed=7):
    g = torch.Generator().manual_seed(seed)
    w = [torch.randn(t.shape, generator=g, dtype=torch.float64).to(t.dtype)
         for t in (p.means2d, p.conics, p.depths)]
    return (p.means2d * w[0]).sum() + (p.conics * w[1]).sum() + (p.depths * w[2]).sum()


def _run(fn, means, quats, scales, opac, view, Ks):
    ins = [t.clone().requires_grad_(True) for t in (means, quats, scales, view)]
    p = fn(ins[0], ins[1], ins[2], opac, ins[3], Ks, W, H, 0.01, 20.0, 0.3)
    grads = torch.autograd.grad(_weighted_sum(p), ins)
    return p, grads


def test_numba_projection_matches_the_torch_projection_values_and_gradients_float64():
    scene = _scene()
    ref, g_ref = _run(project_gaussians, *scene)
    out, g_out = _run(project_cpu, *scene)
    kept = (ref.radii > 0).any(-1)
    culled = ~kept
    assert 0.2 < float(kept.float().mean()) < 0.95  # both kinds present
    # the clamped Jacobian is exercised: kept pairs whose centre lies outside the image
    mx, my = ref.means2d[..., 0], ref.means2d[..., 1]
    assert int((kept & ((mx < 0) | (mx > W) | (my < 0) | (my > H))).sum()) > 5
    assert torch.equal(out.radii, ref.radii)
    for name in ("means2d", "conics", "depths", "opacities"):
        torch.testing.assert_close(getattr(out, name), getattr(ref, name), rtol=1e-12, atol=1e-12)
    assert (out.means2d[culled] == 0).all() and (out.conics[culled] == 0).all()
    for name, a, b in zip(("means", "quats", "scales", "viewmats"), g_out, g_ref):
        scale = float(b.abs().max())
        assert scale > 0, name
        torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-11 * scale, msg=name)


def test_numba_projection_passes_gradcheck_float64():
    s = make_scene(n=10, n_cams=2, width=W, height=H, seed=9, behind=0, scale=0.2)
    means, quats, scales, opac, view, Ks = (s[k] for k in ("means", "quats", "scales", "opacities",
                                                           "viewmats", "Ks"))
    means[0, 0] += 2.0  # off to the side, and large: its Jacobian is clamped
    scales[0] *= 8.0

    def fn(m, q, s, v):
        m2d, con, depth, _ = ProjectCPU.apply(m, q, s, v, opac, Ks, W, H, 0.01, 20.0, 0.3)
        return m2d, con, depth

    ins = tuple(t.clone().requires_grad_(True) for t in (means, quats, scales, view))
    assert torch.autograd.gradcheck(fn, ins, eps=1e-7, atol=1e-5, rtol=1e-4)


def test_float32_inputs_give_float32_outputs_close_to_float64():
    scene64 = _scene()
    scene32 = [t.to(torch.float32) for t in scene64]
    ref, g_ref = _run(project_gaussians, *scene64)
    out, g_out = _run(project_cpu, *scene32)
    for name in ("means2d", "conics", "depths"):
        assert getattr(out, name).dtype == torch.float32
        torch.testing.assert_close(getattr(out, name).double(), getattr(ref, name), rtol=1e-4, atol=1e-4)
    assert float((out.radii != ref.radii).float().mean()) < 0.01  # a ceil at float32's rounding
    for a, b in zip(g_out, g_ref):
        assert a.dtype == torch.float32
        torch.testing.assert_close(a.double(), b, rtol=1e-3, atol=1e-4 * float(b.abs().max()))


@pytest.mark.parametrize("used", ["means2d_and_depths", "depths"])
def test_outputs_without_gradient_count_as_zero(used):
    means, quats, scales, opac, view, Ks = _scene(n=120)
    pick = ((lambda r: r.means2d.sum() + r.depths.sum()) if used == "means2d_and_depths"
            else (lambda r: r.depths.sum()))
    grads = []
    for fn in (project_cpu, project_gaussians):
        m = means.clone().requires_grad_(True)
        (g,) = torch.autograd.grad(pick(fn(m, quats, scales, opac, view, Ks, W, H, 0.01, 20.0, 0.3)), [m])
        grads.append(g)
    torch.testing.assert_close(grads[0], grads[1], rtol=1e-10, atol=1e-12)


def test_tensors_off_the_cpu_are_refused_with_the_argument_named():
    means, quats, scales, opac, view, Ks = _scene(n=100)
    with pytest.raises(InputError, match="project_cpu: viewmats: expected a CPU tensor"):
        project_cpu(means, quats, scales, opac, view.to("meta"), Ks, W, H, 0.01, 20.0, 0.3)
