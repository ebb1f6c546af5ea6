"""Depth order and pixel boxes of the torch backend (no gradients); the CPU backend computes the
same in one numba pass (``_cpu_layout``), tested against these."""

from __future__ import annotations

import torch
from torch import Tensor


@torch.no_grad()
def sorted_visible(depths: Tensor, radii: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Visible (camera, Gaussian) entries grouped by camera, front to back within a camera.

    Args:
        depths: ``[C, N]`` camera-space depths.
        radii: ``[C, N, 2]`` int32 radii, 0 = culled.

    Returns:
        ``(cam, gid, cam_offsets)``: ``[P]`` int64 camera and Gaussian index of each visible entry;
        ``[C + 1]`` int64 start of each camera's run. Depth ties keep Gaussian index order (stable
        sort), as gsplat's radix sort does.
    """
    C, N = depths.shape
    vis = radii[..., 0] > 0
    key = torch.where(vis, depths, torch.full_like(depths, float("inf")))
    order = torch.argsort(key, dim=1, stable=True)  # one sort per camera row; culled entries last
    keep = vis.gather(1, order)
    flat = (order + torch.arange(C, device=depths.device)[:, None] * N)[keep]  # camera-major
    cam, gid = flat // N, flat % N
    counts = keep.sum(1)
    offsets = torch.zeros(C + 1, dtype=torch.int64, device=depths.device)
    offsets[1:] = torch.cumsum(counts, 0)
    return cam, gid, offsets


@torch.no_grad()
def pixel_boxes(means2d: Tensor, radii: Tensor, width: int, height: int) -> Tensor:
    """Inclusive pixel-index box ``[..., 4] = (x0, x1, y0, y1)`` of pixel centres within the radii.

    A pixel ``(i, j)`` has its centre at ``(i + 0.5, j + 0.5)``; the box is clipped to the image and
    may be empty (``x1 < x0``). Every pixel whose alpha can reach 1/255 lies inside it, because the
    radius is the opacity-aware extent of the alpha >= 1/255 ellipse.

    Args:
        means2d: ``[..., 2]`` pixel coordinates. radii: ``[..., 2]`` half-extents in pixels.
        width, height: image size.
    """
    m = means2d.to(torch.float64)
    r = radii.to(torch.float64)
    lo = torch.ceil(m - r - 0.5)
    hi = torch.floor(m + r - 0.5)
    x0 = lo[..., 0].clamp(0, width)
    y0 = lo[..., 1].clamp(0, height)
    x1 = hi[..., 0].clamp(-1, width - 1)
    y1 = hi[..., 1].clamp(-1, height - 1)
    return torch.stack([x0, x1, y0, y1], dim=-1).to(torch.int64)
