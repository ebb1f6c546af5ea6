"""Continuous camera trajectory ``T(t)`` in SE(3), evaluated at any batch of instants.

Two modes:

* ``"linear"``: between the bracketing samples ``a, b`` with ``u = (t - t_a) / (t_b - t_a)``,
  translation ``(1 - u) p_a + u p_b`` and rotation ``R_a Exp(u Log(R_a^T R_b))`` (SO(3) slerp on
  the shortest path; quaternion sign flips in the input cannot matter since poses are matrices).
* ``"spline"``: uniform cubic B-spline in SE(3) in the cumulative form (Kim et al. 1995; Sommer
  et al., "Efficient Derivative Computation for Cumulative B-Splines on Lie Groups", CVPR 2020;
  Mueller et al. 2019): on segment ``i`` with ``u in [0, 1)``,
  ``T(u) = T_i prod_{j=1..3} Exp(B~_j(u) Log(T_{i+j-1}^-1 T_{i+j}))`` with the cumulative basis
  ``B~(u) = C [1, u, u^2, u^3]``, ``C = 1/6 [[6,0,0,0],[5,3,-3,1],[1,3,3,-2],[0,0,0,1]]``.
  Control poses ("knots") sit every ``knot_spacing`` seconds from ``t_min - spacing`` on and are
  fitted to the samples (least squares on ``Log(T_sample^-1 T(t_sample))``, L-BFGS).

Refinement (BAD-Gaussians-style): ``refine=True`` adds learnable twists ``delta [K, 6]``
(initialised to zero) applied on the right of each knot (``T_k Exp(delta_k)``, i.e. in the camera
frame); knots are the samples in linear mode and the control poses in spline mode.

Instants outside ``[t_min, t_max]`` raise :class:`InputError` unless ``outside="clamp"``, which
evaluates them at the nearest end of the range. Internally everything is float64 (timestamps in
seconds may be large); results are cast to ``out_dtype`` at the very end.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from fusiongs.camera.lie import make_rigid, rigid_inverse, se3_exp, se3_log, so3_exp, so3_log
from fusiongs.camera.tum import PoseSamples
from fusiongs.errors import InputError

# the cumulative basis B (rows: B_0..B_3 as coefficients of 1, u, u², u³), written out in
# interpolate_bspline with Python numbers: no tensor to copy to the device on every call
_BASIS = ((6.0, 0.0, 0.0, 0.0), (5.0, 3.0, -3.0, 1.0), (1.0, 3.0, 3.0, -2.0), (0.0, 0.0, 0.0, 1.0))


def interpolate_linear(knot_t: torch.Tensor, knots: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Piecewise linear-translation / slerp-rotation interpolation.

    Args:
        knot_t: ``[M]`` strictly increasing sample times (s), ``M >= 1``.
        knots: ``[M, 4, 4]`` camera-to-world poses at ``knot_t``.
        t: ``[T]`` instants (s) inside ``[knot_t[0], knot_t[-1]]``.

    Returns:
        ``[T, 4, 4]`` camera-to-world poses.
    """
    if knot_t.shape[0] == 1:
        return knots.expand(t.shape[0], 4, 4)
    i = (torch.searchsorted(knot_t, t, right=True) - 1).clamp(0, knot_t.shape[0] - 2)
    ta, tb = knot_t[i], knot_t[i + 1]
    u = ((t - ta) / (tb - ta))[:, None]
    a, b = knots[i], knots[i + 1]
    Ra = a[:, :3, :3]
    R = Ra @ so3_exp(u * so3_log(Ra.transpose(-1, -2) @ b[:, :3, :3]))
    p = (1 - u) * a[:, :3, 3] + u * b[:, :3, 3]
    return make_rigid(R, p)


