"""Where a pixel's surface point lies in another view: depth maps carried between posed cameras.

Conventions as :class:`~fusiongs.camera.pinhole.PinholeCamera`: pixel centres at integer + 0.5,
OpenCV camera axes (z forward), depth along the optical axis, no distortion (the rasteriser's
model). Coordinates are returned as ``torch.nn.functional.grid_sample`` grids
(``align_corners=False``: -1 and +1 are the outer edges of the border pixels), so an image of the
reference view is read at them directly.
"""

from __future__ import annotations

import torch

from fusiongs.camera.pinhole import PinholeCamera


def _pixel_centres(camera: PinholeCamera, device) -> tuple[torch.Tensor, torch.Tensor]:
    """``(u, v)`` ``[H, W]`` float64 pixel-centre coordinates (px)."""
    v, u = torch.meshgrid(torch.arange(camera.height, dtype=torch.float64, device=device) + 0.5,
                          torch.arange(camera.width, dtype=torch.float64, device=device) + 0.5,
                          indexing="ij")
    return u, v


def pixel_rays(camera: PinholeCamera, device: torch.device | str | None = None) -> torch.Tensor:
    """``[H, W, 3]`` float64 rays ``K⁻¹ [u, v, 1]`` through the pixel centres, on ``device``."""
    u, v = _pixel_centres(camera, device)
    return torch.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy,
                        torch.ones_like(u)], -1)


def _as_grid(u: torch.Tensor, v: torch.Tensor, camera: PinholeCamera) -> torch.Tensor:
    """Pixel coordinates ``[..., ]`` to ``grid_sample``'s ``[..., 2]`` (``align_corners=False``)."""
    return torch.stack([2 * u / camera.width - 1, 2 * v / camera.height - 1], -1)


def identity_grid(camera: PinholeCamera, device: torch.device | str | None = None) -> torch.Tensor:
    """``[H, W, 2]`` float64 grid that reads every pixel at its own centre."""
    return _as_grid(*_pixel_centres(camera, device), camera)


def reference_grid(depth: torch.Tensor, valid: torch.Tensor, c2w: torch.Tensor, w2c_ref: torch.Tensor,
                   camera: PinholeCamera, min_depth: float = 1e-3) -> torch.Tensor:
    """The reference camera's pixel that sees the surface point each pixel of each view sees.

    Pixel ``x`` of view ``k`` at depth ``d`` sees ``X = c2w_k (d K⁻¹ [x, 1])``; the returned
    coordinate is ``K (w2c_ref X)`` projected, as a ``grid_sample`` grid. Where ``valid`` is False
    (no surface rendered) or ``X`` is not in front of the reference camera, the pixel reads itself
    (the identity), which is the per-pixel assumption.

    Args:
        depth: ``[T, H, W]`` depth of every pixel of ``T`` views (scene units).
        valid: ``[T, H, W]`` bool, where ``depth`` is a surface.
        c2w: ``[T, 4, 4]`` camera-to-world poses of the views.
        w2c_ref: ``[4, 4]`` world-to-camera pose of the reference view.
        camera: intrinsics shared by all views.
        min_depth: points nearer than this to the reference camera (or behind it) read themselves.

    Returns:
        ``[T, H, W, 2]`` float64 grid, on ``depth``'s device.
    """
    dev = depth.device
    rays = pixel_rays(camera, dev)
    c2w, w2c_ref = c2w.to(dev, torch.float64), w2c_ref.to(dev, torch.float64)
    p = rays * depth.to(torch.float64)[..., None]                                  # [T, H, W, 3]
    world = torch.einsum("tij,thwj->thwi", c2w[:, :3, :3], p) + c2w[:, None, None, :3, 3]
    q = world @ w2c_ref[:3, :3].T + w2c_ref[:3, 3]
    z = q[..., 2]
    safe = torch.where(z > min_depth, z, torch.ones_like(z))
    u = camera.fx * q[..., 0] / safe + camera.cx
    v = camera.fy * q[..., 1] / safe + camera.cy
    grid = _as_grid(u, v, camera)
    keep = valid & (z > min_depth) & torch.isfinite(grid).all(-1)
    return torch.where(keep[..., None], grid, identity_grid(camera, dev).expand_as(grid))
