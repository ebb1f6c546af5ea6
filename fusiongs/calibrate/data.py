"""The data of the threshold calibration (:mod:`fusiongs.calibrate.estimate`): what each event pixel sees
in the frames, the event counts between and inside exposures (plain or weighted), the refractory
gate, and one channel's :class:`~fusiongs.calibrate.fit.PairData`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from fusiongs.calibrate.fit import PairData
from fusiongs.edi import event_count_samples
from fusiongs.errors import InputError
from fusiongs.events.cfa import cfa_channel_index
from fusiongs.events.dead_time import fast_in_spans
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet

if TYPE_CHECKING:
    from fusiongs.calibrate.options import CalibrateOptions

REC601 = (0.299, 0.587, 0.114)


def sensor_intensity(linear: np.ndarray, cfa: str | None) -> np.ndarray:
    """``[F, H*W]`` float64 linear intensity each event pixel sees, from ``[F, H, W, C]`` frames.

    Grey sensors see the Rec.601 luminance of RGB frames (the frame itself when C = 1); colour
    sensors see their own CFA channel of an RGB frame.
    """
    f, h, w, c = linear.shape
    lin = linear.astype(np.float64, copy=False)
    if cfa is None:
        s = lin[..., 0] if c == 1 else lin @ np.asarray(REC601)
    else:
        if c != 3:
            raise InputError("calibrate", "frames", "RGB frames for a colour (CFA) event sensor",
                             f"{c} channel(s)")
        ch = cfa_channel_index(cfa, h, w).astype(np.int64)
        s = np.take_along_axis(lin, np.broadcast_to(ch[None, ..., None], (f, h, w, 1)), axis=-1)[..., 0]
    return s.reshape(f, h * w)


def pixel_channels(events: EventStream) -> np.ndarray:
    """``[H*W]`` int64 channel of every pixel (0 for a grey sensor, 0/1/2 = R/G/B for a CFA)."""
    if events.cfa is None:
        return np.zeros(events.height * events.width, np.int64)
    return cfa_channel_index(events.cfa, events.height, events.width).astype(np.int64).reshape(-1)


def neighbour_counts(between: np.ndarray, height: int, width: int, step: int) -> np.ndarray:
    """``[F-1, 2, H*W]`` median of the four same-channel neighbours' counts (``step`` pixels away:
    1 on a grey sensor, 2 on a CFA), edges replicated: the instruments of
    :func:`~fusiongs.calibrate.fit.iv_thresholds`."""
    q = between.shape[0]
    m = between.reshape(q, 2, height, width).astype(np.float32)
    pad = np.pad(m, ((0, 0), (0, 0), (step, step), (step, step)), mode="edge")
    h, w = height, width
    nb = np.stack([pad[..., 0:h, step:step + w], pad[..., 2 * step:2 * step + h, step:step + w],
                   pad[..., step:step + h, 0:w], pad[..., step:step + h, 2 * step:2 * step + w]])
    return np.median(nb, axis=0).reshape(q, 2, h * w)


def tile_ids(pix: np.ndarray, width: int, tile: int) -> np.ndarray:
    """``[P]`` int64 index of the ``tile`` x ``tile`` pixel square holding each flat pixel index."""
    tiles_x = (width + tile - 1) // tile
    return (pix // width // tile) * tiles_x + (pix % width) // tile


def frame_pairs(n_frames: int, max_gap: int) -> np.ndarray:
    """``[Q, 2]`` int64 pairs ``(i, j)`` with ``1 <= j - i <= max_gap`` (all baselines up to it)."""
    return np.array([(i, i + k) for k in range(1, max_gap + 1) for i in range(n_frames - k)],
                    dtype=np.int64).reshape(-1, 2)


def pair_sums(per_gap: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """``[Q, ...]`` sums over the consecutive mid-exposure gaps each frame pair spans, from
    ``[F-1, ...]`` per-gap values (a cumulative sum; the result keeps ``per_gap``'s dtype kind)."""
    cum = np.concatenate([np.zeros((1, *per_gap.shape[1:]), per_gap.dtype), np.cumsum(per_gap, axis=0)])
    return cum[pairs[:, 1]] - cum[pairs[:, 0]]


def active_pairs(n: np.ndarray, dn: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """``[Q, P]`` bool: the pixel fired between the pair's mid-exposures or inside either exposure
    (``n``: ``[F, M, 2, P]`` counts inside the exposures; ``dn``: ``[Q, 2, P]`` between)."""
    moved = np.abs(n).sum((1, 2))  # [F, P] events inside each exposure
    return (dn.sum(1) + moved[pairs[:, 0]] + moved[pairs[:, 1]]) > 0


def prepare_channel(sens: np.ndarray, counts: list[np.ndarray], between: np.ndarray, pix: np.ndarray,
                    bad_pair: np.ndarray, frame_ok: np.ndarray, width: int, tile: int,
                    max_gap: int = 1,
                    neighbours: np.ndarray | None = None) -> PairData:
    """:class:`PairData` of the pixels ``pix`` (flat indices).

    Args:
        sens: ``[F, H*W]`` linear sensor intensity. counts: F arrays ``[M, 2, H*W]``.
        between: ``[F-1, 2, H*W]`` counts between consecutive mid-exposures. pix: ``[P]`` pixels.
        bad_pair: ``[F-1, H*W]`` bool, pixel excluded from a consecutive pair (refractory gate);
            a longer pair is excluded when any consecutive pair it spans is.
        frame_ok: ``[F, H*W]`` bool, intensity neither saturated nor near black.
        width: sensor width (tiles). tile: tile side in pixels.
        max_gap: longest baseline ``j - i`` of the compared frame pairs.
        neighbours: ``[F-1, 2, H*W]`` instrument counts between consecutive mid-exposures
            (:func:`neighbour_counts`); ``between`` itself when None.
    """
    f = sens.shape[0]
    neighbours = between if neighbours is None else neighbours
    log_s = np.log(np.maximum(sens[:, pix], 1e-12))
    n = np.stack([c[..., pix] for c in counts]).astype(np.float32)
    pairs = frame_pairs(f, max_gap)
    dn = pair_sums(between[..., pix].astype(np.float32), pairs)  # [Q, 2, P]
    bad = pair_sums(bad_pair[:, pix].astype(np.int32), pairs) > 0
    valid = (frame_ok[pairs[:, 0]][:, pix] & frame_ok[pairs[:, 1]][:, pix] & ~bad
             & active_pairs(n, dn, pairs))
    uniq, tid = np.unique(tile_ids(pix, width, tile), return_inverse=True)
    z = pair_sums(neighbours[..., pix].astype(np.float32), pairs)
    return PairData(torch.as_tensor(log_s, dtype=torch.float32), torch.as_tensor(n),
                    torch.as_tensor(pairs), torch.as_tensor(dn), torch.as_tensor(valid),
                    torch.as_tensor(tid.astype(np.int64)), int(uniq.size),
                    torch.as_tensor(z))


def refractory_mask(fast: np.ndarray, height: int, width: int, radius: int, own: bool) -> np.ndarray:
    """``[F-1, H*W]`` bool pixel pairs left out by the refractory gate, from ``fast`` (``[F-1, H*W]``:
    the pixel has two events closer than the gap inside the pair): any pixel within ``radius``
    (a square) is fast, the pixel itself counted only when ``own``."""
    from scipy.ndimage import maximum_filter

    if radius <= 0:
        return fast.copy() if own else np.zeros_like(fast)
    foot = np.ones((1, 2 * radius + 1, 2 * radius + 1), bool)
    foot[0, radius, radius] = own
    return maximum_filter(fast.reshape(-1, height, width), footprint=foot,
                          mode="nearest").reshape(fast.shape)


def count_inputs(frames: FrameSet, events: EventStream, opts: CalibrateOptions,
                  weights: np.ndarray | None) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The counts a fit needs, summed over ``weights`` when given: per frame ``[M, 2, H*W]`` from
    mid-exposure to each EDI sample, ``[F-1, 2, H*W]`` between consecutive mid-exposures, and the
    latter's same-channel neighbour medians (the instruments)."""
    ts, te = np.asarray(frames.t_start, np.float64), np.asarray(frames.t_end, np.float64)
    mids = 0.5 * (ts + te)
    counts = [compact_counts(event_count_samples(events, float(a), float(b), opts.n_samples, weights)
                       .reshape(opts.n_samples, 2, -1)) for a, b in zip(ts, te)]
    between = np.stack([events.count_maps(int(round(mids[i] * 1e6)), int(round(mids[i + 1] * 1e6)),
                                          weights).reshape(2, -1) for i in range(len(frames) - 1)])
    neigh = neighbour_counts(between, events.height, events.width, 1 if events.cfa is None else 2)
    return counts, between, neigh


def gate_inputs(frames: FrameSet, events: EventStream, opts: CalibrateOptions, dead: float
                 ) -> tuple[float, np.ndarray, np.ndarray]:
    """The refractory gate at ``opts.refractory_gate`` dead times (µs): ``(gap, fast, bad_pair)``,
    both ``[F-1, H*W]`` bool (the pixel's own fast events; the pairs the gate leaves out)."""
    ts, te = np.asarray(frames.t_start, np.float64), np.asarray(frames.t_end, np.float64)
    gap = opts.refractory_gate * dead
    spans = np.stack([np.floor(ts[:-1] * 1e6), np.ceil(te[1:] * 1e6)], 1).astype(np.int64)
    fast = fast_in_spans(events, gap, spans)
    bad_pair = refractory_mask(fast, events.height, events.width, opts.refractory_radius,
                               opts.refractory_self)
    return gap, fast, bad_pair


def channel_pixels(sens: np.ndarray, sat: np.ndarray, between: np.ndarray, chan: np.ndarray,
                    hot: np.ndarray, c: int, name: str, opts: CalibrateOptions,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Channel ``c``'s usable pixels (not hot, some events between the frames, lit and unsaturated
    in a frame; at most ``opts.max_pixels``, a seeded subset) and the ``[F, H*W]`` frame mask."""
    sel = np.flatnonzero((chan == c) & ~hot)
    ref = np.quantile(sens[:, sel], 0.99) if sel.size else 1.0
    frame_ok = (sens > opts.dark * ref) & ~sat
    sel = sel[(between[:, :, sel].sum((0, 1)) > 0) & frame_ok[:, sel].any(0)]
    if sel.size < opts.min_pixels:
        raise InputError("calibrate", "events", f"events on at least {opts.min_pixels} usable "
                         f"pixels of channel {name} between the frames", f"{sel.size} pixel(s)")
    if sel.size > opts.max_pixels:
        sel = np.sort(rng.choice(sel, opts.max_pixels, replace=False))
    return sel, frame_ok


def saturated(lin: np.ndarray, opts: CalibrateOptions) -> np.ndarray:
    return np.asarray(lin.max(axis=-1)).reshape(lin.shape[0], -1) >= opts.saturation


def compact_counts(counts: np.ndarray) -> np.ndarray:
    """int16 when every count fits (half the memory of a 1280x720 sensor's [M, 2, H*W] counts);
    weighted (float) counts stay as they are."""
    if counts.dtype.kind == "f":
        return counts
    if counts.size and int(np.abs(counts).max()) < np.iinfo(np.int16).max:
        return counts.astype(np.int16)
    return counts
