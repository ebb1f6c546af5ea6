"""Scoring without truth: held-out blurry frames (docs/method.md §6a).

Every K-th frame is left out of training; afterwards each method predicts the held-out blurry
frame and is scored against the real one (PSNR on 8-bit values in the frames' own encoding):

* ``fusiongs``: N sharp renders inside the exposure, averaged in linear light, times the mean gain
  of the kept frames, through the frames' response (the blur model of training);
* ``fusiongs_ratio``: the same renders, each times the exposure-ratio factor ``ρ`` of the previous
  and next kept frames (the detail the deblurred frames add to the renders,
  :mod:`fusiongs.outputs.exposure_ratio`) carried along the fitted motion to that instant; the two
  neighbours' linear predictions are averaged. It scores the deblurred frames' own detail against
  a frame that did not make it: better than ``fusiongs`` only if that detail is the scene's;
* ``nearest``: the kept blurry frame whose mid-exposure is nearest, as it is;
* ``edi_carried``: the previous and next kept frames, EDI-deblurred to their mid-exposures and
  carried with the events to the N instants of the held-out exposure,
  ``L(t) = L(t_ref) exp(theta_+ dN_+ - theta_- dN_-)``, averaged over the exposure in linear light;
  the two neighbours' linear predictions are averaged (one side alone when the other is missing),
  then encoded by the response.

The held-out rule (:func:`holdout_indices`): frame ``i`` (0-based, in time order) is held out when
``i % K == K - 1``, i.e. frames K, 2K, 3K, ... counted from 1, except the last frame; the first
frame (``i = 0``) is never held out since ``K - 1 >= 1``. Held-out frames are therefore never
adjacent (K >= 2) and always lie between two kept frames.

The functions here take arrays; :func:`fusiongs.pipeline.deblur.score_holdout` runs them on a
trained scene.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from fusiongs.edi import edi_ratio
from fusiongs.errors import InputError
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet

METHODS = ("fusiongs", "fusiongs_ratio", "nearest", "edi_carried")
RULE = "frame i (0-based) is held out when i % K == K - 1, except the last frame; the first is always kept"


def parse_holdout(value: object) -> int:
    """``--holdout`` as an int: ``None``, ``0`` or ``"0"`` = off, else an integer ``K >= 2``.

    Raises:
        InputError: (``--holdout``) for anything else (K = 1 would hold out every frame).
    """
    if value is None:
        return 0
    try:
        k = int(str(value).strip()) if not isinstance(value, (int, np.integer)) else int(value)
    except ValueError:
        k = -1
    if isinstance(value, bool) or not (k == 0 or k >= 2):
        raise InputError("--holdout", "K", "0 (off) or an integer >= 2 (every K-th frame is left out)",
                         repr(value) if isinstance(value, str) else value)
    return k


def holdout_indices(n_frames: int, k: int) -> np.ndarray:
    """Indices of the held-out frames: ``i % k == k - 1`` and ``i < n_frames - 1`` (module rule).

    Args:
        n_frames: number of frames ``F`` (in time order).
        k: the period ``K`` (0 = off; otherwise >= 2).

    Returns:
        ``[H]`` int64 sorted indices (empty when ``k == 0`` or too few frames).
    """
    if k == 0:
        return np.zeros(0, np.int64)
    if k < 2:
        raise InputError("--holdout", "K", "0 (off) or an integer >= 2", k)
    i = np.arange(k - 1, max(int(n_frames) - 1, 0), k, dtype=np.int64)
    return i[i > 0]


def frame_subset(frames: FrameSet, indices: Sequence[int] | np.ndarray) -> FrameSet:
    """A new :class:`FrameSet` of the frames at ``indices`` (copies; ``frames`` is not modified)."""
    idx = np.asarray(indices, dtype=np.int64)
    return FrameSet(np.ascontiguousarray(frames.images[idx]), np.asarray(frames.t_start)[idx].copy(),
                    np.asarray(frames.t_end)[idx].copy(), tuple(frames.names[i] for i in idx),
                    frames.response)


def kept_neighbours(kept: Sequence[int] | np.ndarray, i: int) -> tuple[int | None, int | None]:
    """The nearest kept frame index before and after frame ``i`` (``None`` where there is none)."""
    k = np.asarray(kept, dtype=np.int64)
    before, after = k[k < i], k[k > i]
    return (int(before.max()) if before.size else None, int(after.min()) if after.size else None)


def nearest_kept(mid_times: np.ndarray, kept: Sequence[int] | np.ndarray, i: int) -> int:
    """The kept frame whose mid-exposure time (s, ``[F]``) is nearest to frame ``i``'s; a tie goes to
    the earlier frame."""
    k = np.asarray(kept, dtype=np.int64)
    if k.size == 0:
        raise InputError("holdout", "kept frames", "at least one kept frame", "none")
    d = np.abs(np.asarray(mid_times, np.float64)[k] - float(mid_times[i]))
    return int(k[int(np.argmin(d))])  # argmin takes the first (earliest) of equal distances


def event_counts_at(events: EventStream, t_ref: float, times: Sequence[float] | np.ndarray) -> np.ndarray:
    """ON/OFF event counts from ``t_ref`` to each instant: ``N_pm(t_k) - N_pm(t_ref)``.

    ``N(t)`` counts the events with ``t_e < t`` (the half-open convention of
    :func:`fusiongs.edi.event_count_samples`), so the result is negative before ``t_ref``.

    Args:
        events: time-sorted stream (µs clock = seconds x 1e6).
        t_ref: reference instant in seconds (e.g. a neighbour's mid-exposure).
        times: ``[M]`` instants in seconds, before or after ``t_ref``.

    Returns:
        ``[M, 2, H, W]`` int32 signed counts (channel 0 ON, 1 OFF). One pass over the events between
        the earliest and latest instant: a bincount over (instant bin, polarity, pixel) and a
        cumulative sum, as in ``event_count_samples``.
    """
    ts = np.asarray(times, dtype=np.float64).reshape(-1) * 1e6
    ref = float(t_ref) * 1e6
    if not (np.all(np.isfinite(ts)) and math.isfinite(ref)):
        raise InputError("holdout", "times", "finite instants in seconds", (t_ref, ts.tolist()))
    allt = np.append(ts, ref)
    order = np.argsort(allt, kind="stable")
    sorted_t = allt[order]
    n = sorted_t.size
    i0, i1 = events.index_range(int(np.floor(sorted_t[0])), int(np.ceil(sorted_t[-1])) + 1)
    hw = events.height * events.width
    pix = events.y[i0:i1].astype(np.int64) * events.width + events.x[i0:i1]
    pix += (events.p[i0:i1] < 0) * hw
    b = np.searchsorted(sorted_t, events.t[i0:i1], side="right")  # counts for sorted instants >= b
    hist = np.bincount(b * (2 * hw) + pix, minlength=(n + 1) * 2 * hw)
    cum = np.cumsum(hist.reshape(n + 1, 2 * hw)[:n], axis=0)  # N(sorted_t[j]) - N(sorted_t[0]-)
    at = np.empty_like(cum)
    at[order] = cum  # back to the order of ``allt``
    return (at[:-1] - at[-1]).astype(np.int32).reshape(ts.size, 2, events.height, events.width)


def carry_linear(image_linear: np.ndarray, counts: np.ndarray, theta, cfa: str | None) -> np.ndarray:
    """Carry a sharp linear image to other instants with the events between.

    ``L(t_k) = L(t_ref) exp(theta_+ dN_+(t_k) - theta_- dN_-(t_k))`` per pixel; for a CFA sensor each
    raw pixel uses its own channel's thresholds and the ratio map is demosaiced (bilinear) to RGB
    (:func:`fusiongs.edi.edi_ratio`, as EDI does); grey events scale every channel alike.

    Args:
        image_linear: ``[H, W, C]`` linear image at ``t_ref`` (C = 1 or 3; 3 for CFA events).
        counts: ``[M, 2, H, W]`` from :func:`event_counts_at`.
        theta: a threshold, a ``(theta_pos, theta_neg)`` pair or
            :class:`~fusiongs.events.thresholds.SensorThresholds` (log-intensity units).
        cfa: the event sensor's CFA, or None.

    Returns:
        ``[M, H, W, C]`` float64 linear images at the instants.
    """
    img = np.asarray(image_linear, dtype=np.float64)
    c = np.asarray(counts)
    if img.ndim != 3 or c.ndim != 4 or c.shape[1] != 2 or c.shape[2:] != img.shape[:2]:
        raise InputError("holdout", "image/counts", "[H, W, C] and [M, 2, H, W] of one sensor",
                         f"{img.shape} and {c.shape}")
    return np.stack([img * edi_ratio(c[k:k + 1], theta, cfa) for k in range(c.shape[0])])


def carried_counts(events: EventStream, t_ref: float, t_start: float, t_end: float, n: int) -> np.ndarray:
    """Event counts from ``t_ref`` to the N instants of the exposure ``[t_start, t_end]`` (s).

    The instants are :func:`fusiongs.losses.blur.exposure_instants` (midpoint rule), those of the
    training blur model. The counts do not depend on the thresholds: a caller trying several keeps
    them (``benchmarks/bench_holdout_edi_grid.py``).

    Returns:
        ``[N, 2, H, W]`` int32 from :func:`event_counts_at`.
    """
    from fusiongs.losses.blur import exposure_instants

    return event_counts_at(events, t_ref, exposure_instants(float(t_start), float(t_end), n).numpy())


def carried_exposure(image_linear: np.ndarray, events: EventStream, t_ref: float, t_start: float,
                     t_end: float, n: int, theta) -> np.ndarray:
    """Mean linear image over the exposure ``[t_start, t_end]`` (s) carried from ``t_ref``.

    ``mean_k L(t_k) = L(t_ref) mean_k exp(theta dN(t_k))`` over the instants of
    :func:`carried_counts` (a CFA ratio map is demosaiced after the mean: the two commute).

    Returns:
        ``[H, W, C]`` float64 linear prediction of the blurry frame (before the camera response).
    """
    counts = carried_counts(events, t_ref, t_start, t_end, n)
    return np.asarray(image_linear, np.float64) * edi_ratio(counts, theta, events.cfa)


def tenengrad(image: np.ndarray) -> float:
    """No-reference sharpness: mean Sobel gradient energy ``mean(G_x^2 + G_y^2)`` of the luminance.

    Args:
        image: ``[H, W, C]`` (or ``[H, W]``) display values in [0, 1] (sRGB); the luminance is the
            channel mean. 3x3 Sobel, reflected borders.

    Returns:
        the mean energy (unitless). It rises with sharp edges but also with noise: read it beside
        the held-out and truth scores, not alone.
    """
    import cv2

    a = np.asarray(image, dtype=np.float64)
    lum = a.mean(axis=-1) if a.ndim == 3 else a
    gx = cv2.Sobel(lum, cv2.CV_64F, 1, 0, ksize=3)
    gy = cv2.Sobel(lum, cv2.CV_64F, 0, 1, ksize=3)
    return float(np.mean(gx * gx + gy * gy))


def compare_sharpness(methods: Mapping[str, Mapping[str, np.ndarray]], prefix: str = "deblur_") -> dict:
    """Mean :func:`tenengrad` per method over its views named ``prefix*``.

    Returns:
        ``{method: {"tenengrad": mean, "n": views}}`` for the methods with such views.
    """
    out = {}
    for method, imgs in methods.items():
        vals = [tenengrad(v) for k, v in sorted(imgs.items()) if k.startswith(prefix)]
        if vals:
            out[method] = {"tenengrad": float(np.mean(vals)), "n": len(vals)}
    return out


def heldout_summary(frames: Mapping[str, Mapping[str, float | None]]) -> dict:
    """Per method, the mean PSNR over held-out frames (finite values; None when there are none).

    Args:
        frames: ``{frame name: {method: psnr or None, ...}}``.

    Returns:
        ``{method: {"psnr": mean or None, "n": frames scored}}`` for :data:`METHODS`.
    """
    out = {}
    for m in METHODS:
        vals = [float(r[m]) for r in frames.values() if r.get(m) is not None and math.isfinite(float(r[m]))]
        out[m] = {"psnr": float(np.mean(vals)) if vals else None, "n": len(vals)}
    return out


def format_heldout(doc: Mapping) -> str:
    """The held-out table as text: one line per frame, then the means."""

    def cell(v) -> str:
        return f"{v:>15.2f}" if v is not None else f"{'-':>15}"

    lines = [f"held-out frames (K = {doc['holdout']}), PSNR against the real blurry frame:",
             f"{'frame':<12}" + "".join(f"{m:>15}" for m in METHODS)]
    for name, row in doc["frames"].items():
        lines.append(f"{name:<12}" + "".join(cell(row.get(m)) for m in METHODS))
    lines.append(f"{'mean':<12}" + "".join(cell(doc["mean"][m]["psnr"]) for m in METHODS))
    return "\n".join(lines)
