"""Pooling per-channel threshold estimates of one CFA sensor (:mod:`fusiongs.eval.calibrate`).

The pixel circuits behind a Bayer filter are the same, so the channels' thresholds differ little;
each channel's estimate is combined with the others' by its precision under that prior, after a
channel that disagrees with a consensus of the others has its uncertainty widened to the gap.
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
    """``std [C]`` with the uncertainty of a channel that disagrees with all the others widened.

    The bootstrap std of a channel's fit measures its noise, not its bias: a dim channel (blue
    behind a Bayer filter in a dark scene) fitted on few pixel pairs can come out far from the
    others with a small std. With three or more channels, channel ``c`` is discrepant when the
    others agree with each other (every pair within ``k`` combined standard deviations, the prior
    ``prior`` included) and ``c``'s log estimate lies more than ``k`` standard deviations
    (its own, the others' mean's and the prior's) from their precision-weighted mean ``m``; its
    relative std becomes ``sqrt(rel_c^2 + (log theta_c - m)^2)``, so :func:`shrink_channels` then
    draws it to the others. Fewer than three channels, or ``k`` <= 0: ``std`` unchanged.
    """
    theta, std = np.asarray(theta, np.float64), np.asarray(std, np.float64)
    n = theta.size
    if n < 3 or k <= 0:
        return std
    rel = np.where(np.isfinite(std) & (std > 0), std / theta, np.inf)
    lt = np.log(theta)
    out = std.copy()
    for c in range(n):
        o = np.flatnonzero(np.arange(n) != c)
        if not np.all(np.isfinite(rel[o])) or not np.isfinite(rel[c]):
            continue
        gap = np.abs(lt[o, None] - lt[None, o])
        if np.any(gap > k * np.sqrt(rel[o, None] ** 2 + rel[None, o] ** 2 + prior**2)):
            continue  # the others disagree among themselves: no consensus to measure c against
        w = 1.0 / rel[o] ** 2
        d = lt[c] - float(np.sum(w * lt[o]) / np.sum(w))
        if abs(d) > k * np.sqrt(rel[c] ** 2 + 1.0 / np.sum(w) + prior**2):
            out[c] = theta[c] * np.sqrt(rel[c] ** 2 + d**2)
    return out
