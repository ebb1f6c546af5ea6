"""Pooling per-channel threshold estimates of one CFA sensor (:mod:`fusiongs.calibrate.estimate`).

The pixel circuits behind a Bayer filter are the same, so the channels' thresholds differ little;
each channel's estimate is combined with the others' by its precision under that prior, after a
channel far from the channels' median has its uncertainty widened to the gap.
"""

from __future__ import annotations

import numpy as np


def shrink_channels(theta: np.ndarray, std: np.ndarray, prior: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel thresholds ``[C]`` pulled toward their precision-weighted common value.

    Each channel's log estimate (relative variance ``(std / theta)^2``) is combined with the
    inverse-variance-weighted mean of all channels under a prior that the channels of one sensor
    differ by about ``prior`` (relative std): the posterior mean of a normal model. A channel
    measured on few usable pixels (a dim blue channel behind a Bayer filter) then borrows from the
    others instead of standing alone; well-measured channels keep their own value. The pixel
    circuits behind the filters are the same, so large differences between channels are unlikely.
    A channel without an uncertainty takes the common value.

    Returns:
        ``(theta [C], std [C])`` after pooling (the std from the posterior variance).
    """
    theta, std = np.asarray(theta, np.float64), np.asarray(std, np.float64)
    rel = np.where(np.isfinite(std) & (std > 0), std / theta, np.inf)
    w = 1.0 / rel**2
    lt = np.log(theta)
    common = float(np.sum(w * lt) / np.sum(w)) if np.sum(w) > 0 else float(lt.mean())
    post_w = w + 1.0 / prior**2
    out = np.exp((w * lt + common / prior**2) / post_w)
    return out, out / np.sqrt(post_w)


def discrepant_channels(theta: np.ndarray, std: np.ndarray, prior: float, k: float) -> np.ndarray:
    """``std [C]`` with the uncertainty of every channel far from the channels' median widened.

    The bootstrap std of a channel's fit measures its noise, not its bias: a dim channel (blue
    behind a Bayer filter in a dark scene) fitted on few pixel pairs can come out far from the
    others with a small std, and in dark scenes with long dead times every channel's fit can be
    off in its own direction (tuning seeds 211, 288, 416: one channel +27 to +70 %, another -53 %,
    each with a few percent of bootstrap std). With three or
    more channels the median of their log estimates is the reference, as it stands whatever one
    channel does; channel ``c`` is discrepant when its log estimate lies more than ``k`` standard
    deviations (its own and the prior ``prior``, combined) from it. Its relative std
    becomes ``sqrt(rel_c^2 + (log theta_c - median)^2)``, so :func:`shrink_channels` then draws it
    toward the others. Only channels with a finite std (a fit that did not fail) make the median;
    fewer than three of them, or ``k`` <= 0: ``std`` unchanged.
    """
    theta, std = np.asarray(theta, np.float64), np.asarray(std, np.float64)
    n = theta.size
    rel = np.where(np.isfinite(std) & (std > 0), std / theta, np.inf)
    usable = np.isfinite(rel)
    if usable.sum() < 3 or k <= 0:
        return std
    lt = np.log(theta)
    med = float(np.median(lt[usable]))
    out = std.copy()
    for c in range(n):
        d = lt[c] - med
        if np.isfinite(rel[c]) and abs(d) > k * np.sqrt(rel[c] ** 2 + prior**2):
            out[c] = theta[c] * np.sqrt(rel[c] ** 2 + d**2)
    return out
