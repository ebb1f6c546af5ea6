"""One-pass numba kernels over an event stream's arrays: memory O(pixels), never O(events).

A 1e8-event stream holds 1.3 GB of arrays; the numpy forms these replace built int64 pixel
indices and argsorts of the whole stream (0.8 GB each, 7.6 GB peak in ``fusiongs calibrate``).
Each kernel walks the events once in time order, keeping per-pixel state (the time of the pixel's
previous event). The numpy forms stay in ``tests/reference/event_kernels.py`` as the specification,
and tests compare the two on random streams.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _slot(x, y, p, width, hw):  # pragma: no cover - numba
    """The event's slot in a ``[2 * hw]`` count layout: ``y W + x``, plus ``hw`` for OFF."""
    k = np.int64(y) * width + np.int64(x)
    return k + hw if p < 0 else k


@njit(cache=True)
def count_events(x, y, p, w, width, hw, out):  # pragma: no cover - numba
    """Add every event to ``out`` ``[2 * hw]`` (ON at ``y W + x``, OFF at ``hw + y W + x``): ``w[i]``
    (``w`` of the events' length) or ``w[0]`` (``w`` of length 1)."""
    each = w.shape[0] == x.shape[0]
    for i in range(x.shape[0]):
        out[_slot(x[i], y[i], p[i], width, hw)] += w[i] if each else w[0]


@njit(cache=True)
def interval_histogram(t, x, y, width, hw, edges):  # pragma: no cover - numba
    """Histogram of the intervals between consecutive events of the same pixel.

    Returns ``(counts [len(edges) - 1] int64, intervals int64)``: the bins of ``np.histogram``
    (half-open, the last one closed) and the number of intervals (inside the bins or not).
    """
    nb = edges.shape[0] - 1
    hist = np.zeros(nb, np.int64)
    last = np.zeros(hw, np.int64)
    seen = np.zeros(hw, np.bool_)
    n = 0
    for i in range(t.shape[0]):
        k = np.int64(y[i]) * width + np.int64(x[i])
        if seen[k]:
            dt = t[i] - last[k]
            n += 1
            b = np.searchsorted(edges, dt, side="right") - 1
            if b == nb and dt == edges[nb]:
                b = nb - 1
            if 0 <= b < nb:
                hist[b] += 1
        last[k] = t[i]
        seen[k] = True
    return hist, n


@njit(cache=True)
def fast_mask(t, x, y, width, hw, gap, out):  # pragma: no cover - numba
    """``out[i]`` = event ``i`` follows its pixel's previous event by less than ``gap`` µs."""
    last = np.zeros(hw, np.int64)
    seen = np.zeros(hw, np.bool_)
    for i in range(t.shape[0]):
        k = np.int64(y[i]) * width + np.int64(x[i])
        out[i] = seen[k] and (t[i] - last[k]) < gap
        last[k] = t[i]
        seen[k] = True


@njit(cache=True)
def reset_weights(t, x, y, width, hw, dead, cap, burst_end, out):  # pragma: no cover - numba
    """``out[i]`` = ``w_i = min(dt / (dt - dead), cap)`` for event ``i`` ``dt`` µs after its pixel's
    previous event with ``dt > dead``; left as it is (1) otherwise. With ``burst_end`` a second pass
    (backwards in time) adds ``max(0, (w_i^2 - 1) / (2 w_i) - (w_next - 1))``, ``w_next`` the first
    pass's weight of the pixel's next event (1 when there is none)."""
    last = np.zeros(hw, np.int64)
    seen = np.zeros(hw, np.bool_)
    for i in range(t.shape[0]):
        k = np.int64(y[i]) * width + np.int64(x[i])
        if seen[k]:
            dt = float(t[i] - last[k])
            if dt > dead:
                out[i] = min(dt / (dt - dead), cap)
        last[k] = t[i]
        seen[k] = True
    if not burst_end:
        return
    nxt = np.ones(hw, np.float64)
    for i in range(t.shape[0] - 1, -1, -1):
        k = np.int64(y[i]) * width + np.int64(x[i])
        w = float(out[i])
        extra = (w * w - 1.0) / (2.0 * w) - (nxt[k] - 1.0)
        nxt[k] = w
        if extra > 0.0:
            out[i] = w + extra


@njit(cache=True)
def fast_counts(t, x, y, width, hw, gap, edges, out):  # pragma: no cover - numba
    """Add each fast event (as :func:`fast_mask`) to ``out[j, pixel]`` of its segment
    ``edges[j] <= t < edges[j + 1]`` (``out`` ``[len(edges) - 1, hw]``; outside: not counted)."""
    last = np.zeros(hw, np.int64)
    seen = np.zeros(hw, np.bool_)
    ns = edges.shape[0] - 1
    j = -1  # segment of the current event: edges[j] <= t < edges[j + 1]
    for i in range(t.shape[0]):
        k = np.int64(y[i]) * width + np.int64(x[i])
        while j < ns and t[i] >= edges[j + 1]:
            j += 1
        if seen[k] and (t[i] - last[k]) < gap and 0 <= j < ns:
            out[j, k] += 1
        last[k] = t[i]
        seen[k] = True


@njit(cache=True)
def exposure_counts(t, x, y, p, w, width, hw, ts, t_mid, out):  # pragma: no cover - numba
    """``out[k, q]`` ``[M, 2 * hw]`` (zeroed) becomes the count of events of slot ``q`` (ON at the
    pixel, OFF at ``hw`` + pixel) in ``[t_mid, ts[k])``, negative for ``ts[k] < t_mid``: the
    events of the window, each counted where ``ts[k] > t``, less those before ``t_mid``. Each
    event adds ``w[i]`` (``w`` of the window's length) or ``w[0]`` (``w`` of length 1)."""
    m = ts.shape[0]
    at_mid = np.zeros(out.shape[1], out.dtype)
    each = w.shape[0] == t.shape[0]
    for i in range(t.shape[0]):
        k = _slot(x[i], y[i], p[i], width, hw)
        wi = w[i] if each else w[0]
        b = np.searchsorted(ts, t[i], side="right")  # the event counts for samples >= b
        if b < m:
            out[b, k] += wi
        if t[i] < t_mid:
            at_mid[k] += wi
    for b in range(1, m):
        out[b] += out[b - 1]
    for b in range(m):
        out[b] -= at_mid


@njit(cache=True)
def flat_index(x, y, p, width, hw, out):  # pragma: no cover - numba
    """``out[i]`` = ``y W + x`` of event ``i``, plus ``hw`` for an OFF event (``out`` int32)."""
    for i in range(x.shape[0]):
        out[i] = _slot(x[i], y[i], p[i], width, hw)
