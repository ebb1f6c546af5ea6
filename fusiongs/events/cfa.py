"""Bayer colour filter arrays: channel layout, masks, mosaicing and demosaicing.

A pattern is named by its top-left 2x2 cell read row-major (``"RGGB"``: R at even row and even
column, G at (even, odd) and (odd, even), B at (odd, odd)). OpenCV's legacy Bayer names read the
pattern from pixel (1, 1), so RGGB is ``COLOR_BayerBG2*`` (OpenCV 5 also calls it
``COLOR_BayerRGGB2*``) and kornia's ``CFA.BG``; ``tests/events/test_cfa.py`` checks the mapping
empirically. Used by both the event (colour DAVIS) and the frame (raw files) sides.
"""

from __future__ import annotations

import functools

import numpy as np
import torch

from fusiongs.errors import InputError
from fusiongs.events.stream import CFA_PATTERNS

DEMOSAIC_METHODS = ("bilinear", "opencv-bilinear", "opencv-ea", "opencv-vng", "kornia")
_CHANNEL = {"R": 0, "G": 1, "B": 2}
# OpenCV's legacy names (valid in OpenCV 4 and 5) and kornia's CFA names, per pattern.
_OPENCV_NAME = {"RGGB": "BG", "GRBG": "GB", "BGGR": "RG", "GBRG": "GR"}
_KORNIA_NAME = _OPENCV_NAME
_OPENCV_SUFFIX = {"opencv-bilinear": "", "opencv-ea": "_EA", "opencv-vng": "_VNG"}
# Standard bilinear kernels (Malvar et al. 2004 call this the bilinear baseline).
_K_RB = np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]], dtype=np.float64) / 4.0
_K_G = np.array([[0, 1, 0], [1, 4, 1], [0, 1, 0]], dtype=np.float64) / 4.0


def check_pattern(pattern: object, where: str = "cfa", field: str = "cfa") -> str:
    """Return ``pattern`` if it names a supported 2x2 Bayer layout, else raise :class:`InputError`."""
    if not isinstance(pattern, str) or pattern not in CFA_PATTERNS:
        raise InputError(where, field, f"one of {', '.join(CFA_PATTERNS)}", repr(pattern))
    return pattern


