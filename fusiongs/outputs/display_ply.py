"""``model.ply`` as 3DGS viewers show it: colours and opacities fitted for display-space compositing.

fusiongs composites linear light and encodes the result to sRGB afterwards: a pixel shows
``S(sum_i w_i c_i)`` (``S`` the sRGB encoding, ``w_i`` the compositing weights, ``c_i`` the linear
colours). 3DGS viewers (SuperSplat, the gsplat and nerfstudio viewers, viser) composite the stored
colours as they are, ``sum_i w_i d_i``, with ``d = 0.5 + SH_C0 f_dc`` (plus the ``f_rest`` terms),
``sigmoid(opacity)``, ``exp(scale)`` and a wxyz rotation. Writing ``d_i = S(c_i)`` per Gaussian
(:func:`fusiongs.scene.ply.display_sh`) is exact for one Gaussian alone but not where Gaussians of
different colours overlap: edges, thin structures and half-transparent layers come out wrong.

:func:`fit_display` starts from that per-Gaussian conversion and fits the display colours (every
SH band) and the opacities, geometry fixed, so that the viewers' compositing reproduces the run's
own renders at its fitted poses: Adam on the squared error at a reduced resolution over a few
evenly spaced poses, every pose at every step (no random draws: deterministic). The linear model
of ``checkpoint.pt`` is not changed; the fitted copy is what ``model.ply`` holds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.render import rasterize
from fusiongs.scene.gaussians import GaussianModel
from fusiongs.scene.ply import display_sh


@dataclass(frozen=True)
class DisplayFitOptions:
    """Settings of :func:`fit_display` (cheap: seconds on two CPU cores for a small scene).

    Attributes:
        steps: Adam steps (0: write the per-Gaussian conversion as it is).
        views: poses fitted on at most, evenly spaced over the run's instants.
        max_width: the fit renders at most this many pixels wide (the camera scaled down).
        lr_colour: Adam's step on the display SH coefficients.
        lr_opacity: Adam's step on the opacity logits (0: opacities kept).
    """

    steps: int = 100
    views: int = 8
    max_width: int = 128
    lr_colour: float = 0.01
    lr_opacity: float = 0.02


@dataclass(frozen=True)
class DisplayFit:
    """The result of :func:`fit_display`.

    Attributes:
        model: the display copy: SH coefficients are display values (``save_ply(...,
            colours="display")``), opacities fitted, geometry as the run's.
        psnr_before: dB of the per-Gaussian conversion composited as viewers do, against the run's
            renders at the evaluation poses (full resolution).
        psnr_after: dB of ``model`` composited as viewers do, same images.
        views: poses fitted on. eval_views: poses scored. steps: Adam steps. width, height: the
            fit's resolution (px). seconds: wall time of the fit and both scores.
    """

    model: GaussianModel
    psnr_before: float
    psnr_after: float
    views: int
    eval_views: int
    steps: int
    width: int
    height: int
    seconds: float

    def as_dict(self) -> dict:
        """The figures for ``metrics.json`` (``model_ply``)."""
        return {"psnr_before": self.psnr_before, "psnr_after": self.psnr_after, "views": self.views,
                "eval_views": self.eval_views, "steps": self.steps, "fit_size": [self.width, self.height],
                "seconds": self.seconds,
                "note": "PSNR (dB) of model.ply composited as 3DGS viewers do (stored colours, display "
                        "space) against the run's own renders at its fitted poses, before (each "
                        "Gaussian's colour sRGB-encoded) and after the display-space fit"}


def display_model(model: GaussianModel) -> GaussianModel:
    """A copy of linear-light ``model`` whose SH coefficients are display values, each Gaussian's
    colour sRGB-encoded (:func:`fusiongs.scene.ply.display_sh`); float32, on ``model``'s device,
    every band active (viewers use every band a file holds)."""
    f_dc, f_rest = display_sh(model.sh0, model.shN)
    dev = model.means.device
    return GaussianModel(model.means.detach(), model.log_scales.detach(), model.quats.detach(),
                         model.opacity_logits.detach(), f_dc[:, None, :].float().to(dev),
                         f_rest.float().to(dev), active_sh_degree=model.max_sh_degree)


def composite_display(model: GaussianModel, camera: PinholeCamera, w2c: torch.Tensor,
                      backend: str = "auto") -> torch.Tensor:
    """What a 3DGS viewer shows of ``model`` (display SH coefficients): the stored colours
    composited as they are, every SH band, clipped to [0, 1]; differentiable.

    Args:
        model: Gaussians whose SH coefficients are display values (:func:`display_model`).
        camera: the pinhole camera (pixels).
        w2c: ``[T, 4, 4]`` world-to-camera transforms (OpenCV axes), any float dtype.
        backend: :func:`fusiongs.render.rasterize`'s backend.

    Returns:
        ``[T, H, W, 3]`` display values in [0, 1], ``model``'s dtype and device.
    """
    viewmats = w2c.to(model.means.device, model.means.dtype)
    Ks = camera.K(dtype=model.means.dtype, device=model.means.device).expand(viewmats.shape[0], 3, 3)
    images, _, _ = rasterize(model.means, model.rotations, model.scales, model.opacities,
                             model.sh_coeffs(), viewmats, Ks, camera.width, camera.height,
                             sh_degree=model.max_sh_degree, backend=backend, check_values=False)
    return images.clamp(0.0, 1.0)


def even_subset(n: int, k: int) -> np.ndarray:
    """``min(n, k)`` indices into ``range(n)``, evenly spaced, first and last included when k > 1."""
    if n <= 0 or k <= 0:
        return np.zeros(0, dtype=np.int64)
    if k >= n:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, k)).astype(np.int64))


def fit_scale(camera: PinholeCamera, max_width: int) -> float:
    """The factor that brings ``camera`` to at most ``max_width`` pixels wide (1 when narrower)."""
    return min(1.0, max_width / camera.width)


def psnr_display(model: GaussianModel, camera: PinholeCamera, w2c: torch.Tensor, targets: np.ndarray,
                 backend: str = "auto", batch: int = 8) -> float:
    """PSNR (dB, peak 1) of :func:`composite_display` against ``targets`` ``[T, H, W, 3]`` sRGB in
    [0, 1] (one mean squared error over every pixel of every view)."""
    err, count = 0.0, 0
    with torch.no_grad():
        for i in range(0, w2c.shape[0], batch):
            shown = composite_display(model, camera, w2c[i:i + batch], backend).double().cpu().numpy()
            err += float(((shown - targets[i:i + batch]) ** 2).sum())
            count += shown.size
    mse = err / max(count, 1)
    return float("inf") if mse == 0 else -10.0 * math.log10(mse)


def fit_display(model: GaussianModel, fit_camera: PinholeCamera, w2c_fit: torch.Tensor,
                targets_fit: np.ndarray, eval_camera: PinholeCamera, w2c_eval: torch.Tensor,
                targets_eval: np.ndarray, options: DisplayFitOptions = DisplayFitOptions(),
                backend: str = "auto") -> DisplayFit:
    """Fit the display colours and opacities of ``model`` so that viewers show the run's renders.

    Args:
        model: the run's linear-light Gaussians (not modified).
        fit_camera: the fit's camera (the run's, scaled to :func:`fit_scale`).
        w2c_fit: ``[V, 4, 4]`` world-to-camera transforms of the fit's views.
        targets_fit: ``[V, h, w, 3]`` the run's sRGB renders in [0, 1] at those views
            (``fit_camera``'s size).
        eval_camera: the camera of the scores (the run's own).
        w2c_eval: ``[E, 4, 4]`` the views scored.
        targets_eval: ``[E, H, W, 3]`` the run's sRGB renders there (``eval_camera``'s size).
        options: :class:`DisplayFitOptions`.
        backend: the rasteriser's backend.

    Returns:
        :class:`DisplayFit`: the display copy and its PSNR before and after.
    """
    start = time.perf_counter()
    base = display_model(model)
    before = psnr_display(base, eval_camera, w2c_eval, targets_eval, backend)
    fitted = display_model(model)
    steps = options.steps if w2c_fit.shape[0] else 0
    if steps:
        target = torch.as_tensor(np.asarray(targets_fit, dtype=np.float32), device=model.means.device)
        groups = [{"params": [fitted.sh0, fitted.shN], "lr": options.lr_colour}]
        for p in (fitted.means, fitted.log_scales, fitted.quats):
            p.requires_grad_(False)
        if options.lr_opacity > 0:
            groups.append({"params": [fitted.opacity_logits], "lr": options.lr_opacity})
        else:
            fitted.opacity_logits.requires_grad_(False)
        opt = torch.optim.Adam(groups)
        for _ in range(steps):
            opt.zero_grad(set_to_none=True)
            loss = ((composite_display(fitted, fit_camera, w2c_fit, backend) - target) ** 2).mean()
            loss.backward()
            opt.step()
    fitted.requires_grad_(False)
    after = psnr_display(fitted, eval_camera, w2c_eval, targets_eval, backend)
    if after < before:  # never write a worse file than the plain conversion
        fitted, after = base, before
    return DisplayFit(model=fitted, psnr_before=before, psnr_after=after, views=int(w2c_fit.shape[0]),
                      eval_views=int(w2c_eval.shape[0]), steps=steps, width=fit_camera.width,
                      height=fit_camera.height, seconds=time.perf_counter() - start)


EVAL_VIEWS = 12  # poses the written PLY is scored at (full resolution), evenly spaced


def fit_run_display(state, camera: PinholeCamera, times, gain: float = 1.0, adjust=None,
                    backend: str = "auto", options: DisplayFitOptions = DisplayFitOptions()) -> DisplayFit:
    """:func:`fit_display` of a finished run against its own renders at its fitted poses.

    Args:
        state: the run's :class:`fusiongs.train.state.FusionState` (not modified).
        camera: the run's camera.
        times: ``[T]`` instants (s) on the fitted path: the frames' mid-exposures and the requested
            renders; empty: :data:`EVAL_VIEWS` instants spread over the path.
        gain: the linear gain of the run's renders (``exposure.json``; 1 when frames fix the level).
        adjust: applied to each sRGB render ``[H, W, 3]`` as the run's written images have it (the
            colour anchor), or None.
        backend: the rasteriser's backend.
        options: :class:`DisplayFitOptions`.

    Returns:
        :class:`DisplayFit`; the targets are the run's sharp renders (``render_linear`` times
        ``gain``, clipped, sRGB-encoded, ``adjust`` applied), not the exposure-ratio-corrected frames.
    """
    from fusiongs.train.render_io import exposed_srgb, render_linear

    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if t.size == 0:
        t = np.linspace(state.trajectory.t_min, state.trajectory.t_max, EVAL_VIEWS)
    t = np.unique(t)
    small = camera.scaled(fit_scale(camera, options.max_width))

    def views(k: int, cam: PinholeCamera) -> tuple[torch.Tensor, np.ndarray]:
        tk = t[even_subset(t.size, k)]
        with torch.no_grad():
            w2c = state.trajectory.w2c(torch.as_tensor(tk)).detach()
        srgb = exposed_srgb(render_linear(state, cam, tk, backend), gain)
        if adjust is not None:
            srgb = np.stack([adjust(img) for img in srgb])
        return w2c, np.asarray(srgb, dtype=np.float32)

    w2c_fit, targets_fit = views(options.views, small)
    w2c_eval, targets_eval = views(EVAL_VIEWS, camera)
    return fit_display(state.model, small, w2c_fit, targets_fit, camera, w2c_eval, targets_eval, options,
                       backend)
