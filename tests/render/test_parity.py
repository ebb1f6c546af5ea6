"""Images and every gradient of the "torch" and "cpu" backends equal the dense float64 reference."""

from __future__ import annotations

import pytest
import torch

from fusiongs.render import rasterize
from tests.reference.render import render_reference
from tests.render.scenes import make_scene

NAMES = ("means", "quats", "scales", "opacities", "colors", "viewmats")
TOL = dict(atol=1e-6, rtol=1e-5)

SCENARIOS = {
    "rgb_3cams_background": dict(n=40, n_cams=3, channels=3, background=True),
    "one_channel_background": dict(n=30, n_cams=2, channels=1, background=True, seed=1),
    "five_channels": dict(n=30, n_cams=2, channels=5, seed=2),
    "sh0": dict(n=30, n_cams=2, sh_degree=0, seed=3),
    "sh1_background": dict(n=30, n_cams=2, sh_degree=1, background=True, seed=4),
    "sh2": dict(n=30, n_cams=1, sh_degree=2, seed=5),
    "sh3_3cams": dict(n=30, n_cams=3, sh_degree=3, seed=6),
    "dense_stack_hits_stop": dict(n=45, n_cams=1, channels=3, seed=7, scale=0.5, behind=0),
}


def _render(fn, scene, background, **kw):
    """Render with fresh leaf inputs, backprop a random linear loss, return outputs and grads."""
    ins = {k: scene[k].clone().requires_grad_(True) for k in NAMES}
    C = scene["viewmats"].shape[0]
    D = 3 if scene["sh_degree"] is not None else scene["colors"].shape[-1]
    g = torch.Generator().manual_seed(11)
    bg = torch.rand(C, D, generator=g, dtype=scene["means"].dtype) if background else None
    img, alpha, *_ = fn(*[ins[k] for k in NAMES], scene["Ks"], scene["width"], scene["height"],
                        sh_degree=scene["sh_degree"], backgrounds=bg, **kw)
    w_img = torch.randn(img.shape, generator=g, dtype=img.dtype)
    w_alpha = torch.randn(alpha.shape, generator=g, dtype=alpha.dtype)
    ((img * w_img).sum() + (alpha * w_alpha).sum()).backward()
    return img, alpha, {k: ins[k].grad for k in NAMES}


@pytest.fixture(scope="module")
def references():
    cache = {}

    def get(name):
        if name not in cache:
            cfg = dict(SCENARIOS[name])
            background = cfg.pop("background", False)
            scene = make_scene(**cfg)
            cache[name] = (scene, background, _render(render_reference, scene, background))
        return cache[name]

    return get


@pytest.mark.parametrize("backend", ["torch", "cpu"])
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_backend_matches_dense_reference_images_and_gradients(references, name, backend):
    scene, background, (ref_img, ref_alpha, ref_grads) = references(name)
    img, alpha, grads = _render(rasterize, scene, background, backend=backend)
    torch.testing.assert_close(img, ref_img, **TOL)
    torch.testing.assert_close(alpha, ref_alpha, **TOL)
    for k in NAMES:
        assert grads[k] is not None and torch.isfinite(grads[k]).all(), k
        torch.testing.assert_close(grads[k], ref_grads[k], **TOL, msg=lambda m, k=k: f"{k}: {m}")


def test_scenes_cover_culling_border_and_stop(references):
    """The parity scenes contain what they are meant to exercise."""
    scene, _, (_, ref_alpha, _) = references("rgb_3cams_background")
    _, _, meta = rasterize(*[scene[k] for k in NAMES], scene["Ks"], scene["width"], scene["height"])
    assert (meta.radii[0, :3] == 0).all()  # behind camera 0
    m = meta.means2d
    r = meta.radii.to(m.dtype)
    visible = meta.radii[..., 0] > 0
    cut = visible & ((m[..., 0] - r[..., 0] < 0) | (m[..., 0] + r[..., 0] > scene["width"])
                     | (m[..., 1] - r[..., 1] < 0) | (m[..., 1] + r[..., 1] > scene["height"]))
    assert cut.any()  # some Gaussians are cut by the image border
    _, _, (_, stack_alpha, _) = references("dense_stack_hits_stop")
    remaining = 1 - stack_alpha
    assert remaining.min() < 3e-4  # early stop reached: transmittance ended just above 1e-4
    assert remaining.min() > 1e-4


def test_per_camera_colours_match_reference_per_camera():
    scene = make_scene(n=20, n_cams=2, channels=2, seed=9)
    g = torch.Generator().manual_seed(0)
    cols = torch.rand(2, 20, 2, generator=g, dtype=torch.float64)
    args = [scene[k] for k in ("means", "quats", "scales", "opacities")]
    for backend in ("torch", "cpu"):
        img, _, _ = rasterize(*args, cols, scene["viewmats"], scene["Ks"], scene["width"],
                              scene["height"], backend=backend)
        for c in range(2):
            ref, _, _ = render_reference(*args, cols[c], scene["viewmats"][c:c + 1], scene["Ks"][c:c + 1],
                                         scene["width"], scene["height"])
            torch.testing.assert_close(img[c:c + 1], ref, **TOL)


def test_float32_cpu_and_torch_backends_agree():
    scene = make_scene(n=300, n_cams=2, width=48, height=40, seed=4, dtype=torch.float32, scale=0.08)
    outs = [_render(rasterize, scene, True, backend=b) for b in ("torch", "cpu")]
    torch.testing.assert_close(outs[0][0], outs[1][0], atol=2e-4, rtol=1e-3)
    torch.testing.assert_close(outs[0][1], outs[1][1], atol=2e-4, rtol=1e-3)
    for k in NAMES:
        scale = outs[0][2][k].abs().max()
        torch.testing.assert_close(outs[0][2][k], outs[1][2][k], atol=2e-3 * float(scale), rtol=1e-2)