def cfa_channel_index(pattern: str, height: int, width: int) -> np.ndarray:
    """Colour channel seen by every pixel.

    Args:
        pattern: ``"RGGB"``, ``"BGGR"``, ``"GRBG"`` or ``"GBRG"``.
        height, width: sensor size in pixels.

    Returns:
        ``[H, W]`` int8 channel index, 0 = R, 1 = G, 2 = B.
    """
    check_pattern(pattern)
    cell = np.array([_CHANNEL[c] for c in pattern], dtype=np.int8).reshape(2, 2)
    reps = ((height + 1) // 2, (width + 1) // 2)
    return np.ascontiguousarray(np.tile(cell, reps)[:height, :width])


def cfa_masks(pattern: str, height: int, width: int) -> np.ndarray:
    """``[3, H, W]`` bool masks of the R, G and B pixels of a Bayer sensor."""
    idx = cfa_channel_index(pattern, height, width)
    return np.stack([idx == c for c in range(3)])


def mosaic(rgb: np.ndarray | torch.Tensor, pattern: str) -> np.ndarray | torch.Tensor:
    """Sample a full-colour image through a Bayer filter.

    Args:
        rgb: ``[..., H, W, 3]`` numpy array or tensor (differentiable).
        pattern: Bayer layout name.

    Returns:
        ``[..., H, W]`` mosaic of the same type and dtype.
    """
    if rgb.ndim < 3 or rgb.shape[-1] != 3:
        raise InputError("mosaic", "rgb", "an array [..., H, W, 3]", tuple(rgb.shape))
    h, w = rgb.shape[-3], rgb.shape[-2]
    idx = cfa_channel_index(pattern, h, w).astype(np.int64)
    if isinstance(rgb, torch.Tensor):
        index = torch.from_numpy(idx).to(rgb.device).expand(*rgb.shape[:-1]).unsqueeze(-1)
        return torch.gather(rgb, -1, index).squeeze(-1)
    index = np.broadcast_to(idx, rgb.shape[:-1])[..., None]
    return np.take_along_axis(rgb, index, axis=-1)[..., 0]


def demosaic(raw: np.ndarray | torch.Tensor, pattern: str, method: str = "bilinear"
             ) -> np.ndarray | torch.Tensor:
    """Reconstruct ``[..., H, W, 3]`` colour from a Bayer mosaic.

    Methods:
        ``"bilinear"``: normalised convolution of each channel's samples with the standard
        bilinear kernels; any float data, including signed event maps; numpy in -> numpy out,
        tensor in -> tensor out (differentiable). Equals OpenCV's bilinear demosaic away from the
        one-pixel border; at the border only the available neighbours are averaged.
        ``"opencv-bilinear" | "opencv-ea" | "opencv-vng"``: OpenCV's Bayer conversions on numpy
        ``[H, W]``. uint8/uint16 are used as they are (VNG needs uint8); non-negative float data
        is quantised to 16 bit (8 bit for VNG) relative to its maximum and scaled back. Returns
        float32 in the input's units.
        ``"kornia"``: ``kornia.color.raw_to_rgb`` (bilinear), differentiable; odd sizes are
        padded by reflection (which keeps the CFA phase) and cropped back.

    Args:
        raw: ``[..., H, W]`` mosaic (leading dimensions only for ``"bilinear"`` and ``"kornia"``).
        pattern: Bayer layout name of ``raw``'s top-left cell.
        method: one of ``DEMOSAIC_METHODS``.

    Returns:
        ``[..., H, W, 3]`` RGB, float32 (or the input tensor's float dtype).
    """
    check_pattern(pattern)
    if method not in DEMOSAIC_METHODS:
        raise InputError("demosaic", "method", f"one of {', '.join(DEMOSAIC_METHODS)}", repr(method))
    if raw.ndim < 2:
        raise InputError("demosaic", "raw", "a mosaic [..., H, W]", tuple(raw.shape))
    if method == "bilinear":
        return _bilinear(raw, pattern)
    if method == "kornia":
        return _kornia(raw, pattern)
    return _opencv(raw, pattern, method)


@functools.lru_cache(maxsize=16)
def _bilinear_tensors(pattern: str, h: int, w: int, device: torch.device, dtype: torch.dtype
                      ) -> tuple[torch.Tensor, torch.Tensor]:
    """The CFA masks ``[3, H, W]`` and bilinear kernels ``[3, 1, 3, 3]`` on ``device``, made once
    per (pattern, size, device, dtype): the demosaic mode calls :func:`_bilinear` every training
    step, and a host-to-device copy per call stalls a GPU."""
    masks = torch.as_tensor(cfa_masks(pattern, h, w), dtype=dtype, device=device)
    kernels = torch.as_tensor(np.stack([_K_RB, _K_G, _K_RB]), dtype=dtype, device=device)[:, None]
    return masks, kernels


def _bilinear(raw, pattern):
    h, w = raw.shape[-2], raw.shape[-1]
    if isinstance(raw, torch.Tensor):
        x = raw if raw.is_floating_point() else raw.float()
        lead = x.shape[:-2]
        x = x.reshape(-1, 1, h, w)
        m, k = _bilinear_tensors(pattern, h, w, x.device, x.dtype)  # [3, H, W], [3, 1, 3, 3]
        num = torch.nn.functional.conv2d(x * m, k, padding=1, groups=3)
        den = torch.nn.functional.conv2d(m[None], k, padding=1, groups=3)
        out = num / den
        return out.reshape(*lead, 3, h, w).movedim(-3, -1)
    import cv2

    masks = cfa_masks(pattern, h, w)
    x = np.asarray(raw)
    dtype = x.dtype if x.dtype in (np.float32, np.float64) else np.float32
    flat = x.reshape(-1, h, w).astype(np.float64)
    out = np.empty(flat.shape + (3,), dtype=dtype)
    for c, k in enumerate((_K_RB, _K_G, _K_RB)):
        mc = masks[c].astype(np.float64)
        den = cv2.filter2D(mc, -1, k, borderType=cv2.BORDER_CONSTANT)
        for i in range(flat.shape[0]):  # leading (batch) dimension only, not pixels
            num = cv2.filter2D(flat[i] * mc, -1, k, borderType=cv2.BORDER_CONSTANT)
            out[i, ..., c] = num / den
    return out.reshape(x.shape + (3,))


def _opencv(raw, pattern, method):
    import cv2

    if isinstance(raw, torch.Tensor):
        raw = raw.detach().cpu().numpy()
    x = np.asarray(raw)
    if x.ndim != 2:
        raise InputError("demosaic", "raw", f"a single mosaic [H, W] for {method}", tuple(x.shape))
    code = getattr(cv2, f"COLOR_Bayer{_OPENCV_NAME[pattern]}2RGB{_OPENCV_SUFFIX[method]}")
    scale = 1.0
    native = (np.uint8,) if method == "opencv-vng" else (np.uint8, np.uint16)
    if x.dtype not in native:
        if x.size and (not np.all(np.isfinite(x)) or x.min() < 0):
            raise InputError("demosaic", "raw", f"finite non-negative values for {method} "
                             "(use method='bilinear' for signed data)")
        top = 255 if method == "opencv-vng" else 65535
        peak = float(x.max()) if x.size else 0.0
        scale = peak / top if peak > 0 else 1.0
        x = np.clip(np.rint(x.astype(np.float64) / scale), 0, top)
        x = x.astype(np.uint8 if top == 255 else np.uint16)
    out = cv2.cvtColor(np.ascontiguousarray(x), code)
    return (out.astype(np.float64) * scale).astype(np.float32)


def _kornia(raw, pattern):
    from kornia.color import CFA, raw_to_rgb

    t = raw if isinstance(raw, torch.Tensor) else torch.from_numpy(np.asarray(raw))
    if not t.is_floating_point():
        t = t.float()
    h, w = t.shape[-2], t.shape[-1]
    lead = t.shape[:-2]
    x = t.reshape(-1, 1, h, w)
    ph, pw = h % 2, w % 2
    if ph or pw:
        if h < 2 or w < 2:
            raise InputError("demosaic", "raw", "at least 2x2 pixels for kornia", (h, w))
        x = torch.nn.functional.pad(x, (0, pw, 0, ph), mode="reflect")
    out = raw_to_rgb(x, getattr(CFA, _KORNIA_NAME[pattern]))[..., :h, :w]
    out = out.reshape(*lead, 3, h, w).movedim(-3, -1)
    return out if isinstance(raw, torch.Tensor) else out.numpy().astype(np.float32)
