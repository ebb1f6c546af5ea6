"""CPU backend: numba kernels behind torch autograd Functions (projection and compositing).

Compositing: float32 inputs use the SIMD kernels of ``_cpu_simd``; float64 inputs the scalar
kernels of ``_cpu_kernels`` (the precise path that gradcheck and the parity tests run on); the SIMD
kernels read each entry's values from one record (``_cpu_simd.pack_entries``, made per render). The
entries' depth order and pixel boxes come from ``_cpu_layout`` (a numba radix sort; the same as the
torch reference in ``_boxes``), and the backward pass leaves out cameras whose outputs get no
gradient (:func:`row_ends`). The projection (``_cpu_projection``) computes in float64 and returns
the inputs' dtype.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from fusiongs.errors import InputError
from fusiongs.render import _cpu_kernels as K
from fusiongs.render import _cpu_projection as P
from fusiongs.render import _cpu_simd as S
from fusiongs.render._cpu_layout import depth_keys, visible_layout
from fusiongs.render.projection import Projected


def _np(t: Tensor) -> np.ndarray:
    return t.detach().contiguous().numpy()


def _use_simd(dtype, n_entries: int) -> bool:
    """The float32 SIMD kernels for float32 (entry indices must fit int32), else the scalar ones."""
    return dtype == np.float32 and n_entries < 2**31


def _idle_cameras(v_img: np.ndarray, v_alpha: np.ndarray) -> np.ndarray:
    """``[C]`` bool: cameras whose image and alpha gradients are all exactly zero (NaN is not)."""
    C = v_img.shape[0]
    return ~((v_img.reshape(C, -1) != 0).any(1) | (v_alpha.reshape(C, -1) != 0).any(1))


def row_ends(row_off: np.ndarray, idle: np.ndarray, height: int) -> np.ndarray:
    """``[C*H]`` end of each row's entries for the backward kernels, the rows of ``idle`` cameras
    ``[C]`` left empty (end = start).

    The backward kernels walk row ``task``'s entries ``rows[row_off[task]:row_end[task]]``. A camera
    whose images and alphas get no gradient (an output the loss does not use, as the window
    starts of an event-only warm-up step) gives every entry a zero gradient, which is what
    ``gbuf``'s zeros already hold: skipping its rows changes no value.
    """
    row_end = row_off[1:].copy()
    for c in np.flatnonzero(idle):
        row_end[c * height:(c + 1) * height] = row_off[c * height:(c + 1) * height]
    return row_end


class CompositeCPU(torch.autograd.Function):
    """Differentiable compositing on CPU (numba forward and hand-written backward).

    Forward inputs: ``means2d [C,N,2]``, ``conics [C,N,3]``, ``colors [C,N,D]``, ``opacities [C,N]``
    (differentiable), then ``ids [P]``, ``box [P,4]``, ``cam_off [C+1]`` (int64, from
    :func:`~fusiongs.render._cpu_layout.visible_layout`, or the torch reference's
    :func:`~fusiongs.render._boxes.sorted_visible` / :func:`~fusiongs.render._boxes.pixel_boxes`),
    ``width``, ``height``.
    Outputs: ``images [C,H,W,D]`` and ``alphas [C,H,W,1]`` (no background).
    """

    @staticmethod
    def forward(ctx, means2d, conics, colors, opacities, ids, box, cam_off, width, height):
        C, N, D = colors.shape
        dtype = colors.dtype
        npd = np.float64 if dtype == torch.float64 else np.float32
        m = _np(means2d).astype(npd, copy=False)
        con = _np(conics).astype(npd, copy=False)
        arrs = (np.ascontiguousarray(m[..., 0]), np.ascontiguousarray(m[..., 1]),
                np.ascontiguousarray(con[..., 0]), np.ascontiguousarray(con[..., 1]),
                np.ascontiguousarray(con[..., 2]), _np(opacities).astype(npd, copy=False))
        col = _np(colors)
        ids_np, box_np, off_np = _np(ids), _np(box), _np(cam_off)
        simd = _use_simd(npd, len(ids_np))
        row_off, rows, entry_row0 = K.row_lists(box_np, off_np, height)
        img = np.zeros((C, height, width, D), npd)
        tfin = np.empty((C, height, width), npd)
        last = np.empty((C, height, width), np.int64)
        if simd:  # the SIMD kernels read one record per entry (with its alpha limit)
            arrs = S.pack_entries(ids_np, off_np, *arrs, S.alpha_limits(arrs[5]), col)
            S.forward(box_np, row_off, rows, *arrs, height, width, img, tfin, last)
        else:
            K.forward(ids_np, box_np, row_off, rows, *arrs, col, height, width, img, tfin, last)
        ctx.saved = (ids_np, box_np, off_np, row_off, rows, entry_row0, arrs, col, tfin, last, width,
                     height, simd)
        img_t = torch.from_numpy(img)
        alpha_t = torch.from_numpy(1.0 - tfin).unsqueeze(-1)
        return img_t, alpha_t

    @staticmethod
    def backward(ctx, v_img, v_alpha):
        (ids_np, box_np, off_np, row_off, rows, entry_row0, arrs, col, tfin, last, width, height,
         simd) = ctx.saved
        C, N, D = col.shape
        npd = col.dtype
        v_img_np = _np(v_img).astype(npd, copy=False)
        v_alpha_np = np.ascontiguousarray(_np(v_alpha)[..., 0].astype(npd, copy=False))
        gbuf = np.zeros((int(entry_row0[-1]), 6 + D), npd)
        row_end = row_ends(row_off, _idle_cameras(v_img_np, v_alpha_np), height)
        if simd:
            S.backward(box_np, row_off, row_end, rows, entry_row0, *arrs, height, width, tfin, last,
                       v_img_np, v_alpha_np, gbuf)
        else:
            K.backward(ids_np, box_np, row_off, row_end, rows, entry_row0, *arrs, col, height, width,
                       tfin, last, v_img_np, v_alpha_np, gbuf)
        out = np.zeros((C, N, 6 + D), npd)
        K.reduce_grads(ids_np, off_np, entry_row0, gbuf, out)
        g = torch.from_numpy(out)
        return (g[..., 0:2], g[..., 2:5], g[..., 6:], g[..., 5], None, None, None, None, None)


def composite_cpu(proj: Projected, colors: Tensor, width: int, height: int) -> tuple[Tensor, Tensor]:
    """Composite projected Gaussians with the numba kernels (same contract as ``composite_pairs``).

    Args:
        proj: screen-space Gaussians of C cameras. colors: ``[C, N, D]`` (float32 or float64, CPU).
        width, height: image size (px).

    Returns:
        ``(images [C, H, W, D], alphas [C, H, W, 1])`` without background.
    """
    keys, bits = depth_keys(_np(proj.depths))
    gid, box, offsets = (torch.from_numpy(a) for a in visible_layout(
        keys, bits, _np(proj.radii), _np(proj.means2d), width, height))
    return CompositeCPU.apply(proj.means2d, proj.conics, colors, proj.opacities, gid, box, offsets,
                              width, height)


def _f64(t: Tensor) -> np.ndarray:
    return _np(t.to(torch.float64))


class ProjectCPU(torch.autograd.Function):
    """:func:`fusiongs.render.projection.project_gaussians` as one numba kernel each way.

    Forward inputs: ``means [N,3]``, ``quats [N,4]``, ``scales [N,3]``, ``viewmats [C,4,4]``
    (differentiable), then ``opacities [N]`` and ``Ks [C,3,3]`` (no gradient: they only cull and
    size the radii), ``width``, ``height``, ``near``, ``far``, ``eps2d``.
    Outputs: ``means2d [C,N,2]``, ``conics [C,N,3]``, ``depths [C,N]`` (the means' dtype) and
    ``radii [C,N,2]`` int32 (not differentiable).
    """

    @staticmethod
    def forward(ctx, means, quats, scales, viewmats, opacities, Ks, width, height, near, far, eps2d):
        C, N = viewmats.shape[0], means.shape[0]
        arrs = (_f64(means), _f64(quats), _f64(scales))
        view, k = _f64(viewmats), _f64(Ks)
        m2d, con = np.empty((C, N, 2)), np.empty((C, N, 3))
        depth, radii = np.empty((C, N)), np.empty((C, N, 2), np.int32)
        P.forward(*arrs, _f64(opacities), view, k, width, height, near, far, eps2d, m2d, con, depth, radii)
        ctx.saved = (arrs, view, k, width, height, eps2d, radii, means.dtype, viewmats.dtype)
        dt = means.dtype
        radii_t = torch.from_numpy(radii)
        ctx.mark_non_differentiable(radii_t)
        return (torch.from_numpy(m2d).to(dt), torch.from_numpy(con).to(dt),
                torch.from_numpy(depth).to(dt), radii_t)

    @staticmethod
    def backward(ctx, g_m2d, g_con, g_depth, _g_radii):
        arrs, view, k, width, height, eps2d, radii, dt, vdt = ctx.saved
        C, N = radii.shape[:2]
        grads = [np.zeros(shape) if g is None else _f64(g)
                 for g, shape in ((g_m2d, (C, N, 2)), (g_con, (C, N, 3)), (g_depth, (C, N)))]
        g_means, g_quats, g_scales = np.empty((N, 3)), np.empty((N, 4)), np.empty((N, 3))
        g_view = np.empty((max(1, -(-N // P.BLOCK)), C, 12))
        P.backward(*arrs, view, k, width, height, eps2d, radii, *grads, g_means, g_quats, g_scales, g_view)
        gv = torch.zeros(C, 4, 4, dtype=vdt)
        gv[:, :3, :] = torch.from_numpy(g_view.sum(0).reshape(C, 3, 4))
        return (torch.from_numpy(g_means).to(dt), torch.from_numpy(g_quats).to(dt),
                torch.from_numpy(g_scales).to(dt), gv, None, None, None, None, None, None, None)


def project_cpu(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, viewmats: Tensor,
                Ks: Tensor, width: int, height: int, near_plane: float, far_plane: float,
                eps2d: float) -> Projected:
    """:func:`fusiongs.render.projection.project_gaussians` (same arguments, same result up to
    rounding: computed in float64) with the numba kernels of ``_cpu_projection``; CPU tensors."""
    for name, t in (("means", means), ("quats", quats), ("scales", scales), ("opacities", opacities),
                    ("viewmats", viewmats), ("Ks", Ks)):
        if t.device.type != "cpu":
            raise InputError("project_cpu", name, "a CPU tensor (the numba projection)", str(t.device))
    m2d, con, depth, radii = ProjectCPU.apply(means, quats, scales, viewmats, opacities, Ks, width,
                                              height, float(near_plane), float(far_plane), float(eps2d))
    return Projected(means2d=m2d, conics=con, depths=depth, radii=radii,
                     opacities=opacities.unsqueeze(0).expand(depth.shape))
