"""Image quality metrics following the evaluation protocol of docs/method.md ('Evaluation protocol').

PSNR and SSIM are computed on 8-bit sRGB images (values quantised to k/255). SSIM uses a Gaussian
window (σ = 1.5, 11 taps), population (not sample) covariances and only the window positions that fit
inside the image (Wang et al., IEEE TIP 2004; identical to ``kornia.metrics.ssim`` with
``padding='valid'`` and to scikit-image with ``gaussian_weights=True, use_sample_covariance=False``).
Colour error is the mean CIEDE2000 difference ΔE00 (Sharma, Wu and Dalal, Color Res. Appl. 2005)
over pixels, on CIE L*a*b* (D65) of the same 8-bit sRGB values, computed with colour-science.
"""

from __future__ import annotations

import numpy as np
import torch

from fusiongs.errors import InputError


def quantize8(img: np.ndarray | torch.Tensor) -> np.ndarray:
    """Clip to [0, 1] and round to 8 bits; returns float64 ``[H, W, C]`` values k/255."""
    a = img.detach().cpu().numpy() if isinstance(img, torch.Tensor) else np.asarray(img)
    a = a.astype(np.float64)
    if a.ndim == 2:
        a = a[..., None]
    return np.round(np.clip(a, 0.0, 1.0) * 255.0) / 255.0


def _check_pair(pred: np.ndarray, gt: np.ndarray) -> None:
    if pred.shape != gt.shape:
        raise InputError("metrics", "image shape", f"prediction and truth of equal shape {gt.shape}",
                         pred.shape)


def psnr(pred: np.ndarray | torch.Tensor, gt: np.ndarray | torch.Tensor) -> float:
    """PSNR in dB between two sRGB images ``[H, W, C]`` in [0, 1], after 8-bit quantisation."""
    p, g = quantize8(pred), quantize8(gt)
    _check_pair(p, g)
    mse = float(np.mean((p - g) ** 2))
    return float("inf") if mse == 0.0 else float(10.0 * np.log10(1.0 / mse))


def ssim(pred: np.ndarray | torch.Tensor, gt: np.ndarray | torch.Tensor) -> float:
    """SSIM between two sRGB images ``[H, W, C]`` in [0, 1], after 8-bit quantisation."""
    import kornia

    p, g = quantize8(pred), quantize8(gt)
    _check_pair(p, g)
    if min(p.shape[0], p.shape[1]) < 11:
        raise InputError("metrics", "image size", "at least 11x11 pixels for SSIM", p.shape[:2])
    tp = torch.from_numpy(p).permute(2, 0, 1)[None]
    tg = torch.from_numpy(g).permute(2, 0, 1)[None]
    m = kornia.metrics.ssim(tp, tg, window_size=11, max_val=1.0, padding="valid")
    return float(m.mean())


def srgb_to_lab(img: np.ndarray | torch.Tensor) -> np.ndarray:
    """CIE L*a*b* ``[H, W, 3]`` (D65, L* in [0, 100]) of an sRGB image ``[H, W, C]`` (C = 1 or 3)
    in [0, 1], after 8-bit quantisation; a grey image is taken as R = G = B."""
    import colour

    a = quantize8(img)
    if a.shape[-1] == 1:
        a = np.repeat(a, 3, axis=-1)
    if a.shape[-1] != 3:
        raise InputError("metrics", "image channels", "1 or 3", a.shape[-1])
    white = colour.RGB_COLOURSPACES["sRGB"].whitepoint
    return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(a, illuminant=white), illuminant=white)


def delta_e00(pred: np.ndarray | torch.Tensor, gt: np.ndarray | torch.Tensor) -> float:
    """Mean CIEDE2000 colour difference over pixels of two sRGB images ``[H, W, C]`` in [0, 1].

    0 for equal images; about 1 is a just noticeable difference; black to white is 100.
    """
    import colour

    p, g = srgb_to_lab(pred), srgb_to_lab(gt)
    _check_pair(p, g)
    return float(np.mean(colour.delta_E(p, g, method="CIE 2000")))


def affine_fit(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-channel least-squares affine correction ``a_c·pred + b_c`` of ``pred`` toward ``gt``.

    Event-only reconstructions have no absolute brightness or colour balance; EventNeRF (Rudnev et
    al., CVPR 2023) reports metrics after such a fit. Both inputs ``[H, W, C]``; the result is
    clipped to [0, 1].
    """
    p = np.asarray(pred, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    _check_pair(p, g)
    p2 = p.reshape(-1, p.shape[-1])
    g2 = g.reshape(-1, g.shape[-1])
    mp, mg = p2.mean(0), g2.mean(0)
    var = ((p2 - mp) ** 2).mean(0)
    cov = ((p2 - mp) * (g2 - mg)).mean(0)
    a = np.where(var > 1e-12, cov / np.maximum(var, 1e-12), 0.0)
    b = mg - a * mp
    return np.clip(p * a + b, 0.0, 1.0)


def global_affine_fit(preds: list[np.ndarray], gts: list[np.ndarray]) -> list[np.ndarray]:
    """One per-channel least-squares affine correction ``a_c·pred + b_c`` fitted over all views.

    The stricter protocol of event-only work (EventNeRF, Rudnev et al., CVPR 2023; Robust e-NeRF,
    Low and Lee, ICCV 2023): one gain and offset per channel for a whole scene, so the views must
    agree with each other in brightness, not only each with its own truth. Inputs: lists of
    ``[H, W, C]`` images (views may differ in size); returns the corrected views, clipped to [0, 1].
    """
    if len(preds) != len(gts) or not preds:
        raise InputError("metrics", "preds/gts", "two non-empty lists of the same length",
                         (len(preds), len(gts)))
    for a, b in zip(preds, gts):
        _check_pair(np.asarray(a), np.asarray(b))
    c = np.asarray(preds[0]).shape[-1]
    p2 = np.concatenate([np.asarray(x, dtype=np.float64).reshape(-1, c) for x in preds])
    g2 = np.concatenate([np.asarray(x, dtype=np.float64).reshape(-1, c) for x in gts])
    mp, mg = p2.mean(0), g2.mean(0)
    var = ((p2 - mp) ** 2).mean(0)
    cov = ((p2 - mp) * (g2 - mg)).mean(0)
    a = np.where(var > 1e-12, cov / np.maximum(var, 1e-12), 0.0)
    b = mg - a * mp
    return [np.clip(np.asarray(x, dtype=np.float64) * a + b, 0.0, 1.0) for x in preds]


def image_metrics(pred: np.ndarray, gt: np.ndarray, *, affine: bool = False,
                  delta_e: bool | None = None) -> dict[str, float]:
    """``{"psnr", "ssim"}`` of one sRGB image pair, optionally after :func:`affine_fit`.

    ``delta_e`` (default: the value of ``affine``) adds ``"delta_e00"``, :func:`delta_e00` of the
    same (fitted) pair.
    """
    if affine:
        pred = affine_fit(pred, gt)
    out = {"psnr": psnr(pred, gt), "ssim": ssim(pred, gt)}
    if affine if delta_e is None else delta_e:
        out["delta_e00"] = delta_e00(pred, gt)
    return out