def interpolate_bspline(t0: float, spacing: float, knots: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Uniform cubic B-spline in SE(3), cumulative form (see the module docstring).

    Args:
        t0: time (s) of knot 1; knot ``k`` sits at ``t0 + (k - 1) * spacing``.
        spacing: knot spacing (s).
        knots: ``[K, 4, 4]`` control poses, ``K >= 4``; segments ``0 .. K-4`` cover
            ``[t0, t0 + (K - 3) * spacing]``.
        t: ``[T]`` instants (s) in that range.

    Returns:
        ``[T, 4, 4]`` camera-to-world poses.
    """
    n_seg = knots.shape[0] - 3
    s = (t - t0) / spacing
    i = torch.floor(s).clamp(0, n_seg - 1)
    u = s - i
    i = i.long()
    u2, u3 = u * u, u * u * u
    bt = torch.stack([(c0 + c1 * u + c2 * u2 + c3 * u3) / 6.0 for c0, c1, c2, c3 in _BASIS[1:]], -1)
    ctrl = knots[i[:, None] + torch.arange(4, device=t.device)]  # [T, 4, 4, 4]
    omega = se3_log(rigid_inverse(ctrl[:, :-1]) @ ctrl[:, 1:])  # [T, 3, 6]
    steps = se3_exp(bt[:, :, None] * omega)  # [T, 3, 4, 4]: B_1..B_3(u)
    return ctrl[:, 0] @ steps[:, 0] @ steps[:, 1] @ steps[:, 2]


class Trajectory(nn.Module):
    """Camera trajectory in time built from :class:`PoseSamples` (see the module docstring).

    Args:
        samples: timestamped camera-to-world poses (OpenCV axes).
        mode: ``"linear"`` or ``"spline"``.
        refine: add learnable se(3) corrections ``delta`` (zeros) to the knots.
        knot_spacing: spline knot spacing (s); default the median sample interval (knots then
            coincide with uniformly spaced samples).
        outside: ``"raise"`` (InputError for instants outside ``[t_min, t_max]``) or ``"clamp"``.
        out_dtype: dtype of the returned matrices.
        fit_iters: L-BFGS iterations of the spline fit (0: knots = linear interpolation).

    Raises:
        InputError: unknown mode/outside, too few samples, non-increasing times, bad spacing.
    """

    def __init__(self, samples: PoseSamples, mode: str = "linear", refine: bool = False,
                 knot_spacing: float | None = None, outside: str = "raise",
                 out_dtype: torch.dtype = torch.float32, fit_iters: int = 50,
                 device: torch.device | str | None = None):
        super().__init__()
        if mode not in ("linear", "spline"):
            raise InputError("trajectory", "mode", "'linear' or 'spline'", repr(mode))
        if outside not in ("raise", "clamp"):
            raise InputError("trajectory", "outside", "'raise' or 'clamp'", repr(outside))
        ts = np.asarray(samples.t, dtype=np.float64)
        c2w = np.asarray(samples.c2w, dtype=np.float64)
        if ts.ndim != 1 or c2w.shape != (ts.shape[0], 4, 4) or ts.shape[0] < (1 if mode == "linear" else 2):
            raise InputError("trajectory", "samples", f"t [M] and c2w [M, 4, 4] with M >= "
                             f"{1 if mode == 'linear' else 2}", f"{ts.shape} and {c2w.shape}")
        if np.any(np.diff(ts) <= 0) or not np.all(np.isfinite(ts)):
            raise InputError("trajectory", "samples.t", "finite, strictly increasing times")
        self.mode, self.outside, self.out_dtype = mode, outside, out_dtype
        self.t_min, self.t_max = float(ts[0]), float(ts[-1])
        f64 = dict(dtype=torch.float64, device=device)
        sample_t, sample_c2w = torch.tensor(ts, **f64), torch.tensor(c2w, **f64)
        self.register_buffer("sample_t", sample_t)
        if mode == "linear":
            self.spacing = 0.0
            self.register_buffer("knot_t", sample_t)
            self.register_buffer("knots", sample_c2w)
        else:
            dt = float(np.median(np.diff(ts))) if knot_spacing is None else float(knot_spacing)
            if not (math.isfinite(dt) and dt > 0):
                raise InputError("trajectory", "knot_spacing", "a positive number of seconds", dt)
            self.spacing = dt
            n_seg = max(1, math.ceil((self.t_max - self.t_min) / dt - 1e-9))
            knot_t = self.t_min + (torch.arange(n_seg + 3, **f64) - 1) * dt
            init = interpolate_linear(sample_t, sample_c2w, knot_t.clamp(self.t_min, self.t_max))
            self.register_buffer("knot_t", knot_t)
            self.register_buffer("knots", _fit_bspline(self.t_min, dt, init, sample_t, sample_c2w,
                                                       fit_iters))
        self.delta = nn.Parameter(torch.zeros(self.knots.shape[0], 6, **f64)) if refine else None

    def _check(self, t: torch.Tensor) -> torch.Tensor:
        t = torch.as_tensor(t, dtype=torch.float64, device=self.knots.device).reshape(-1)
        if self.outside == "clamp":
            return t.clamp(self.t_min, self.t_max)
        bad = (t < self.t_min) | (t > self.t_max) | ~torch.isfinite(t)
        if bool(bad.any()):
            v = float(t[bad][0])
            raise InputError("trajectory", "t", f"instants within [{self.t_min!r}, {self.t_max!r}] s", v)
        return t

    def knot_poses(self) -> torch.Tensor:
        """``[K, 4, 4]`` float64 knot poses including the refinement ``delta`` (if any)."""
        if self.delta is None:
            return self.knots
        return self.knots @ se3_exp(self.delta)

    def c2w(self, t: torch.Tensor) -> torch.Tensor:
        """Camera-to-world poses ``[T, 4, 4]`` (``out_dtype``) at instants ``t`` ``[T]`` (s)."""
        return self._c2w64(self._check(t)).to(self.out_dtype)

    def w2c(self, t: torch.Tensor) -> torch.Tensor:
        """World-to-camera view matrices ``[T, 4, 4]`` (``out_dtype``) at instants ``t`` ``[T]`` (s)."""
        return rigid_inverse(self._c2w64(self._check(t))).to(self.out_dtype)

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        """Same as :meth:`w2c` (view matrices for the rasteriser)."""
        return self.w2c(t)

    def _c2w64(self, t: torch.Tensor) -> torch.Tensor:
        if self.mode == "linear":
            return interpolate_linear(self.knot_t, self.knot_poses(), t)
        return interpolate_bspline(self.t_min, self.spacing, self.knot_poses(), t)

    def as_pose_samples(self, t: np.ndarray | None = None) -> PoseSamples:
        """Evaluate (without gradients) at ``t`` (default the sample times) for ``write_tum``."""
        ts = np.asarray(self.sample_t.cpu().numpy() if t is None else t, dtype=np.float64)
        with torch.no_grad():
            c2w = self._c2w64(self._check(torch.from_numpy(ts)))
        return PoseSamples(t=ts.copy(), c2w=c2w.cpu().numpy())


def _fit_bspline(t0: float, spacing: float, init: torch.Tensor, sample_t: torch.Tensor,
                 sample_c2w: torch.Tensor, iters: int, end_weight: float = 1e-2) -> torch.Tensor:
    """Knots ``[K, 4, 4]`` minimising ``sum ||Log(T_m^-1 T(t_m))||^2`` over the samples (L-BFGS),
    starting from ``init`` (linear interpolation of the samples at the knot times)."""
    if iters <= 0:
        return init
    eps = torch.zeros(init.shape[0], 6, dtype=init.dtype, device=init.device, requires_grad=True)
    target_inv = rigid_inverse(sample_c2w)
    opt = torch.optim.LBFGS([eps], lr=1.0, max_iter=iters, tolerance_grad=1e-12,
                            tolerance_change=1e-15, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        knots = init @ se3_exp(eps)
        pred = interpolate_bspline(t0, spacing, knots, sample_t)
        loss = se3_log(target_inv @ pred).square().sum()
        # End conditions ("not-a-knot"-like): the increments Log(T_k^-1 T_k+1) of the first and
        # last four knots change linearly; this fixes the two knots the samples leave free.
        ends = torch.cat([knots[:4], knots[-4:]])
        d = se3_log(rigid_inverse(ends[:-1]) @ ends[1:])
        loss = loss + end_weight * ((d[0] - 2 * d[1] + d[2]).square().sum()
                                    + (d[4] - 2 * d[5] + d[6]).square().sum())
        loss.backward()
        return loss

    with torch.enable_grad():
        opt.step(closure)
    return (init @ se3_exp(eps)).detach()
