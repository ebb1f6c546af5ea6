"""Focal length of a pycolmap reconstruction by a profile of bundle adjustments.

Hand-held recordings are shallow and rotation-dominant: the focal length is often barely
constrained, and a bundle adjustment that frees it from the start wanders (on an 8-frame cut of a
real desk recording it returned 5.6, 49 and 973 px for a 346-pixel-wide sensor depending on the
seed). So the model is built with the focal length held at a guess, then re-adjusted with it held
at each value of a grid around the guess (factors ``2^(k/2)``); the RMS reprojection residual along
the grid says where the focal length lies and whether the data constrain it at all:

* the best grid value is refined by a parabola in ``log f`` through it and its two neighbours, then
  by one bundle adjustment with the focal length free, starting there (kept when it stays within
  half a grid step);
* the focal length counts as observable when the error rises by ``min_rise`` (relative) at half and
  at twice the best value (a bundle adjustment that diverges, or that folds points behind the
  cameras where the reprojection cost vanishes, counts as a rise); otherwise the
  guess is kept, since any value in the flat valley explains the images equally well.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MAX_BEHIND = 0.01  # share of observations behind their camera above which a solve has failed


@dataclass(frozen=True)
class FocalProfile:
    """Result of :func:`profile_focal`.

    Attributes:
        focal: the focal length to use (pixels).
        observable: whether the data constrain it (else ``focal`` is the guess).
        grid: ``[(focal px, RMS reprojection residual px)]`` along the grid (``inf``: the bundle
            adjustment failed).
    """

    focal: float
    observable: bool
    grid: tuple[tuple[float, float], ...]


def _set_focal(rec, f: float) -> None:
    cam = next(iter(rec.cameras.values()))
    p = np.asarray(cam.params, np.float64).copy()
    p[list(cam.focal_length_idxs())] = f
    cam.params = p


def _focal(rec) -> float:
    return float(next(iter(rec.cameras.values())).mean_focal_length())


def _adjust(pycolmap, rec, f: float | None, threads: int):
    """A copy of ``rec`` bundle-adjusted with the focal length held at ``f`` (free when None);
    returns ``(copy, RMS reprojection residual in pixels)`` (``inf`` when the solve failed)."""
    r = pycolmap.Reconstruction(rec)
    if f is not None:
        _set_focal(r, f)
    opts = pycolmap.BundleAdjustmentOptions()
    opts.refine_focal_length = f is None
    opts.refine_principal_point = False
    opts.refine_extra_params = False
    opts.print_summary = False
    opts.ceres.solver_options.num_threads = threads
    config = pycolmap.BundleAdjustmentConfig()
    for image_id in r.reg_image_ids():
        config.add_image(image_id)
    config.fix_gauge(pycolmap.BundleAdjustmentGauge.TWO_CAMS_FROM_WORLD)
    summary = pycolmap.create_default_bundle_adjuster(opts, config, r).solve()
    n = max(int(summary.num_residuals), 1)
    rms = math.sqrt(2.0 * float(summary.ceres_summary.final_cost) / n)
    failed = summary.termination_type == pycolmap.BundleAdjustmentTerminationType.FAILURE
    ok = (not failed and math.isfinite(rms) and rms < 1e3 and _focal(r) > 0
          and _behind_share(r) <= MAX_BEHIND)
    return r, (rms if ok else math.inf)


def _behind_share(rec) -> float:
    """Share of the observations whose point lies behind (or on) the observing camera. A bundle
    adjustment held at a far too short focal length can fold the scene behind the cameras, where
    the reprojection cost vanishes: such a solve is a failure, not a perfect fit."""
    w2c = {i: np.asarray(im.cam_from_world().matrix()) for i, im in rec.images.items() if im.has_pose}
    behind = total = 0
    for p in rec.points3D.values():
        x = np.append(np.asarray(p.xyz, np.float64), 1.0)
        for el in p.track.elements:
            m = w2c.get(el.image_id)
            if m is not None:
                total += 1
                behind += float(m[2] @ x) <= 0
    return behind / total if total else 1.0


def profile_focal(rec, guess: float, *, octaves: float = 2.0, steps_per_octave: int = 2,
                  min_rise: float = 0.01, threads: int = 1):
    """Profile the reprojection error over focal lengths ``guess x 2^(k / steps_per_octave)`` for
    ``|k| <= octaves x steps_per_octave`` and return the adjusted model with its focal length.

    Args:
        rec: a ``pycolmap.Reconstruction`` with one camera (not modified).
        guess: the focal length the model was built with (pixels); kept when unobservable.
        octaves, steps_per_octave: extent and density of the grid.
        min_rise: relative error rise at half and twice the best focal length that makes it
            observable.
        threads: CPU threads of the bundle adjustments.

    Returns:
        ``(reconstruction adjusted at the chosen focal length, FocalProfile)``.
    """
    import pycolmap

    n = int(round(octaves * steps_per_octave))
    fs = guess * 2.0 ** (np.arange(-n, n + 1) / steps_per_octave)
    errs = np.array([_adjust(pycolmap, rec, float(f), threads)[1] for f in fs])
    grid = tuple((float(f), float(e)) for f, e in zip(fs, errs))
    if not np.isfinite(errs).any():
        return _adjust(pycolmap, rec, guess, threads)[0], FocalProfile(guess, False, grid)
    i = int(np.argmin(errs))
    octave = steps_per_octave  # grid steps per factor 2
    lo = errs[i - octave] if i - octave >= 0 else math.inf
    hi = errs[i + octave] if i + octave < len(errs) else math.inf
    observable = min(lo, hi) >= errs[i] * (1 + min_rise)
    if not observable:
        return _adjust(pycolmap, rec, guess, threads)[0], FocalProfile(guess, False, grid)
    f = float(fs[i])
    if 0 < i < len(errs) - 1 and np.isfinite(errs[i - 1:i + 2]).all():
        y0, y1, y2 = errs[i - 1:i + 2]
        curv = y0 - 2 * y1 + y2
        if curv > 0:  # vertex of the parabola in log f, within half a step of the best
            step = math.log(2.0) / steps_per_octave
            f = float(fs[i] * math.exp(float(np.clip(0.5 * step * (y0 - y2) / curv, -step / 2, step / 2))))
    start, _ = _adjust(pycolmap, rec, f, threads)
    free, err = _adjust(pycolmap, start, None, threads)
    half_step = 2.0 ** (0.5 / steps_per_octave)
    if math.isfinite(err) and f / half_step <= _focal(free) <= f * half_step:
        return free, FocalProfile(_focal(free), True, grid)
    return start, FocalProfile(f, True, grid)
