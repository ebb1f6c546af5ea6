"""Camera response (transfer) curves between stored pixel values and linear irradiance.

sRGB follows IEC 61966-2-1 exactly: decoding is ``v / 12.92`` for ``v <= 0.04045`` and
``((v + 0.055) / 1.055) ** 2.4`` above; encoding is ``12.92 l`` for ``l <= 0.0031308`` and
``1.055 l ** (1 / 2.4) - 0.055`` above. ``"gamma:G"`` means ``value = linear ** (1 / G)``.
Every function takes numpy arrays (any float dtype) or tensors (differentiable, finite gradients
everywhere including 0) and returns the same type.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from fusiongs.errors import InputError

Array = np.ndarray | torch.Tensor


def _where(x: Array, cond, a, b):
    return torch.where(cond, a, b) if isinstance(x, torch.Tensor) else np.where(cond, a, b)


def _clamp_min(x: Array, lo: float) -> Array:
    return torch.clamp(x, min=lo) if isinstance(x, torch.Tensor) else np.maximum(x, lo)


def _as_float(x: Array) -> Array:
    if isinstance(x, torch.Tensor):
        return x if x.is_floating_point() else x.float()
    x = np.asarray(x)
    return x if np.issubdtype(x.dtype, np.floating) else x.astype(np.float32)


def srgb_to_linear(v: Array) -> Array:
    """sRGB decoding (EOTF, IEC 61966-2-1): encoded values ``[...]`` in [0, 1] -> linear."""
    v = _as_float(v)
    hi = ((_clamp_min(v, 0.04045) + 0.055) / 1.055) ** 2.4
    return _where(v, v <= 0.04045, v / 12.92, hi)


def linear_to_srgb(l: Array) -> Array:
    """sRGB encoding (inverse EOTF, IEC 61966-2-1): linear ``[...]`` in [0, 1] -> encoded."""
    l = _as_float(l)
    hi = 1.055 * _clamp_min(l, 0.0031308) ** (1.0 / 2.4) - 0.055
    return _where(l, l <= 0.0031308, l * 12.92, hi)


def gamma_to_linear(v: Array, gamma: float) -> Array:
    """Decode a pure power response: ``linear = value ** gamma`` (negative values clamp to 0)."""
    v = _as_float(v)
    return _clamp_min(v, 0.0) ** gamma


def linear_to_gamma(l: Array, gamma: float) -> Array:
    """Encode with a pure power response: ``value = linear ** (1 / gamma)``.

    Gradients at exactly 0 are taken at 1e-12 to stay finite.
    """
    l = _as_float(l)
    safe = _clamp_min(l, 1e-12)
    return _where(l, l > 0, safe ** (1.0 / gamma), l * 0.0)


def parse_response(response: object, where: str = "frame_response",
                   field: str = "frame_response") -> tuple[str, float | None]:
    """Validate a response name: ``("srgb", None)``, ``("linear", None)`` or ``("gamma", G)``.

    Raises:
        InputError: naming ``where``/``field`` for anything else (G must be a positive number).
    """
    expected = '"srgb", "linear" or "gamma:G" with G a positive number'
    if response in ("srgb", "linear"):
        return str(response), None
    if isinstance(response, str) and response.startswith("gamma:"):
        try:
            g = float(response[len("gamma:"):])
        except ValueError:
            g = float("nan")
        if math.isfinite(g) and g > 0:
            return "gamma", g
    raise InputError(where, field, expected, repr(response))


def response_to_linear(values: Array, response: str) -> Array:
    """Stored pixel values ``[...]`` encoded by ``response`` -> linear irradiance (same shape)."""
    kind, g = parse_response(response)
    if kind == "srgb":
        return srgb_to_linear(values)
    if kind == "gamma":
        return gamma_to_linear(values, g)
    return _as_float(values)


def linear_to_response(linear: Array, response: str) -> Array:
    """Linear irradiance ``[...]`` -> values encoded by ``response`` (same shape, not clipped)."""
    kind, g = parse_response(response)
    if kind == "srgb":
        return linear_to_srgb(linear)
    if kind == "gamma":
        return linear_to_gamma(linear, g)
    return _as_float(linear)
