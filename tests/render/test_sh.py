"""Spherical harmonics: constants (orthonormal basis), DC helpers, gsplat's +0.5 / clamp rule."""

from __future__ import annotations

import math

import pytest
import torch

from fusiongs.render import eval_sh, rasterize, rgb_to_sh, sh_to_rgb
from fusiongs.render.sh import sh_basis
from tests.render.scenes import make_scene


def _fibonacci_sphere(n: int) -> torch.Tensor:
    i = torch.arange(n, dtype=torch.float64) + 0.5
    z = 1 - 2 * i / n
    phi = i * math.pi * (3 - math.sqrt(5))
    r = torch.sqrt(1 - z * z)
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), z], -1)


def test_sh_basis_up_to_degree_3_is_orthonormal_on_the_sphere():
    dirs = _fibonacci_sphere(20000)
    B = sh_basis(3, dirs)  # [n, 16]
    gram = B.T @ B * (4 * math.pi / len(dirs))
    torch.testing.assert_close(gram, torch.eye(16, dtype=torch.float64), atol=2e-3, rtol=0)


def test_eval_sh_normalises_directions_and_reads_only_needed_coefficients():
    g = torch.Generator().manual_seed(0)
    coeffs = torch.randn(5, 16, 2, generator=g, dtype=torch.float64)
    dirs = torch.randn(5, 3, generator=g, dtype=torch.float64)
    a = eval_sh(1, dirs * 7.0, coeffs)
    b = eval_sh(1, dirs, coeffs[:, :4])
    torch.testing.assert_close(a, b)
    with pytest.raises(ValueError):
        eval_sh(2, dirs, coeffs[:, :4])


def test_rgb_sh_dc_round_trip():
    rgb = torch.linspace(0, 1, 7, dtype=torch.float64)
    torch.testing.assert_close(sh_to_rgb(rgb_to_sh(rgb)), rgb)
    torch.testing.assert_close(eval_sh(0, torch.ones(7, 3, dtype=torch.float64),
                                       rgb_to_sh(rgb)[:, None, None]) + 0.5, rgb[:, None])


def test_sh_colours_get_half_offset_and_clamp_at_zero():
    scene = make_scene(n=10, n_cams=1, sh_degree=0, behind=0)
    dc = torch.full((10, 1, 3), -5.0, dtype=torch.float64)
    dc[:, 0, 1] = rgb_to_sh(torch.tensor(0.25, dtype=torch.float64))
    _, _, meta = rasterize(scene["means"], scene["quats"], scene["scales"], scene["opacities"], dc,
                           scene["viewmats"], scene["Ks"], scene["width"], scene["height"], sh_degree=0)
    assert (meta.colors[..., 0] == 0).all() and (meta.colors[..., 2] == 0).all()
    torch.testing.assert_close(meta.colors[..., 1], torch.full((1, 10), 0.25, dtype=torch.float64))
