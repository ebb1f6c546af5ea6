"""Random test scenes for the render tests (generated, seeded)."""

from __future__ import annotations

import math

import torch


def look_at(eye: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """World->camera matrix [4, 4] (OpenCV axes: x right, y down, z forward)."""
    f = target - eye
    f = f / f.norm()
    up = torch.tensor([0.0, -1.0, 0.0], dtype=eye.dtype)
    r = torch.linalg.cross(f, up)
    r = r / r.norm()
    d = torch.linalg.cross(f, r)
    R = torch.stack([r, d, f])
    V = torch.eye(4, dtype=eye.dtype)
    V[:3, :3] = R
    V[:3, 3] = -R @ eye
    return V


def make_scene(n: int = 40, n_cams: int = 2, width: int = 24, height: int = 18, channels: int = 3,
               sh_degree: int | None = None, seed: int = 0, dtype=torch.float64, behind: int = 3,
               scale: float = 0.12) -> dict:
    """Gaussians around the origin seen by cameras at distance ~3; some behind camera 0, some cut."""
    g = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=dtype)
    means = (r(n, 3) - 0.5) * torch.tensor([2.4, 1.8, 1.5], dtype=dtype)
    if behind:
        means[:behind] = torch.tensor([0.0, 0.0, -4.2], dtype=dtype) + 0.3 * (r(behind, 3) - 0.5)
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = scale * (0.4 + r(n, 3))
    opacities = 0.25 + 0.7 * r(n)
    if sh_degree is None:
        colors = r(n, channels)
    else:
        colors = 0.6 * torch.randn(n, (sh_degree + 1) ** 2, 3, generator=g, dtype=dtype)
    views, Ks = [], []
    for c in range(n_cams):
        ang = 0.35 * c
        eye = torch.tensor([3.0 * math.sin(ang), 0.2 * c, -3.0 * math.cos(ang)], dtype=dtype)
        views.append(look_at(eye, torch.zeros(3, dtype=dtype)))
        f = 0.9 * width + 3 * c
        Ks.append(torch.tensor([[f, 0, width / 2 + 0.7 * c], [0, f * 1.05, height / 2 - 0.4 * c],
                                [0, 0, 1]], dtype=dtype))
    return dict(means=means, quats=quats, scales=scales, opacities=opacities, colors=colors,
                viewmats=torch.stack(views), Ks=torch.stack(Ks), width=width, height=height,
                sh_degree=sh_degree)
