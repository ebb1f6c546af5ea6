"""The plane-sweep matching cost written plainly (float64 geometry, one plane at a time, sources
sorted by ``topk``): the specification :func:`fusiongs.camera.stereo.plane_sweep_cost` is tested
against; nothing else calls it."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.reproject import pixel_rays


def plane_sweep_cost(ref: torch.Tensor, ref_c2w: torch.Tensor, src: torch.Tensor, src_c2w: torch.Tensor,
                     camera: PinholeCamera, depths: torch.Tensor, window: int = 5) -> torch.Tensor:
    """:func:`fusiongs.camera.stereo.plane_sweep_cost` (same arguments, same ``[D, H, W]`` result),
    written plainly; inputs are assumed valid (the fast form checks them)."""
    gamma = 1 / 2.2
    r = ref.clamp_min(0).pow(gamma).float().permute(2, 0, 1)[None]      # [1, C, H, W]
    s = src.clamp_min(0).pow(gamma).float().permute(0, 3, 1, 2)         # [S, C, H, W]
    rays = pixel_rays(camera, "cpu").reshape(-1, 3)                     # [P, 3]
    ref_c2w, src_c2w = ref_c2w.double(), src_c2w.double()
    w2s = torch.linalg.inv(src_c2w) @ ref_c2w                           # ref camera -> source camera
    rot, trans = w2s[:, :3, :3], w2s[:, :3, 3]
    rot_rays = torch.einsum("sij,pj->spi", rot, rays)                   # [S, P, 3]
    keep = (src.shape[0] + 1) // 2
    h, w = camera.height, camera.width
    out = torch.empty(len(depths), h, w, dtype=torch.float32)
    for k, d in enumerate(depths.tolist()):                             # loop over planes only
        x = rot_rays * d + trans[:, None, :]                            # [S, P, 3]
        z = x[..., 2]
        front = z > 1e-6
        zs = torch.where(front, z, torch.ones_like(z))
        u = camera.fx * x[..., 0] / zs + camera.cx
        v = camera.fy * x[..., 1] / zs + camera.cy
        inside = front & (u >= 0) & (u <= w) & (v >= 0) & (v <= h)
        grid = torch.stack([2 * u / w - 1, 2 * v / h - 1], -1).float().reshape(-1, h, w, 2)
        warped = F.grid_sample(s, grid, mode="bilinear", padding_mode="border", align_corners=False)
        diff = (warped - r).abs().mean(1)                               # [S, H, W]
        diff = torch.where(inside.reshape(-1, h, w), diff, torch.full_like(diff, float("inf")))
        best = diff.topk(keep, dim=0, largest=False).values             # [keep, H, W]
        out[k] = best.mean(0)
    finite = torch.isfinite(out)
    filled = torch.where(finite, out, torch.zeros_like(out))[:, None]
    num = F.avg_pool2d(filled, window, 1, window // 2, count_include_pad=False)[:, 0]
    den = F.avg_pool2d(finite.float()[:, None], window, 1, window // 2, count_include_pad=False)[:, 0]
    return torch.where(finite, num / den.clamp_min(1e-6), torch.full_like(out, float("inf")))
