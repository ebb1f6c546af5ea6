"""Float32 SIMD variants of the numba compositing kernels (same results as ``_cpu_kernels``).

The per-row work is the same as in :mod:`fusiongs.render._cpu_kernels` (one parallel task per image
row, entries front to back, the classic 3DGS backward walking them back to front), but the loop
over a Gaussian's pixels in a row is written without branches so that LLVM vectorises it (16
float32 lanes with AVX-512, 8 with AVX2):

- every early ``continue`` becomes a mask, and a masked-out pixel gets weight 0, so stores need
  no condition (``s' = a·c + (1 − a)·s`` is exactly ``s`` for ``a = 0``);
- ``exp`` is :func:`exp_neg_f32`, a polynomial with a bit-built power of two (libm's scalar ``exp``
  does not vectorise); relative error below 1e-7, the float32 rounding level;
- pixel indices are unsigned, which removes numba's negative-index wrap-around that otherwise keeps
  LLVM from proving a load and a store hit the same element, and the error model is numpy's, so
  that a division carries no ZeroDivisionError branch;
- colours live in row buffers laid out ``[D, W]``; three colours (the usual case) are handled in one
  pass over the row (views of the three rows: 2-9 % less time than a pass per channel on the
  173x130 event-only model), other counts one channel at a time; with three
  colours the forward pass also computes each pixel's alpha in that same pass (7-9 % less forward
  time, the same images bit for bit), while the backward pass keeps its
  three passes (fused, in full or in part, it was no faster);
- each entry's mean, conic, opacity and colours are copied once per render into one record in
  entry order (:func:`pack_entries`), so that a row's entries, which come in entry order, are read
  from consecutive records instead of gathered by Gaussian index from ten arrays (on a trained
  173x130 model's nine views, forward 5 % and backward 13 % less time, the same results bit for
  bit);
- the forward pass shrinks each row's span to the pixels still below the stop transmittance, and
  the backward pass skips, before any per-pixel work, entries behind the last contributing entry of
  every pixel they cover (most entries of saturated rows).

The float64 kernels of ``_cpu_kernels`` remain the reference (gradcheck runs on them); the parity of
these kernels with them is tested in ``tests/render/test_cpu_simd.py``.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.extending import intrinsic

from fusiongs.render._cpu_kernels import ALPHA_T, MAX_A, T_STOP, row_span, store_geometry_grads

F = np.float32
U = np.uint64
# exp(r) ≈ 1 + r + r² q(r) on |r| <= ln2 / 2, q fitted by weighted least squares on Chebyshev
# nodes (relative error 6.5e-8 in float32).
Q0, Q1, Q2, Q3, Q4, Q5 = (F(5.0000000e-01), F(1.6666666e-01), F(4.1666269e-02), F(8.3334297e-03),
                          F(1.3946021e-03), F(1.9826496e-04))
LOG2E = F(1.4426950408889634)
LN2_HI = F(0.693359375)  # ln 2 split so that n · LN2_HI is exact for |n| < 2^15
LN2_LO = F(-2.1219444005469057e-04)
LANES = 16  # pixels per block: one AVX-512 register of float32
SIGMA_MAX = F(80.0)  # exp(-80) ~ 2e-35: still a normal float32, and far below any alpha cut


@intrinsic
def _int32_bits_as_float32(typingctx, x):
    """Reinterpret the bits of an int32 as a float32 (vectorises to nothing)."""
    sig = types.float32(types.int32)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.FloatType())

    return sig, codegen


@njit(cache=True, inline="always", fastmath={"contract"})
def exp_neg_f32(s):  # pragma: no cover - numba
    """``exp(-s)`` in float32 for ``0 <= s <= 80``: ``2^n · exp(r)``, ``-s = n ln 2 + r``."""
    x = -s
    n = np.int32(x * LOG2E + F(128.5)) - np.int32(128)  # round to nearest; x * LOG2E > -128
    nf = F(n)
    r = (x - nf * LN2_HI) - nf * LN2_LO
    q = ((((Q5 * r + Q4) * r + Q3) * r + Q2) * r + Q1) * r + Q0
    p = (q * r) * r + r + F(1.0)
    return p * _int32_bits_as_float32((n + np.int32(127)) << np.int32(23))


def alpha_limits(op: np.ndarray) -> np.ndarray:
    """``[C, N]`` float64 ``_cpu_kernels.alpha_limit`` of each opacity (once per render, not per
    row; opacities below 1/255 belong to culled entries and get the limit of 1/255)."""
    o = np.maximum(op.astype(np.float64), ALPHA_T)
    return 2.0 * np.log(o / ALPHA_T) * (1.0 + 1e-6) + 1e-6


@njit(cache=True, parallel=True)
def pack_entries(ids, cam_off, mx, my, ca, cb, cc, op, lim, col):  # pragma: no cover - numba
    """``(pk [P, 6 + D] float32, limk [P] float64)``: each entry's mean, conic, opacity and colours,
    and its alpha limit, in entry order (one record per entry instead of gathers by Gaussian)."""
    C = cam_off.shape[0] - 1
    D = col.shape[2]
    P = ids.shape[0]
    pk = np.empty((P, 6 + D), np.float32)
    limk = np.empty(P, np.float64)
    for c in range(C):
        for k in prange(cam_off[c], cam_off[c + 1]):
            g = ids[k]
            pk[k, 0] = mx[c, g]
            pk[k, 1] = my[c, g]
            pk[k, 2] = ca[c, g]
            pk[k, 3] = cb[c, g]
            pk[k, 4] = cc[c, g]
            pk[k, 5] = op[c, g]
            for d in range(D):
                pk[k, 6 + d] = col[c, g, d]
            limk[k] = lim[c, g]
    return pk, limk


@njit(cache=True, inline="always")
def _span(k, y, box, pk, lim):  # pragma: no cover - numba
    """``_cpu_kernels.row_span`` of entry k in row y, from its packed record."""
    return row_span(box[k, 0], box[k, 1], pk[k, 0], pk[k, 1], pk[k, 2], pk[k, 3], pk[k, 4], y, lim)


@njit(cache=True, inline="always", fastmath={"contract"})
def _lane_gauss(mxg, x, ha, bdy, cyy):  # pragma: no cover - numba
    """``(dx, sigma, exp(-sigma))`` of pixel x of a row: ``sigma = ha dx² + bdy dx + cyy``, the
    exponential taken of sigma clamped to ``[0, SIGMA_MAX]`` (callers mask ``sigma < 0``)."""
    dx = mxg - F(x)
    sigma = (ha * dx + bdy) * dx + cyy
    sc = sigma if sigma > F(0.0) else F(0.0)
    sc = sc if sc < SIGMA_MAX else SIGMA_MAX
    return dx, sigma, exp_neg_f32(sc)


@njit(cache=True, inline="always", fastmath={"contract"})
def _lane_front(mxg, x, ha, bdy, cyy, o, xe, kk, trow, alive, lrow):  # pragma: no cover - numba
    """One pixel of an entry in the forward pass: returns ``(alpha T, stop)``, the entry's weight
    at the pixel (0 where it does not count) and whether the pixel's transmittance stops there;
    ``trow``, ``alive`` and ``lrow`` are updated in place."""
    _, sigma, gauss = _lane_gauss(mxg, x, ha, bdy, cyy)
    alpha = o * gauss
    alpha = alpha if alpha < F(MAX_A) else F(MAX_A)
    t = trow[x]
    nt = t * (F(1.0) - alpha)
    hit = (x <= xe) & (sigma >= F(0.0)) & (alpha >= F(ALPHA_T)) & (alive[x] > F(0.0))
    stop = hit & (nt <= F(T_STOP))
    use = hit & (nt > F(T_STOP))
    trow[x] = nt if use else t
    alive[x] = F(0.0) if stop else alive[x]
    lrow[x] = kk if use else lrow[x]
    return (alpha * t if use else F(0.0)), stop


@njit(cache=True, parallel=True, fastmath={"contract"}, error_model="numpy")
def forward(box, row_off, rows, pk, limk, height, width,
            img, tfin, last):  # pragma: no cover - numba
    """``_cpu_kernels.forward`` for float32 arrays, the Gaussians' values read from the records
    ``pk`` and alpha limits ``limk`` of :func:`pack_entries` (in place of ``ids`` and the per-Gaussian
    arrays)."""
    D = pk.shape[1] - 6
    for task in prange(row_off.shape[0] - 1):
        c = task // height
        y = task % height
        wp = width + LANES  # row buffers padded for whole blocks of LANES pixels
        trow = np.ones(wp, np.float32)
        alive = np.ones(wp, np.float32)  # 1 until the pixel's transmittance would hit T_STOP
        lrow = np.full(wp, -1, np.int32)
        wbuf = np.zeros(wp, np.float32)
        acc = np.zeros((D, wp), np.float32)
        acc0, acc1, acc2 = acc[0], acc[min(1, D - 1)], acc[min(2, D - 1)]  # used when D == 3 only
        lo, hi = 0, width - 1  # span of pixels still alive
        py = F(y) + F(0.5)
        for r in range(row_off[task], row_off[task + 1]):
            k = rows[r]
            x0, x1 = _span(k, y, box, pk, limk[k])
            x0 = max(x0, lo)
            x1 = min(x1, hi)
            if x1 < x0:
                continue
            dy = pk[k, 1] - py
            ha = F(0.5) * pk[k, 2]
            bdy = pk[k, 3] * dy
            cyy = F(0.5) * pk[k, 4] * dy * dy
            o = pk[k, 5]
            mxg = pk[k, 0] - F(0.5)
            kk = np.int32(k)
            xe = U(x1)
            n_stop = 0
            if D == 3:  # one pass: each pixel's alpha and its three colours together
                c0 = pk[k, 6]
                c1 = pk[k, 7]
                c2 = pk[k, 8]
                for blk in range(U(x0), U(x1 + 1), U(LANES)):
                    for lane in range(U(LANES)):
                        x = blk + lane
                        w, stop = _lane_front(mxg, x, ha, bdy, cyy, o, xe, kk, trow, alive, lrow)
                        n_stop += 1 if stop else 0
                        acc0[x] += w * c0
                        acc1[x] += w * c1
                        acc2[x] += w * c2
            else:
                for blk in range(U(x0), U(x1 + 1), U(LANES)):
                    for lane in range(U(LANES)):
                        x = blk + lane
                        wbuf[x], stop = _lane_front(mxg, x, ha, bdy, cyy, o, xe, kk, trow, alive, lrow)
                        n_stop += 1 if stop else 0
                for d in range(D):
                    cd = pk[k, 6 + d]
                    for blk in range(U(x0), U(x1 + 1), U(LANES)):
                        for lane in range(U(LANES)):
                            x = blk + lane
                            acc[d, x] += wbuf[x] * cd
            if n_stop > 0:
                while lo <= hi and alive[lo] == F(0.0):
                    lo += 1
                while hi >= lo and alive[hi] == F(0.0):
                    hi -= 1
                if lo > hi:
                    break
        for x in range(width):
            tfin[c, y, x] = trow[x]
            last[c, y, x] = lrow[x]
            for d in range(D):
                img[c, y, x, d] = acc[d, x]


@njit(cache=True, parallel=True, fastmath={"contract", "reassoc"}, error_model="numpy")
def backward(box, row_off, row_end, rows, entry_row0, pk, limk, height, width,
             tfin, last, v_img, v_alpha, gbuf):  # pragma: no cover - numba
    """``_cpu_kernels.backward`` for float32 arrays (rows ``row_off[task]:row_end[task]``), the
    Gaussians' values read from :func:`pack_entries`' ``pk`` and ``limk`` (sums reassociated)."""
    D = pk.shape[1] - 6
    for task in prange(row_off.shape[0] - 1):
        c = task // height
        y = task % height
        wp = width + LANES  # padded as in the forward pass
        trow = np.ones(wp, np.float32)    # transmittance in front of the current entry
        varow = np.zeros(wp, np.float32)  # v_alpha · T_final
        lrow = np.full(wp, -1, np.int32)
        vrow = np.zeros((D, wp), np.float32)
        srow = np.zeros((D, wp), np.float32)  # colour composited behind the current entry
        vrow0, vrow1, vrow2 = vrow[0], vrow[min(1, D - 1)], vrow[min(2, D - 1)]  # used when D == 3
        srow0, srow1, srow2 = srow[0], srow[min(1, D - 1)], srow[min(2, D - 1)]  # only
        abuf = np.zeros(wp, np.float32)   # alpha of the entry (0 where it does not count)
        tbuf = np.zeros(wp, np.float32)   # T in front of the entry (0 where it does not count)
        ibuf = np.zeros(wp, np.float32)   # 1 / (1 - alpha) (0 where it does not count)
        gbx = np.zeros(wp, np.float32)    # exp(-sigma), 0 where no gradient reaches the entry
        vabuf = np.zeros(wp, np.float32)  # dL/dalpha before the T factor
        row_last = -1  # the deepest entry that reaches any pixel of the row
        for x in range(width):
            trow[x] = tfin[c, y, x]
            varow[x] = v_alpha[c, y, x] * tfin[c, y, x]
            lrow[x] = last[c, y, x]
            row_last = max(row_last, last[c, y, x])
            for d in range(D):
                vrow[d, x] = v_img[c, y, x, d]
        py = F(y) + F(0.5)
        for r in range(row_end[task] - 1, row_off[task] - 1, -1):
            k = rows[r]
            if k > row_last:
                continue  # behind every pixel's last entry: no gradient (gbuf starts zeroed)
            e = entry_row0[k] + y - box[k, 2]
            x0, x1 = _span(k, y, box, pk, limk[k])
            if x1 < x0:
                continue
            reach = np.int32(-1)
            for x in range(U(x0), U(x1 + 1)):
                reach = max(reach, lrow[x])
            if np.int32(k) > reach:
                continue  # behind the last entry of each pixel in its range
            dy = pk[k, 1] - py
            a = pk[k, 2]
            b = pk[k, 3]
            cz = pk[k, 4]
            ha = F(0.5) * a
            bdy = b * dy
            cyy = F(0.5) * cz * dy * dy
            o = pk[k, 5]
            mxg = pk[k, 0] - F(0.5)
            kk = np.int32(k)
            xe = U(x1)
            for blk in range(U(x0), U(x1 + 1), U(LANES)):
                for lane in range(U(LANES)):
                    x = blk + lane
                    _, sigma, gauss = _lane_gauss(mxg, x, ha, bdy, cyy)
                    og = o * gauss
                    alpha = og if og < F(MAX_A) else F(MAX_A)
                    valid = (x <= xe) & (kk <= lrow[x]) & (sigma >= F(0.0)) & (alpha >= F(ALPHA_T))
                    inv = F(1.0) / (F(1.0) - alpha)
                    t = trow[x] * inv
                    abuf[x] = alpha if valid else F(0.0)
                    tbuf[x] = t if valid else F(0.0)
                    ibuf[x] = inv if valid else F(0.0)
                    trow[x] = t if valid else trow[x]
                    gbx[x] = gauss if valid & (og <= F(MAX_A)) else F(0.0)
                    vabuf[x] = F(0.0)
            if D == 3:
                c0 = pk[k, 6]
                c1 = pk[k, 7]
                c2 = pk[k, 8]
                g0 = F(0.0)
                g1 = F(0.0)
                g2 = F(0.0)
                for blk in range(U(x0), U(x1 + 1), U(LANES)):
                    for lane in range(U(LANES)):
                        x = blk + lane
                        al = abuf[x]
                        at = al * tbuf[x]
                        v0 = vrow0[x]
                        v1 = vrow1[x]
                        v2 = vrow2[x]
                        s0 = srow0[x]
                        s1 = srow1[x]
                        s2 = srow2[x]
                        g0 += at * v0
                        g1 += at * v1
                        g2 += at * v2
                        vabuf[x] += (c0 - s0) * v0 + (c1 - s1) * v1 + (c2 - s2) * v2
                        srow0[x] = al * c0 + (F(1.0) - al) * s0
                        srow1[x] = al * c1 + (F(1.0) - al) * s1
                        srow2[x] = al * c2 + (F(1.0) - al) * s2
                gbuf[e, 6] = g0
                gbuf[e, 7] = g1
                gbuf[e, 8] = g2
            else:
                for d in range(D):
                    cd = pk[k, 6 + d]
                    g_col = F(0.0)
                    for blk in range(U(x0), U(x1 + 1), U(LANES)):
                        for lane in range(U(LANES)):
                            x = blk + lane
                            vc = vrow[d, x]
                            al = abuf[x]
                            g_col += al * tbuf[x] * vc
                            vabuf[x] += (cd - srow[d, x]) * vc
                            srow[d, x] = al * cd + (F(1.0) - al) * srow[d, x]
                    gbuf[e, 6 + d] = g_col
            g_mx = F(0.0)
            g_my = F(0.0)
            g_a = F(0.0)
            g_b = F(0.0)
            g_c = F(0.0)
            g_o = F(0.0)
            for blk in range(U(x0), U(x1 + 1), U(LANES)):
                for lane in range(U(LANES)):
                    x = blk + lane
                    dx = mxg - F(x)
                    gs = gbx[x]
                    va = vabuf[x] * tbuf[x] + varow[x] * ibuf[x]
                    g_o += gs * va
                    vs = -o * gs * va
                    g_a += F(0.5) * dx * dx * vs
                    g_b += dx * dy * vs
                    g_c += F(0.5) * dy * dy * vs
                    g_mx += (a * dx + b * dy) * vs
                    g_my += (b * dx + cz * dy) * vs
            store_geometry_grads(gbuf, e, g_mx, g_my, g_a, g_b, g_c, g_o)

