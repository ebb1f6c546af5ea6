"""Numba CPU kernels: per-pixel alpha compositing and its hand-written backward.

Each parallel task is one image row of one camera. Per row, a list of the visible Gaussians whose
pixel box meets the row is built once (front to back, CSR layout); the task splats them over the
row's pixels (only the x-range where the Gaussian's alpha can reach 1/255 is visited, with a small
margin; the exact alpha test decides). The backward pass walks each row's list back to front (the
classic 3DGS backward, Kerbl et al. 2023), recovering each pair's transmittance from the stored
final transmittance and the last contributing entry per pixel. Gradients go to one slot per
(entry, row) and are summed per entry afterwards, so no two threads write the same memory.

Array conventions (``P`` visible entries sorted by camera then depth; ``k`` indexes them):
    ids[P] Gaussian index; box[P, 4] inclusive pixel box (x0, x1, y0, y1);
    mx, my, ca, cb, cc, op: [C, N] centre, conic (a, b, c), opacity; col: [C, N, D].
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

ALPHA_T = 1.0 / 255.0
MAX_A = 0.999
T_STOP = 1e-4


@njit(cache=True, inline="always")
def alpha_limit(o):  # pragma: no cover - numba
    """Bound on the Mahalanobis term ``d^T Σ^-1 d`` where opacity o can still give alpha 1/255,
    with a small margin against rounding."""
    return 2.0 * math.log(o / ALPHA_T) * (1.0 + 1e-6) + 1e-6


@njit(cache=True, inline="always")
def _row_range(k, c, g, y, box, mx, my, ca, cb, cc, op):  # pragma: no cover - numba
    """Inclusive x-range of row ``y`` where entry k may reach alpha 1/255 (x1 < x0 if none)."""
    return row_span(box[k, 0], box[k, 1], mx[c, g], my[c, g], ca[c, g], cb[c, g], cc[c, g], y,
                    alpha_limit(op[c, g]))


@njit(cache=True, inline="always")
def row_span(bx0, bx1, mxg, myg, a, b, cz, y, lim):  # pragma: no cover - numba
    """Inclusive x-range, within the box columns ``[bx0, bx1]``, of the pixels of row ``y`` where a
    Gaussian centred at ``(mxg, myg)`` (px) with conic ``(a, b, cz)`` has ``d^T Σ^-1 d <= lim``
    (x1 < x0 if none); the shared span of the scalar and the SIMD kernels."""
    dy = myg - (y + 0.5)
    disc = (b * dy) ** 2 - a * (cz * dy * dy - lim)
    if disc < 0.0 or a <= 0.0:
        return 0, -1
    s = math.sqrt(disc)
    lo = (-b * dy - s) / a  # dx = mx - (x + 0.5) in [lo, hi]
    hi = (-b * dy + s) / a
    x0 = max(bx0, int(math.ceil(mxg - hi - 0.5)))
    x1 = min(bx1, int(math.floor(mxg - lo - 0.5)))
    return x0, x1


@njit(cache=True, parallel=True)
def row_lists(box, cam_off, height):  # pragma: no cover - numba
    """Per-row lists of entries, front to back: ``(row_off[C*H+1], rows[R], entry_row0[P+1])``.

    ``rows[row_off[c*H+y]:row_off[c*H+y+1]]`` are the entries whose box meets row y of camera c;
    the gradient slot of (entry k, row y) is ``entry_row0[k] + y - box[k, 2]``.
    """
    C = cam_off.shape[0] - 1
    P = box.shape[0]
    heights = np.zeros(P, np.int64)
    for k in prange(P):
        if box[k, 0] <= box[k, 1] and box[k, 2] <= box[k, 3]:
            heights[k] = box[k, 3] - box[k, 2] + 1
    entry_row0 = np.zeros(P + 1, np.int64)
    for k in range(P):
        entry_row0[k + 1] = entry_row0[k] + heights[k]
    counts = np.zeros(C * height + 1, np.int64)
    for c in prange(C):
        for k in range(cam_off[c], cam_off[c + 1]):
            for y in range(box[k, 2], box[k, 2] + heights[k]):
                counts[c * height + y + 1] += 1
    row_off = np.cumsum(counts)
    rows = np.empty(row_off[-1], np.int64)
    for c in prange(C):
        fill = row_off[c * height:(c + 1) * height].copy()
        for k in range(cam_off[c], cam_off[c + 1]):
            for y in range(box[k, 2], box[k, 2] + heights[k]):
                rows[fill[y]] = k
                fill[y] += 1
    return row_off, rows, entry_row0


@njit(cache=True, parallel=True)
def forward(ids, box, row_off, rows, mx, my, ca, cb, cc, op, col, height, width,
            img, tfin, last):  # pragma: no cover - numba
    """Composite front to back into ``img[C,H,W,D]``, ``tfin[C,H,W]``, ``last[C,H,W]`` (entry k)."""
    D = col.shape[2]
    for task in prange(row_off.shape[0] - 1):
        c = task // height
        y = task % height
        done = np.zeros(width, np.bool_)
        for x in range(width):
            tfin[c, y, x] = 1.0
            last[c, y, x] = -1
        py = y + 0.5
        for r in range(row_off[task], row_off[task + 1]):
            k = rows[r]
            g = ids[k]
            x0, x1 = _row_range(k, c, g, y, box, mx, my, ca, cb, cc, op)
            dy = my[c, g] - py
            a = ca[c, g]
            b = cb[c, g]
            cz = cc[c, g]
            o = op[c, g]
            skip = math.log(o / ALPHA_T) * (1.0 + 1e-9) + 1e-12  # beyond: alpha < 1/255 surely
            for x in range(x0, x1 + 1):
                if done[x]:
                    continue
                dx = mx[c, g] - (x + 0.5)
                sigma = 0.5 * (a * dx * dx + cz * dy * dy) + b * dx * dy
                if sigma < 0.0 or sigma > skip:
                    continue
                alpha = min(MAX_A, o * math.exp(-sigma))
                if alpha < ALPHA_T:
                    continue
                t = tfin[c, y, x]
                nt = t * (1.0 - alpha)
                if nt <= T_STOP:
                    done[x] = True
                    continue
                w = alpha * t
                for d in range(D):
                    img[c, y, x, d] += w * col[c, g, d]
                tfin[c, y, x] = nt
                last[c, y, x] = k


@njit(cache=True, inline="always")
def store_geometry_grads(gbuf, e, g_mx, g_my, g_a, g_b, g_c, g_o):  # pragma: no cover - numba
    """Write one (entry, row) slot's mean, conic and opacity gradients (columns 0-5 of gbuf)."""
    gbuf[e, 0] = g_mx
    gbuf[e, 1] = g_my
    gbuf[e, 2] = g_a
    gbuf[e, 3] = g_b
    gbuf[e, 4] = g_c
    gbuf[e, 5] = g_o


