"""Pure-torch compositing over a packed list of (pixel, Gaussian) pairs (CPU or CUDA, autograd).

Front-to-back alpha compositing (Kerbl et al. 2023, Eq. 3) with gsplat's discrete rules: alpha is
``min(0.999, o exp(-sigma))``, pairs with ``sigma < 0`` or ``alpha < 1/255`` are skipped, and a
pixel stops before the Gaussian that would bring its transmittance to ``<= 1e-4``.

The transmittance of each pair is a segmented product, computed as a cumulative sum of
``log(1 - alpha)`` over the pixel's pairs (in float64, so long runs keep their precision).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from fusiongs.render._boxes import pixel_boxes, sorted_visible
from fusiongs.render.projection import ALPHA_THRESHOLD, MAX_ALPHA, T_STOP, Projected


def _pair_alpha(proj: Projected, flat: Tensor, px: Tensor, py: Tensor) -> tuple[Tensor, Tensor]:
    """Gaussian exponent sigma and clamped alpha of each pair (differentiable)."""
    m = proj.means2d.reshape(-1, 2)[flat]
    con = proj.conics.reshape(-1, 3)[flat]
    op = proj.opacities.reshape(-1)[flat]
    dx = m[:, 0] - (px.to(m.dtype) + 0.5)
    dy = m[:, 1] - (py.to(m.dtype) + 0.5)
    sigma = 0.5 * (con[:, 0] * dx * dx + con[:, 2] * dy * dy) + con[:, 1] * dx * dy
    alpha = torch.clamp(op * torch.exp(-sigma), max=MAX_ALPHA)
    return sigma, alpha


def drawn_pairs(proj: Projected, width: int, height: int) -> tuple[Tensor, Tensor, Tensor]:
    """The (pixel, Gaussian) pairs that contribute, with their compositing weights.

    Args:
        proj: screen-space Gaussians of C cameras (see :func:`project_gaussians`).
        width, height: image size (px).

    Returns:
        ``(pix [M], flat [M], weight [M])``: flat pixel index ``c*H*W + y*W + x``, flat Gaussian
        index ``c*N + n`` and ``alpha * transmittance`` (differentiable), sorted by pixel, front to
        back within a pixel.
    """
    C, N = proj.depths.shape
    dev = proj.means2d.device
    cam, gid, _ = sorted_visible(proj.depths, proj.radii)
    with torch.no_grad():
        box = pixel_boxes(proj.means2d[cam, gid], proj.radii[cam, gid], width, height)
        nx = (box[:, 1] - box[:, 0] + 1).clamp_min(0)
        ny = (box[:, 3] - box[:, 2] + 1).clamp_min(0)
        counts = nx * ny
        owner = torch.repeat_interleave(torch.arange(len(counts), device=dev), counts)
        start = torch.cumsum(counts, 0) - counts
        local = torch.arange(len(owner), device=dev) - start[owner]
        px = box[owner, 0] + local % nx[owner]
        py = box[owner, 2] + local // nx[owner]
        flat = cam[owner] * N + gid[owner]
        sigma, alpha = _pair_alpha(proj, flat, px, py)
        keep = (sigma >= 0) & (alpha >= ALPHA_THRESHOLD)
        flat, px, py = flat[keep], px[keep], py[keep]
        pix = (flat // N) * (height * width) + py * width + px
        pix, order = torch.sort(pix, stable=True)  # depth order survives within a pixel
        flat, px, py = flat[order], px[order], py[order]
    _, alpha = _pair_alpha(proj, flat, px, py)
    log1m = torch.log1p(-alpha.to(torch.float64))
    csum = torch.cumsum(log1m, 0)
    with torch.no_grad():
        first = torch.ones_like(pix, dtype=torch.bool)
        first[1:] = pix[1:] != pix[:-1]
        seg = torch.cumsum(first.to(torch.int64), 0) - 1
        seg_start = torch.nonzero(first).squeeze(1)
    excl = csum - log1m
    base = excl[seg_start][seg]
    with torch.no_grad():
        # next transmittance stays above T_STOP; it only decreases, so this is a prefix per pixel
        drawn = (csum - base) > math.log(T_STOP)
    trans = torch.exp((excl - base)[drawn]).to(alpha.dtype)
    return pix[drawn], flat[drawn], alpha[drawn] * trans


def composite_pairs(proj: Projected, colors: Tensor, width: int, height: int) -> tuple[Tensor, Tensor]:
    """Composite projected Gaussians into images without background.

    Args:
        proj: screen-space Gaussians of C cameras (see :func:`project_gaussians`).
        colors: ``[C, N, D]`` per-camera colours.
        width, height: image size (px).

    Returns:
        ``(images [C, H, W, D], alphas [C, H, W, 1])``; ``alphas = 1 - final transmittance``.
    """
    C = proj.depths.shape[0]
    D = colors.shape[-1]
    npix = C * height * width
    pix, flat, weight = drawn_pairs(proj, width, height)
    col = colors.reshape(-1, D)[flat] * weight[:, None]
    image = torch.zeros(npix, D, dtype=colors.dtype, device=colors.device).index_add(0, pix, col)
    acc = torch.zeros(npix, dtype=weight.dtype, device=colors.device).index_add(0, pix, weight)
    return image.reshape(C, height, width, D), acc.reshape(C, height, width, 1)
