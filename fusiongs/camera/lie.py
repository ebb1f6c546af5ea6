"""Differentiable SO(3) / SE(3) helpers in torch: exp, log, quaternions, rigid inverse.

Conventions: quaternions are ``(w, x, y, z)``; a twist ``xi = (rho, phi)`` holds the translational
part ``rho`` first and the rotation vector ``phi`` second, and ``se3_exp(xi)`` is the 4x4 matrix
``[[R, V rho], [0, 1]]`` (Barfoot, *State Estimation for Robotics*, 2017, §7.1.3–7.1.5). Every
function works on any batch shape ``[...]``, is loop-free and has finite gradients at the identity
(small-angle Taylor series behind ``torch.where`` with safe denominators).
"""

from __future__ import annotations

import torch

_SMALL = 1e-6  # squared angle (rad^2) below which Taylor series replace the closed forms


def skew(v: torch.Tensor) -> torch.Tensor:
    """Cross-product matrices ``[..., 3, 3]`` of vectors ``v`` ``[..., 3]`` (``skew(a) b = a x b``)."""
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], dim=-1).reshape(v.shape[:-1] + (3, 3))


def _coefficients(theta2: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """``A = sin t / t``, ``B = (1 - cos t) / t^2``, ``C = (t - sin t) / t^3`` and
    ``D = (1 - A / (2B)) / t^2`` for squared angles ``theta2``, safe at 0."""
    small = theta2 < _SMALL
    t2 = torch.where(small, torch.ones_like(theta2), theta2)
    t = torch.sqrt(t2)
    s, c = torch.sin(t), torch.cos(t)
    a = torch.where(small, 1 - theta2 / 6 + theta2**2 / 120, s / t)
    b = torch.where(small, 0.5 - theta2 / 24 + theta2**2 / 720, (1 - c) / t2)
    cc = torch.where(small, 1 / 6 - theta2 / 120 + theta2**2 / 5040, (t - s) / (t2 * t))
    d = torch.where(small, 1 / 12 + theta2 / 720 + theta2**2 / 30240, (1 - t * s / (2 * (1 - c))) / t2)
    return a, b, cc, d


def so3_exp(phi: torch.Tensor) -> torch.Tensor:
    """Rotation vectors ``[..., 3]`` (rad) to rotation matrices ``[..., 3, 3]`` (Rodrigues)."""
    a, b, _, _ = _coefficients((phi * phi).sum(-1))
    k = skew(phi)
    eye = torch.eye(3, dtype=phi.dtype, device=phi.device).expand(k.shape)
    return eye + a[..., None, None] * k + b[..., None, None] * (k @ k)


def matrix_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``[..., 3, 3]`` to unit quaternions ``[..., 4]`` (w, x, y, z), ``w >= 0``.

    Shepperd's method, loop-free: the four candidate formulas are evaluated and the one dividing by
    the largest of ``|w|, |x|, |y|, |z|`` is kept, so the result is accurate near 180 degrees.
    """
    m = R
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    diag = torch.stack([m00 + m11 + m22, m00 - m11 - m22, m11 - m00 - m22, m22 - m00 - m11], -1)
    s = 2 * torch.sqrt(torch.clamp(1 + diag, min=1e-12))  # 4|q_k| for each candidate k
    s0, s1, s2, s3 = s.unbind(-1)
    cands = torch.stack([
        torch.stack([s0 / 4, (m21 - m12) / s0, (m02 - m20) / s0, (m10 - m01) / s0], -1),
        torch.stack([(m21 - m12) / s1, s1 / 4, (m01 + m10) / s1, (m02 + m20) / s1], -1),
        torch.stack([(m02 - m20) / s2, (m01 + m10) / s2, s2 / 4, (m12 + m21) / s2], -1),
        torch.stack([(m10 - m01) / s3, (m02 + m20) / s3, (m12 + m21) / s3, s3 / 4], -1),
    ], -2)  # [..., 4 candidates, 4]
    k = diag.argmax(-1)[..., None, None].expand(diag.shape[:-1] + (1, 4))
    q = torch.gather(cands, -2, k).squeeze(-2)
    q = q * torch.where(q[..., :1] < 0, -1.0, 1.0).to(q.dtype)
    return q / q.norm(dim=-1, keepdim=True)


def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Quaternions ``[..., 4]`` (w, x, y, z; any non-zero norm, normalised here) to ``[..., 3, 3]``."""
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], -1).reshape(q.shape[:-1] + (3, 3))


def so3_log(R: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``[..., 3, 3]`` to rotation vectors ``[..., 3]`` with angle in ``[0, pi]``.

    Computed through the quaternion, ``phi = 2 atan2(|v|, w) v / |v|`` with ``w >= 0`` (shortest
    path), and the series ``2/w - 2|v|^2/(3 w^3)`` for small ``|v|``.
    """
    q = matrix_to_quat(R)
    w, v = q[..., 0], q[..., 1:]
    n2 = (v * v).sum(-1)
    small = n2 < _SMALL
    n = torch.sqrt(torch.where(small, torch.ones_like(n2), n2))
    w_safe = torch.where(small, w, torch.ones_like(w))  # w ~ 1 when |v| is small
    coef = torch.where(small, 2 / w_safe - 2 * n2 / (3 * w_safe**3), 2 * torch.atan2(n, w) / n)
    return coef[..., None] * v


def se3_exp(xi: torch.Tensor) -> torch.Tensor:
    """Twists ``[..., 6]`` = ``(rho, phi)`` to rigid transforms ``[..., 4, 4]``."""
    rho, phi = xi[..., :3], xi[..., 3:]
    a, b, c, _ = _coefficients((phi * phi).sum(-1))
    k = skew(phi)
    k2 = k @ k
    eye = torch.eye(3, dtype=xi.dtype, device=xi.device).expand(k.shape)
    R = eye + a[..., None, None] * k + b[..., None, None] * k2
    V = eye + b[..., None, None] * k + c[..., None, None] * k2
    return make_rigid(R, (V @ rho[..., None])[..., 0])


def se3_log(T: torch.Tensor) -> torch.Tensor:
    """Rigid transforms ``[..., 4, 4]`` to twists ``[..., 6]`` = ``(rho, phi)``, angle in ``[0, pi]``."""
    phi = so3_log(T[..., :3, :3])
    _, _, _, d = _coefficients((phi * phi).sum(-1))
    k = skew(phi)
    eye = torch.eye(3, dtype=T.dtype, device=T.device).expand(k.shape)
    v_inv = eye - 0.5 * k + d[..., None, None] * (k @ k)
    rho = (v_inv @ T[..., :3, 3:4])[..., 0]
    return torch.cat([rho, phi], -1)


def make_rigid(R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Rotation ``[..., 3, 3]`` and translation ``[..., 3]`` to a homogeneous ``[..., 4, 4]``."""
    top = torch.cat([R, t[..., None]], -1)
    bottom = torch.zeros(top.shape[:-2] + (1, 4), dtype=R.dtype, device=R.device)
    bottom[..., 0, 3] = 1
    return torch.cat([top, bottom], -2)


def rigid_inverse(T: torch.Tensor) -> torch.Tensor:
    """Inverse ``[..., 4, 4]`` of rigid transforms in closed form ``[[R^T, -R^T t], [0, 1]]``."""
    Rt = T[..., :3, :3].transpose(-1, -2)
    return make_rigid(Rt, -(Rt @ T[..., :3, 3:4])[..., 0])
