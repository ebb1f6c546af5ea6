"""The floor peer of event-only reconstruction: the leaky-integrator (high-pass) intensity image of
the events alone, scored like fusiongs's renders.

Event-only training anchors its intensity to this image (Event-3DGS's photovoltage contrast, a
per-pixel high-pass filter of the event stream; Scheerlinck et al., ACCV 2018), so a
reconstruction that does not beat it clearly has learned nothing from the events beyond it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _fitted_at_instants(scene_path: str | Path, image_at) -> dict[str, float]:
    """Affine-fit PSNR / SSIM, averaged over the scene's requested instants, of ``image_at(scene,
    names, times)`` (sRGB ``[K, H, W, 3]`` in [0, 1], one per instant) against ``SCENE/gt/NAME.png``;
    the instants in time order (a scene with frames lists its deblur views first)."""
    from fusiongs.eval.metrics import image_metrics
    from fusiongs.frames.image_io import read_image
    from fusiongs.io.scene_io import load_scene

    scene = load_scene(scene_path)
    views = sorted(scene.renders, key=lambda r: r.t)
    names = [r.name for r in views]
    times = np.array([r.t for r in views])
    truth = [read_image(Path(scene_path) / "gt" / f"{name}.png") for name in names]
    out = [image_metrics(img, gt, affine=True, delta_e=False)
           for img, gt in zip(image_at(scene, truth, times), truth)]
    return {k: float(np.mean([o[k] for o in out])) for k in ("psnr", "ssim")}


def leaky_integrator_floor(scene_path: str | Path, theta0: float = 0.22,
                           tau: float = 0.05) -> dict[str, float]:
    """Affine-fit PSNR / SSIM of the events' high-pass intensity image at the scene's requested
    instants against its truth (``SCENE/gt/NAME.png``), averaged over the instants.

    Args:
        scene_path: a scene folder with ``renders`` and their truth.
        theta0: contrast threshold the events are integrated with (log units; the affine fit
            absorbs most of a wrong value).
        tau: time constant of the high-pass filter (s).

    Returns:
        ``{"psnr": dB, "ssim": ...}`` after a per-channel affine fit (8-bit sRGB).
    """
    from fusiongs.events.cfa import demosaic
    from fusiongs.events.hpf import high_pass_filter
    from fusiongs.frames.response import linear_to_srgb

    def hpf_image(scene, truth, times):
        v = high_pass_filter(scene.events, times * 1e6, tau=tau, contrast=theta0)  # [K, H, W] log
        for img in v:
            lin = np.exp(img - np.percentile(img, 99))
            lin = demosaic(lin, scene.events.cfa) if scene.events.cfa else np.repeat(lin[..., None], 3, -1)
            yield linear_to_srgb(np.clip(lin, 0, 1)).astype(np.float32)

    return _fitted_at_instants(scene_path, hpf_image)


def grey_ceiling(scene_path: str | Path) -> dict[str, float]:
    """The most a grey event sensor's reconstruction can score under the affine-fit protocol: the
    truth's own grey (linear light weighted as a grey sensor and the model see it, Rec. 601:
    :data:`fusiongs.losses.event.REC601`), affine-fitted per channel to the truth at the scene's
    requested instants. A grey sensor sees no hue, so however
    sharp its reconstruction, the fit cannot bring back colour the luminance does not carry.

    Returns:
        ``{"psnr": dB, "ssim": ...}`` averaged over the instants (8-bit sRGB).
    """
    from fusiongs.frames.response import linear_to_srgb, srgb_to_linear
    from fusiongs.losses.event import REC601

    def luminance(scene, truth, times):
        for gt in truth:
            y = srgb_to_linear(gt.astype(np.float64)) @ np.array(REC601)
            yield np.repeat(linear_to_srgb(np.clip(y, 0, 1))[..., None], 3, -1).astype(np.float32)

    return _fitted_at_instants(scene_path, luminance)
