"""A simple tiled pure-torch compositor (16x16 tiles, dense per-tile Gaussian lists): the baseline.

Every tile holds the depth-sorted list of Gaussians whose pixel box meets it, padded to the longest
list; alpha is evaluated densely for (tile, list entry, tile pixel) and composited with a cumulative
product. Same rules as ``fusiongs.render`` (alpha clamp, 1/255 skip, 1e-4 stop). Benchmark only.
"""

from __future__ import annotations

import torch
from torch import Tensor

from fusiongs.render._boxes import pixel_boxes, sorted_visible
from fusiongs.render.projection import ALPHA_THRESHOLD, MAX_ALPHA, T_STOP, Projected

TILE = 16


def composite_tiled(proj: Projected, colors: Tensor, width: int, height: int) -> tuple[Tensor, Tensor]:
    """Composite ``[C, N, D]`` colours into ``(images [C,H,W,D], alphas [C,H,W,1])``, no background."""
    C, N = proj.depths.shape
    D = colors.shape[-1]
    dev = colors.device
    tw, th = -(-width // TILE), -(-height // TILE)
    cam, gid, _ = sorted_visible(proj.depths, proj.radii)
    with torch.no_grad():
        box = pixel_boxes(proj.means2d[cam, gid], proj.radii[cam, gid], width, height)
        tx0, tx1 = box[:, 0] // TILE, box[:, 1] // TILE
        ty0, ty1 = box[:, 2] // TILE, box[:, 3] // TILE
        ntx = (tx1 - tx0 + 1).clamp_min(0) * (box[:, 1] >= box[:, 0])
        nty = (ty1 - ty0 + 1).clamp_min(0) * (box[:, 3] >= box[:, 2])
        counts = ntx * nty
        owner = torch.repeat_interleave(torch.arange(len(counts), device=dev), counts)
        local = torch.arange(len(owner), device=dev) - (torch.cumsum(counts, 0) - counts)[owner]
        tile = (cam[owner] * th + ty0[owner] + local // ntx[owner]) * tw + tx0[owner] + local % ntx[owner]
        tile, order = torch.sort(tile, stable=True)
        flat = (cam[owner] * N + gid[owner])[order]
        per_tile = torch.bincount(tile, minlength=C * th * tw)
        rank = torch.arange(len(tile), device=dev) - (torch.cumsum(per_tile, 0) - per_tile)[tile]
        L = int(per_tile.max()) if len(tile) else 1
        lists = torch.full((C * th * tw, L), -1, dtype=torch.int64, device=dev)
        lists[tile, rank] = flat
        valid = lists >= 0
        safe = lists.clamp_min(0)
        ty, tx = torch.meshgrid(torch.arange(TILE, device=dev), torch.arange(TILE, device=dev),
                                indexing="ij")
        t_id = torch.arange(C * th * tw, device=dev)
        px = ((t_id % tw) * TILE)[:, None] + tx.reshape(1, -1)  # [T, 256]
        py = (((t_id // tw) % th) * TILE)[:, None] + ty.reshape(1, -1)
    m = proj.means2d.reshape(-1, 2)[safe]  # [T, L, 2]
    con = proj.conics.reshape(-1, 3)[safe]
    op = proj.opacities.reshape(-1)[safe]
    dx = m[..., 0:1] - (px[:, None, :] + 0.5)
    dy = m[..., 1:2] - (py[:, None, :] + 0.5)
    sigma = 0.5 * (con[..., 0:1] * dx * dx + con[..., 2:3] * dy * dy) + con[..., 1:2] * dx * dy
    alpha = torch.clamp(op[..., None] * torch.exp(-sigma), max=MAX_ALPHA)
    use = (sigma >= 0) & (alpha >= ALPHA_THRESHOLD) & valid[..., None]
    alpha = torch.where(use, alpha, torch.zeros_like(alpha))  # [T, L, 256]
    t_incl = torch.cumprod(1 - alpha, dim=1)
    t_excl = torch.cat([torch.ones_like(t_incl[:, :1]), t_incl[:, :-1]], dim=1)
    drawn = (t_incl > T_STOP).detach()
    weight = torch.where(drawn, alpha * t_excl, torch.zeros_like(alpha))
    col = colors.reshape(-1, D)[safe]  # [T, L, D]
    img = torch.einsum("tlp,tld->tpd", weight, col)  # [T, 256, D]
    acc = weight.sum(1)  # [T, 256]
    img = img.reshape(C, th, tw, TILE, TILE, D).permute(0, 1, 3, 2, 4, 5).reshape(C, th * TILE, tw * TILE, D)
    acc = acc.reshape(C, th, tw, TILE, TILE).permute(0, 1, 3, 2, 4).reshape(C, th * TILE, tw * TILE)
    return img[:, :height, :width], acc[:, :height, :width, None]
