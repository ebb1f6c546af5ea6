"""Summary statistics and sanity warnings of an event stream (``fusiongs inspect``): counts, time gaps,
hot pixels, fast events (the sensor statistics of the calibration are in :mod:`fusiongs.events.dead_time`)."""

from __future__ import annotations

import numpy as np

from fusiongs.events.stream import EventStream


def time_gaps(t: np.ndarray, factor: float = 10.0,
              min_gap_us: int = 50_000) -> tuple[np.ndarray, np.ndarray, int]:
    """Find silent stretches in a sorted stream.

    A gap is an inter-event interval longer than ``max(factor * median interval, min_gap_us)``:
    the relative test adapts to sparse streams, the absolute floor keeps busy streams (median
    ~1 µs) from reporting every ordinary 10 µs pause.

    Args:
        t: ``[E]`` int64 sorted timestamps in µs.

    Returns:
        ``(start_us, length_us, threshold_us)``: ``[G]`` gap starts and lengths, and the threshold.
    """
    if t.size < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), int(min_gap_us)
    thr = int(max(factor * _median_interval(t), min_gap_us))
    starts, lengths = [], []
    for a in range(0, t.size - 1, CHUNK):  # in chunks: no [E] temporaries (1e8 events: 0.8 GB each)
        dt = np.diff(t[a:a + CHUNK + 1])
        i = np.flatnonzero(dt > thr)
        starts.append(t[a + i])
        lengths.append(dt[i])
    return np.concatenate(starts), np.concatenate(lengths), thr


CHUNK = 1 << 22


def _median_interval(t: np.ndarray, cap: int = 1 << 16) -> float:
    """``np.median(np.diff(t))`` of sorted int64 ``t`` from a histogram of the intervals (exact
    while the median is below ``cap`` µs; a sparser stream is small enough to diff whole)."""
    n = t.size - 1
    hist = np.zeros(cap + 1, np.int64)
    for a in range(0, n, CHUNK):
        hist += np.bincount(np.minimum(np.diff(t[a:a + CHUNK + 1]), cap), minlength=cap + 1)
    cum = np.cumsum(hist)
    lo = int(np.searchsorted(cum, (n - 1) // 2, side="right"))  # the two middle order statistics
    hi = int(np.searchsorted(cum, n // 2, side="right"))
    if hi >= cap:
        return float(np.median(np.diff(t)))
    return 0.5 * (lo + hi)


def fast_event_mask(events: EventStream, gap_us: float) -> np.ndarray:
    """``[E]`` bool, in stream order: the event follows the previous event of the same pixel by
    less than ``gap_us`` µs (either polarity). With a refractory period, such events mark pixels
    whose log intensity changed faster than the sensor could report: their counts are lower bounds.
    """
    from fusiongs.events._kernels import fast_mask

    fast = np.zeros(len(events), bool)
    if gap_us <= 0 or len(events) < 2:
        return fast
    fast_mask(events.t, events.x, events.y, events.width, events.height * events.width,
              float(gap_us), fast)
    return fast


def hot_pixels(counts: np.ndarray, factor: float = 20.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Pixels firing far more than a typical active pixel.

    Args:
        counts: ``[H, W]`` events per pixel.
        factor: a pixel is hot when its count exceeds ``factor`` times the median count of the
            active (non-zero) pixels.

    Returns:
        ``(yx, n, median)``: ``[K, 2]`` row/column of hot pixels sorted by count (highest first),
        ``[K]`` their counts, and the median active count.
    """
    active = counts[counts > 0]
    if active.size == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64), 0.0
    med = float(np.median(active))
    ys, xs = np.nonzero(counts > factor * med)
    n = counts[ys, xs]
    order = np.argsort(-n, kind="stable")
    return np.stack([ys, xs], 1)[order], n[order], med


def frames_outside_events(t_start: np.ndarray, t_end: np.ndarray, t_first: int, t_last: int) -> np.ndarray:
    """Indices of frames whose exposure ``[t_start, t_end]`` (µs) is not covered by the events."""
    t_start, t_end = np.asarray(t_start), np.asarray(t_end)
    return np.flatnonzero((t_start < t_first) | (t_end > t_last))


def summarize(stream: EventStream) -> dict:
    """Plain-number summary: count, first/last time (s), duration (s), rate (ev/s), ON fraction,
    resolution and CFA."""
    n = len(stream)
    return {"events": n, "width": stream.width, "height": stream.height, "cfa": stream.cfa,
            "t_first_s": float(stream.t[0]) * 1e-6 if n else None,
            "t_last_s": float(stream.t[-1]) * 1e-6 if n else None,
            "duration_s": stream.duration_us * 1e-6, "rate_ev_per_s": stream.rate,
            "on_fraction": stream.polarity_balance if n else None}


def stream_warnings(stream: EventStream, *, gap_factor: float = 10.0, gap_min_us: int = 50_000,
                    hot_factor: float = 20.0, max_listed: int = 5) -> list[str]:
    """Human-readable warnings about time gaps and hot pixels (empty list when all looks fine)."""
    out = []
    start, length, thr = time_gaps(stream.t, gap_factor, gap_min_us)
    if start.size:
        top = np.argsort(-length, kind="stable")[:max_listed]
        listed = ", ".join(f"{length[i] / 1e3:.1f} ms at {start[i] * 1e-6:.6f} s" for i in top)
        out.append(f"{start.size} time gap(s) longer than {thr / 1e3:.3g} ms: {listed}")
    yx, n, med = hot_pixels(stream.pixel_counts(), hot_factor)
    if n.size:
        listed = ", ".join(f"(x={x}, y={y}): {c}" for (y, x), c in zip(yx[:max_listed].tolist(),
                                                                          n[:max_listed].tolist()))
        out.append(f"{n.size} hot pixel(s) with more than {hot_factor:g}x the median active-pixel "
                   f"count ({med:g}): {listed}")
    return out
