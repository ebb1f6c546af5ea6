"""EWA projection of 3D Gaussians to screen space (pure torch, differentiable).

Follows Zwicker et al., "EWA Volume Splatting" (IEEE Vis 2001) as used by 3DGS (Kerbl et al. 2023),
with gsplat 1.5.3's conventions: the Jacobian's x/z and y/z are clamped to the field of view widened
by 30 %, ``eps2d`` is added to the 2D covariance, and the screen-space radius is the opacity-aware
extent ``min(3.33, sqrt(2 ln(255 o)))`` standard deviations per axis (Radl et al. 2024, StopThePop,
appendix B.2), rounded up.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

ALPHA_THRESHOLD = 1.0 / 255.0  # pairs with a smaller alpha are skipped
MAX_ALPHA = 0.999  # alpha is clamped to this
T_STOP = 1e-4  # compositing stops before transmittance would reach this


@dataclass
class Projected:
    """Per-camera screen-space Gaussians; culled entries have radii 0 and zero geometry.

    Attributes:
        means2d: ``[C, N, 2]`` pixel coordinates of the centres (differentiable).
        conics: ``[C, N, 3]`` inverse 2D covariance ``(a, b, c)`` of ``[[a, b], [b, c]]`` (1/px²).
        depths: ``[C, N]`` camera-space z (world units).
        radii: ``[C, N, 2]`` int32 half-extent of the screen box in pixels (x, y); 0 = culled.
        opacities: ``[C, N]`` opacities (broadcast of the input).
    """

    means2d: Tensor
    conics: Tensor
    depths: Tensor
    radii: Tensor
    opacities: Tensor


def quat_to_rotmat(quats: Tensor) -> Tensor:
    """Rotation matrices ``[..., 3, 3]`` from quaternions ``[..., 4]`` (wxyz, normalised here)."""
    w, x, y, z = F.normalize(quats, dim=-1).unbind(-1)
    rows = [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]
    return torch.stack(rows, dim=-1).reshape(quats.shape[:-1] + (3, 3))


def project_gaussians(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, viewmats: Tensor,
                      Ks: Tensor, width: int, height: int, near_plane: float, far_plane: float,
                      eps2d: float) -> Projected:
    """Project Gaussians into C pinhole cameras (gsplat ``fully_fused_projection`` semantics).

    Args:
        means: ``[N, 3]`` world centres. quats: ``[N, 4]`` wxyz. scales: ``[N, 3]`` std devs.
        opacities: ``[N]`` in (0, 1]. viewmats: ``[C, 4, 4]`` world->camera. Ks: ``[C, 3, 3]``.
        width, height: image size (px). near_plane, far_plane: depth culling range.
        eps2d: added to the diagonal of the 2D covariance (px²).

    Returns:
        :class:`Projected`. Gaussians are culled (radii 0) when the depth is outside
        ``[near_plane, far_plane]``, the 2D covariance is not positive definite, the opacity is
        below 1/255, or the screen box misses the image.
    """
    R = viewmats[:, :3, :3]
    t = viewmats[:, :3, 3]
    means_c = torch.matmul(means, R.transpose(-1, -2)) + t[:, None, :]  # [C, N, 3]
    M = quat_to_rotmat(quats) * scales[:, None, :]  # [N, 3, 3] = R_q S, world covariance M M^T
    x, y, z = means_c.unbind(-1)
    with torch.no_grad():
        depth_ok = (z >= near_plane) & (z <= far_plane)
    z = torch.where(depth_ok, z, torch.ones_like(z))  # keeps culled entries finite in backward
    fx, fy = Ks[:, 0, 0, None], Ks[:, 1, 1, None]
    cx, cy = Ks[:, 0, 2, None], Ks[:, 1, 2, None]
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    lim_x_pos, lim_x_neg = (width - cx) / fx + 0.3 * tan_x, cx / fx + 0.3 * tan_x
    lim_y_pos, lim_y_neg = (height - cy) / fy + 0.3 * tan_y, cy / fy + 0.3 * tan_y
    tx = z * torch.clamp(x / z, min=-lim_x_neg, max=lim_x_pos)
    ty = z * torch.clamp(y / z, min=-lim_y_neg, max=lim_y_pos)
    # Rows of T = J R M (J: EWA Jacobian, 2x3 with zeros at (0,1), (1,0)); 2D covariance = T T^T.
    # Broadcast products instead of batched 3x3 matmuls, which are slow on CPU for tiny matrices.
    jr0 = (fx / z)[..., None] * R[:, None, 0, :] - (fx * tx / (z * z))[..., None] * R[:, None, 2, :]
    jr1 = (fy / z)[..., None] * R[:, None, 1, :] - (fy * ty / (z * z))[..., None] * R[:, None, 2, :]
    T0 = (jr0[..., :, None] * M).sum(-2)  # [C, N, 3]
    T1 = (jr1[..., :, None] * M).sum(-2)
    means2d = torch.stack([fx * x / z + cx, fy * y / z + cy], dim=-1)

    c00 = (T0 * T0).sum(-1) + eps2d
    c11 = (T1 * T1).sum(-1) + eps2d
    c01 = (T0 * T1).sum(-1)
    det = c00 * c11 - c01 * c01
    opac = opacities.unsqueeze(0).expand(z.shape)
    with torch.no_grad():
        ok = depth_ok & (det > 0) & (opac >= ALPHA_THRESHOLD)
        extent = torch.sqrt(2.0 * torch.log(opac.clamp_min(ALPHA_THRESHOLD) / ALPHA_THRESHOLD))
        extent = extent.clamp(max=3.33)
        rx = torch.ceil(extent * torch.sqrt(c00.clamp_min(0)))
        ry = torch.ceil(extent * torch.sqrt(c11.clamp_min(0)))
        ok &= (rx > 0) | (ry > 0)
        mx, my = means2d[..., 0], means2d[..., 1]
        ok &= (mx + rx > 0) & (mx - rx < width) & (my + ry > 0) & (my - ry < height)
        radii = torch.stack([rx, ry], dim=-1).masked_fill(~ok[..., None], 0).to(torch.int32)
    det = torch.where(ok, det, torch.ones_like(det))
    conics = torch.stack([c11 / det, -c01 / det, c00 / det], dim=-1)
    okf = ok.unsqueeze(-1)
    return Projected(
        means2d=torch.where(okf, means2d, torch.zeros_like(means2d)),
        conics=torch.where(okf, conics, torch.zeros_like(conics)),
        depths=torch.where(ok, means_c[..., 2], torch.zeros_like(z)),
        radii=radii,
        opacities=opac,
    )
