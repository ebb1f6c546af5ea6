"""Real spherical harmonics (degrees 0-3) for view-dependent Gaussian colour.

Basis order and signs follow the 3DGS convention (Kerbl et al., SIGGRAPH 2023, as used by gsplat):
coefficient ``k`` of degree ``l`` multiplies the real SH basis function listed in :func:`sh_basis`.
"""

from __future__ import annotations

import torch
from torch import Tensor

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def num_sh_bases(degree: int) -> int:
    """Number of coefficients ``(degree + 1) ** 2`` of an SH expansion up to ``degree``."""
    return (degree + 1) ** 2


def sh_basis(degree: int, dirs: Tensor) -> Tensor:
    """Real SH basis functions evaluated at unit directions.

    Args:
        degree: highest degree, 0..3.
        dirs: ``[..., 3]`` unit view directions (x, y, z).

    Returns:
        ``[..., (degree + 1) ** 2]`` basis values.
    """
    if not 0 <= degree <= 3:
        raise ValueError(f"sh degree must be 0..3, got {degree}")
    x, y, z = dirs.unbind(-1)
    out = [torch.full_like(x, SH_C0)]
    if degree >= 1:
        out += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [SH_C2[0] * xy, SH_C2[1] * yz, SH_C2[2] * (2.0 * zz - xx - yy), SH_C2[3] * xz,
                SH_C2[4] * (xx - yy)]
    if degree >= 3:
        out += [SH_C3[0] * y * (3.0 * xx - yy), SH_C3[1] * xy * z, SH_C3[2] * y * (4.0 * zz - xx - yy),
                SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy), SH_C3[4] * x * (4.0 * zz - xx - yy),
                SH_C3[5] * z * (xx - yy), SH_C3[6] * x * (xx - 3.0 * yy)]
    return torch.stack(out, dim=-1)


def eval_sh(degree: int, dirs: Tensor, coeffs: Tensor) -> Tensor:
    """Evaluate an SH expansion (gsplat's ``spherical_harmonics`` semantics, no offset, no clamp).

    Args:
        degree: degree to use, 0..3; only the first ``(degree + 1) ** 2`` coefficients are read.
        dirs: ``[..., 3]`` view directions (any length; normalised here, differentiably).
        coeffs: ``[..., K, D]`` coefficients with ``K >= (degree + 1) ** 2`` (broadcast with dirs).

    Returns:
        ``[..., D]`` value of the expansion. Renderers add 0.5 and clamp at 0 (see ``rasterize``).
    """
    k = num_sh_bases(degree)
    if coeffs.shape[-2] < k:
        raise ValueError(f"degree {degree} needs {k} SH coefficients, got {coeffs.shape[-2]}")
    unit = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    basis = sh_basis(degree, unit)  # [..., k]
    return (basis.unsqueeze(-1) * coeffs[..., :k, :]).sum(-2)


def rgb_to_sh(rgb: Tensor) -> Tensor:
    """DC coefficient whose rendered colour (value + 0.5) equals ``rgb``: ``(rgb - 0.5) / C0``."""
    return (rgb - 0.5) / SH_C0


def sh_to_rgb(sh_dc: Tensor) -> Tensor:
    """Colour rendered from a DC coefficient alone: ``sh_dc * C0 + 0.5`` (before the clamp at 0)."""
    return sh_dc * SH_C0 + 0.5
