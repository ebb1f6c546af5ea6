"""PSNR against the scene's truth images while training: the ``psnr_truth`` curve of
``history.jsonl``, for simulated scenes whose ``gt/`` folder holds sharp images.

Every ``output.truth_every`` iterations the current model is rendered at up to ``MAX_VIEWS``
truth instants (requested renders and frame mid-exposures, evenly chosen) and scored on 8-bit sRGB:
as rendered, and after a per-channel affine fit (EventNeRF's protocol, the figure that means
something for event-only runs). These are raw renders: no exposure-ratio correction and no colour
anchor, so with frames the curve runs below the final ``metrics.json`` deblur figures; without
frames they get the outputs' exposure gain (``output.exposure``) of the probe's own renders.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusiongs.eval.metrics import affine_fit, psnr
from fusiongs.io.scene import Scene
from fusiongs.train.render_io import read_gt, render_srgb
from fusiongs.train.state import FusionState

MAX_VIEWS = 6  # truth images scored per probe (a few renders: ~1 % of a run at truth_every 100)


@dataclass(frozen=True)
class TruthProbe:
    """Truth images ``gt [V, H, W, 3]`` (sRGB in [0, 1]) at instants ``times [V]`` (s, host)."""

    names: tuple[str, ...]
    times: np.ndarray
    gt: np.ndarray


def truth_probe(scene: Scene, max_views: int = MAX_VIEWS) -> TruthProbe | None:
    """The probe of a scene with ``gt/`` images for its requested renders or frames; None without."""
    gt_dir = scene.root / "gt" if scene.root is not None else None
    if gt_dir is None or not gt_dir.is_dir() or max_views < 1:
        return None
    keys = [r.name for r in scene.renders] + [f"deblur_{n}" for n in scene.frames.names]
    times = [float(r.t) for r in scene.renders] + [float(t) for t in scene.frames.mid_times()]
    gt = read_gt(gt_dir, keys)
    found = [(k, t) for k, t in zip(keys, times) if k in gt and gt[k].shape[:2] ==
             (scene.camera.height, scene.camera.width)]
    if not found:
        return None
    pick = np.unique(np.linspace(0, len(found) - 1, min(max_views, len(found))).round().astype(int))
    chosen = [found[i] for i in pick]
    return TruthProbe(tuple(k for k, _ in chosen), np.array([t for _, t in chosen], np.float64),
                      np.stack([gt[k] for k, _ in chosen]).astype(np.float32))


def probe_psnr(state: FusionState, camera, probe: TruthProbe, backend: str = "auto",
               auto_exposure: bool = False) -> tuple[float, float]:
    """Mean PSNR (dB, 8-bit sRGB) of renders at the probe's instants: as rendered (with the
    outputs' exposure gain when ``auto_exposure``, :func:`~fusiongs.train.render_io.render_srgb`),
    and after a per-channel affine fit to the truth."""
    renders = render_srgb(state, camera, probe.times, backend, auto_exposure=auto_exposure)
    raw = [psnr(r, g) for r, g in zip(renders, probe.gt)]
    fit = [psnr(affine_fit(r, g), g) for r, g in zip(renders, probe.gt)]
    return float(np.mean(raw)), float(np.mean(fit))


def should_probe(it: int, every: int, last: int) -> bool:
    """Probe after iteration ``it`` (0-based): every ``every`` iterations and after the last one."""
    return every > 0 and ((it + 1) % every == 0 or it + 1 == last)