@njit(cache=True, parallel=True)
def backward(ids, box, row_off, row_end, rows, entry_row0, mx, my, ca, cb, cc, op, col, height, width,
             tfin, last, v_img, v_alpha, gbuf):  # pragma: no cover - numba
    """Back-to-front gradients per (entry, row) slot into ``gbuf[R, 6 + D]`` (zeros on entry).

    Row ``task`` walks ``rows[row_off[task]:row_end[task]]`` (``row_end`` is ``row_off[1:]``, or
    less where the caller leaves a row's slots at zero: ``fusiongs.render.cpu.row_ends``).
    Columns of gbuf: d/d mean x, mean y, conic a, b, c, opacity, colour[0:D].
    """
    D = col.shape[2]
    for task in prange(row_off.shape[0] - 1):
        c = task // height
        y = task % height
        trow = np.empty(width, np.float64)
        srow = np.zeros((width, D), np.float64)
        gcol = np.zeros(D, np.float64)
        for x in range(width):
            trow[x] = tfin[c, y, x]
        py = y + 0.5
        for r in range(row_end[task] - 1, row_off[task] - 1, -1):
            k = rows[r]
            g = ids[k]
            x0, x1 = _row_range(k, c, g, y, box, mx, my, ca, cb, cc, op)
            dy = my[c, g] - py
            a = ca[c, g]
            b = cb[c, g]
            cz = cc[c, g]
            o = op[c, g]
            e = entry_row0[k] + y - box[k, 2]
            skip = math.log(o / ALPHA_T) * (1.0 + 1e-9) + 1e-12
            g_mx = 0.0
            g_my = 0.0
            g_a = 0.0
            g_b = 0.0
            g_c = 0.0
            g_o = 0.0
            for x in range(x0, x1 + 1):
                if k > last[c, y, x]:
                    continue
                dx = mx[c, g] - (x + 0.5)
                sigma = 0.5 * (a * dx * dx + cz * dy * dy) + b * dx * dy
                if sigma < 0.0 or sigma > skip:
                    continue
                gauss = math.exp(-sigma)
                og = o * gauss
                alpha = min(MAX_A, og)
                if alpha < ALPHA_T:
                    continue
                inv = 1.0 / (1.0 - alpha)
                t = trow[x] * inv
                w = alpha * t
                va = 0.0
                for d in range(D):
                    vc = v_img[c, y, x, d]
                    cgd = col[c, g, d]
                    gcol[d] += w * vc
                    va += (cgd - srow[x, d]) * vc
                    srow[x, d] = alpha * cgd + (1.0 - alpha) * srow[x, d]
                va = va * t + v_alpha[c, y, x] * tfin[c, y, x] * inv
                trow[x] = t
                if og <= MAX_A:
                    vs = -og * va
                    g_o += gauss * va
                    g_a += 0.5 * dx * dx * vs
                    g_b += dx * dy * vs
                    g_c += 0.5 * dy * dy * vs
                    g_mx += (a * dx + b * dy) * vs
                    g_my += (b * dx + cz * dy) * vs
            store_geometry_grads(gbuf, e, g_mx, g_my, g_a, g_b, g_c, g_o)
            for d in range(D):
                gbuf[e, 6 + d] = gcol[d]
                gcol[d] = 0.0


@njit(cache=True, parallel=True)
def reduce_grads(ids, cam_off, entry_row0, gbuf, out):  # pragma: no cover - numba
    """Sum each entry's row slots of ``gbuf`` into ``out[C, N, 6 + D]``."""
    C = cam_off.shape[0] - 1
    for c in range(C):
        for k in prange(cam_off[c], cam_off[c + 1]):
            g = ids[k]
            for e in range(entry_row0[k], entry_row0[k + 1]):
                for j in range(gbuf.shape[1]):
                    out[c, g, j] += gbuf[e, j]
