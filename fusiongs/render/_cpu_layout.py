"""The CPU backend's depth order and pixel boxes in one numba pass (no gradients).

The same entries, order and boxes as :func:`fusiongs.render._boxes.sorted_visible` followed by
:func:`fusiongs.render._boxes.pixel_boxes` (the torch reference, which the torch backend uses; the
parity is tested in ``tests/render/test_cpu_layout.py``), without their ~15 tensor operations and
comparison sort: each camera's visible entries are ordered by a stable LSD radix sort of their
depths' bits, one camera per parallel task.

A float's bits, with the sign bit set for positive values and every bit flipped for negative ones,
order like the floats themselves (−0 is first made +0, which the reference treats as equal to it;
NaN depths never reach the sort, since they fail the projection's depth test and are culled). A
stable sort keeps ties in index order, as the reference's stable sort does.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

DIGIT_BITS = 11  # radix digits: 3 passes for float32 depths, 6 for float64 (2048 buckets each)


def depth_keys(depths: np.ndarray) -> tuple[np.ndarray, int]:
    """``([C, N] uint64 keys that sort like ``depths``, their bit width)`` for float32 or float64."""
    d = depths + depths.dtype.type(0.0)  # -0.0 + 0.0 = +0.0
    bits = 8 * d.dtype.itemsize
    u = d.view(np.uint32 if bits == 32 else np.uint64).astype(np.uint64)
    top = np.uint64(1) << np.uint64(bits - 1)
    mask = np.uint64((1 << bits) - 1)
    return np.where((u & top) != 0, ~u & mask, u | top), bits


@njit(cache=True, parallel=True)
def visible_layout(keys, bits, radii, means2d, width, height):  # pragma: no cover - numba
    """Visible entries of each camera, front to back, and their inclusive pixel boxes.

    Args:
        keys: ``[C, N]`` uint64 from :func:`depth_keys`. bits: their width (32 or 64).
        radii: ``[C, N, 2]`` int32, 0 = culled. means2d: ``[C, N, 2]`` pixel centres (float).
        width, height: image size.

    Returns:
        ``(gid [P] int64, box [P, 4] int64 (x0, x1, y0, y1), cam_offsets [C + 1] int64)``.
    """
    C, N = keys.shape
    counts = np.zeros(C, np.int64)
    for c in range(C):
        for g in range(N):
            if radii[c, g, 0] > 0:
                counts[c] += 1
    off = np.zeros(C + 1, np.int64)
    for c in range(C):
        off[c + 1] = off[c] + counts[c]
    gid = np.empty(off[C], np.int64)
    box = np.empty((off[C], 4), np.int64)
    nb = 1 << DIGIT_BITS
    digit_mask = np.uint64(nb - 1)
    for c in prange(C):
        n = counts[c]
        key = np.empty(n, np.uint64)
        idx = np.empty(n, np.int64)
        j = 0
        for g in range(N):  # visible entries in index order
            if radii[c, g, 0] > 0:
                key[j] = keys[c, g]
                idx[j] = g
                j += 1
        key2 = np.empty(n, np.uint64)
        idx2 = np.empty(n, np.int64)
        for shift in range(0, bits, DIGIT_BITS):  # least significant digit first: stable
            s = np.uint64(shift)
            start = np.zeros(nb + 1, np.int64)
            for j in range(n):
                start[((key[j] >> s) & digit_mask) + 1] += 1
            for b in range(nb):
                start[b + 1] += start[b]
            for j in range(n):
                d = (key[j] >> s) & digit_mask
                p = start[d]
                start[d] = p + 1
                key2[p] = key[j]
                idx2[p] = idx[j]
            key, key2 = key2, key
            idx, idx2 = idx2, idx
        for j in range(n):
            g = idx[j]
            k = off[c] + j
            gid[k] = g
            mx, my = np.float64(means2d[c, g, 0]), np.float64(means2d[c, g, 1])
            rx, ry = np.float64(radii[c, g, 0]), np.float64(radii[c, g, 1])
            box[k, 0] = np.int64(min(max(np.ceil(mx - rx - 0.5), 0.0), np.float64(width)))
            box[k, 1] = np.int64(min(max(np.floor(mx + rx - 0.5), -1.0), np.float64(width - 1)))
            box[k, 2] = np.int64(min(max(np.ceil(my - ry - 0.5), 0.0), np.float64(height)))
            box[k, 3] = np.int64(min(max(np.floor(my + ry - 0.5), -1.0), np.float64(height - 1)))
    return gid, box, off
