"""Dense float64 reference renderer, used only by the tests (slow, plain, obviously correct).

Every pixel meets every Gaussian; Gaussians are composited one after another in depth order
(Kerbl et al. 2023, Eq. 3) with gsplat 1.5.3's rules written out literally. Gradients come from
autograd. Intended for tens of Gaussians on images of tens of pixels.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from fusiongs.render.sh import eval_sh


def _project_one(mean, quat, scale, opacity, viewmat, K, width, height, near, far, eps2d):
    """Project one Gaussian into one camera; returns None when culled."""
    w, x, y, z = quat / torch.sqrt((quat * quat).sum())
    rot = torch.stack([
        torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)]),
        torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)]),
        torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]),
    ])
    cov = rot @ torch.diag(scale * scale) @ rot.T
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    p = R @ mean + t
    if not (near <= float(p[2].detach()) <= far):
        return None
    cov_c = R @ cov @ R.T
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    lim_x_pos = (width - cx) / fx + 0.3 * (0.5 * width / fx)
    lim_x_neg = cx / fx + 0.3 * (0.5 * width / fx)
    lim_y_pos = (height - cy) / fy + 0.3 * (0.5 * height / fy)
    lim_y_neg = cy / fy + 0.3 * (0.5 * height / fy)
    u = torch.minimum(torch.maximum(p[0] / p[2], -lim_x_neg), lim_x_pos)
    v = torch.minimum(torch.maximum(p[1] / p[2], -lim_y_neg), lim_y_pos)
    zero = torch.zeros((), dtype=p.dtype)
    J = torch.stack([torch.stack([fx / p[2], zero, -fx * u / p[2]]),
                     torch.stack([zero, fy / p[2], -fy * v / p[2]])])
    cov2 = J @ cov_c @ J.T + eps2d * torch.eye(2, dtype=p.dtype)
    det = cov2[0, 0] * cov2[1, 1] - cov2[0, 1] * cov2[1, 0]
    if float(det.detach()) <= 0 or float(opacity.detach()) < 1 / 255:
        return None
    extent = min(3.33, math.sqrt(2 * math.log(float(opacity.detach()) * 255)))
    rx = math.ceil(extent * math.sqrt(float(cov2[0, 0].detach())))
    ry = math.ceil(extent * math.sqrt(float(cov2[1, 1].detach())))
    centre = torch.stack([fx * p[0] / p[2] + cx, fy * p[1] / p[2] + cy])
    mx, my = float(centre[0].detach()), float(centre[1].detach())
    if rx <= 0 and ry <= 0:
        return None
    if mx + rx <= 0 or mx - rx >= width or my + ry <= 0 or my - ry >= height:
        return None
    conic = torch.stack([cov2[1, 1], -cov2[0, 1], cov2[0, 0]]) / det
    return centre, conic, p[2], (rx, ry)


def render_reference(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
                     viewmats: Tensor, Ks: Tensor, width: int, height: int, *, sh_degree: int | None = None,
                     backgrounds: Tensor | None = None, near_plane: float = 0.01,
                     far_plane: float = 1e10, eps2d: float = 0.3) -> tuple[Tensor, Tensor, Tensor]:
    """Render like :func:`fusiongs.render.rasterize`, densely and sequentially (tests only).

    Args: as :func:`fusiongs.render.rasterize` (colors ``[N, D]`` or SH ``[N, K, 3]``).

    Returns:
        ``(images [C, H, W, D], alphas [C, H, W, 1], radii [C, N, 2] int32)``.
    """
    C, N = viewmats.shape[0], means.shape[0]
    ys, xs = torch.meshgrid(torch.arange(height, dtype=means.dtype) + 0.5,
                            torch.arange(width, dtype=means.dtype) + 0.5, indexing="ij")
    images, alphas = [], []
    radii = torch.zeros(C, N, 2, dtype=torch.int32)
    for c in range(C):
        if sh_degree is None:
            col_c = colors
        else:
            campos = torch.linalg.inv(viewmats[c])[:3, 3]  # as gsplat: inverse, not R^T
            col_c = torch.clamp_min(eval_sh(sh_degree, means - campos, colors) + 0.5, 0.0)
        splats = []
        for n in range(N):
            out = _project_one(means[n], quats[n], scales[n], opacities[n], viewmats[c], Ks[c],
                               width, height, near_plane, far_plane, eps2d)
            if out is not None:
                radii[c, n] = torch.tensor(out[3], dtype=torch.int32)
                splats.append((float(out[2].detach()), n, out[0], out[1]))
        splats.sort(key=lambda s: (s[0], s[1]))  # front to back, ties by index
        T = torch.ones(height, width, dtype=means.dtype)
        done = torch.zeros(height, width, dtype=torch.bool)
        image = torch.zeros(height, width, col_c.shape[-1], dtype=means.dtype)
        for _, n, centre, conic in splats:
            dx, dy = centre[0] - xs, centre[1] - ys
            sigma = 0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) + conic[1] * dx * dy
            alpha = torch.clamp(opacities[n] * torch.exp(-sigma), max=0.999)
            use = (sigma >= 0) & (alpha >= 1 / 255) & ~done
            next_T = T * (1 - alpha)
            stop = use & (next_T <= 1e-4)
            done = done | stop
            use = use & ~stop
            image = image + torch.where(use[..., None], (alpha * T)[..., None] * col_c[n], 0.0)
            T = torch.where(use, next_T, T)
        if backgrounds is not None:
            image = image + T[..., None] * backgrounds[c]
        images.append(image)
        alphas.append((1 - T)[..., None])
    return torch.stack(images), torch.stack(alphas), radii
