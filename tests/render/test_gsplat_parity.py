"""gsplat backend parity with the pure-torch backend on CUDA (skipped without CUDA and gsplat)."""

from __future__ import annotations

import pytest
import torch

from fusiongs.render import rasterize
from fusiongs.render.gsplat_backend import gsplat_available
from tests.render.scenes import make_scene

pytestmark = [
    pytest.mark.cuda,
    pytest.mark.skipif(not torch.cuda.is_available() or not gsplat_available(),
                       reason="needs a CUDA GPU and gsplat"),
]
NAMES = ("means", "quats", "scales", "opacities", "colors", "viewmats")


@pytest.mark.parametrize("sh_degree", [None, 3])
def test_gsplat_and_torch_backends_agree_on_cuda(sh_degree):
    scene = make_scene(n=200, n_cams=2, width=64, height=48, sh_degree=sh_degree, seed=1,
                       dtype=torch.float32, scale=0.08)
    dev = torch.device("cuda", torch.cuda.current_device())
    bg = torch.rand(2, 3, device=dev)
    outs = []
    for backend in ("gsplat", "torch"):
        ins = {k: scene[k].to(dev).clone().requires_grad_(True) for k in NAMES}
        img, alpha, meta = rasterize(*[ins[k] for k in NAMES], scene["Ks"].to(dev), 64, 48,
                                     sh_degree=sh_degree, backgrounds=bg, backend=backend)
        assert meta.backend == backend
        (img.square().sum() + alpha.sum()).backward()
        outs.append((img, alpha, meta.radii, {k: ins[k].grad for k in NAMES}))
    (gi, ga, gr, gg), (ti, ta, tr, tg) = outs
    assert (gr == tr).float().mean() > 0.99
    torch.testing.assert_close(gi, ti, atol=1e-4, rtol=1e-3)
    torch.testing.assert_close(ga, ta, atol=1e-4, rtol=1e-3)
    for k in ("means", "quats", "scales", "opacities", "colors"):
        scale = float(tg[k].abs().max())
        torch.testing.assert_close(gg[k], tg[k], atol=2e-3 * scale, rtol=1e-2)
