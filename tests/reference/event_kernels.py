"""Plain numpy forms of the one-pass kernels of :mod:`fusiongs.events._kernels`: whole-stream
index arrays and argsorts, obviously correct and memory-hungry (O(events) temporaries). The
specification the tests compare the kernels against; nothing else calls them."""

from __future__ import annotations

import numpy as np

from fusiongs.events.stream import EventStream


def count_maps(events: EventStream, i0: int = 0, i1: int | None = None,
               weights: np.ndarray | None = None) -> np.ndarray:
    """``[2, H, W]`` ON / OFF counts of the events ``[i0, i1)`` (a bincount; int64, or float64
    sums of ``weights[i0:i1]``)."""
    i1 = len(events) if i1 is None else i1
    hw = events.height * events.width
    idx = events.y[i0:i1].astype(np.int64) * events.width + events.x[i0:i1]
    idx += (events.p[i0:i1] < 0) * hw
    w = None if weights is None else np.asarray(weights[i0:i1], np.float64)
    return np.bincount(idx, w, minlength=2 * hw).reshape(2, events.height, events.width)


def same_pixel_intervals(events: EventStream) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(dt, index, previous)``: the interval of every event after its pixel's previous one (µs),
    the event's index in the stream and that previous event's index, from a stable sort by pixel."""
    pix = events.y.astype(np.int64) * events.width + events.x
    order = np.argsort(pix, kind="stable")  # time order kept within each pixel
    ps, ts = pix[order], events.t[order]
    same = ps[1:] == ps[:-1]
    return (ts[1:] - ts[:-1])[same], order[1:][same], order[:-1][same]


def interval_histogram(events: EventStream, edges: np.ndarray) -> tuple[np.ndarray, int]:
    dt, _, _ = same_pixel_intervals(events)
    return np.histogram(dt, edges)[0], int(dt.size)


def reset_weights(events: EventStream, dead_us: float, cap: float, burst_end: bool = False) -> np.ndarray:
    """``[E]`` float64 ``w = min(dt / (dt - d), cap)`` where the interval ``dt`` to the pixel's
    previous event exceeds ``d``, else 1; with ``burst_end``, plus ``max(0, (w^2 - 1) / (2 w) -
    (w_next - 1))`` with ``w_next`` the pixel's next event's ``w`` (1 for its last event)."""
    w = np.ones(len(events))
    dt, idx, prev = same_pixel_intervals(events)
    dt = dt.astype(np.float64)
    over = dt > dead_us
    w[idx[over]] = np.minimum(dt[over] / (dt[over] - dead_us), cap)
    if not burst_end:
        return w
    w_next = np.ones(len(events))
    w_next[prev] = w[idx]
    return w + np.maximum(0.0, (w * w - 1.0) / (2.0 * w) - (w_next - 1.0))


def fast_event_mask(events: EventStream, gap_us: float) -> np.ndarray:
    fast = np.zeros(len(events), bool)
    dt, idx, _ = same_pixel_intervals(events)
    fast[idx] = dt < gap_us
    return fast


def fast_event_counts(events: EventStream, gap_us: float, edges_us: np.ndarray) -> np.ndarray:
    hw = events.height * events.width
    out = np.zeros((len(edges_us) - 1, hw), np.int32)
    fast = fast_event_mask(events, gap_us)
    pix = (events.y.astype(np.int64) * events.width + events.x)[fast]
    seg = np.searchsorted(edges_us, events.t[fast], side="right") - 1
    ok = (seg >= 0) & (seg < len(edges_us) - 1)
    np.add.at(out, (seg[ok], pix[ok]), 1)
    return out


def exposure_counts(events: EventStream, ts: np.ndarray, mid: float, i0: int, i1: int,
                    weights: np.ndarray | None = None) -> np.ndarray:
    """``[M, 2, H, W]`` counts of :func:`fusiongs.edi.event_count_samples` (int32, or float64
    sums of ``weights[i0:i1]``): a bincount over (sample bin, polarity, pixel), a cumulative sum
    over the bins, less the counts at mid."""
    t = events.t[i0:i1]
    hw, m = events.height * events.width, len(ts)
    pix = events.y[i0:i1].astype(np.int64) * events.width + events.x[i0:i1]
    pix += (events.p[i0:i1] < 0) * hw
    w = None if weights is None else np.asarray(weights[i0:i1], np.float64)
    b = np.searchsorted(ts, t, side="right")  # the event counts for samples k >= b
    hist = np.bincount(b * (2 * hw) + pix, w, minlength=(m + 1) * 2 * hw)
    cum = np.cumsum(hist.reshape(m + 1, 2 * hw)[:m], axis=0)
    at_mid = np.bincount(pix[t < mid], None if w is None else w[t < mid], minlength=2 * hw)
    out = (cum - at_mid).reshape(m, 2, events.height, events.width)
    return out if w is not None else out.astype(np.int32)
