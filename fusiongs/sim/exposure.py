"""Blurry frame formation: exposure-time integration in linear light, sensor noise, 8-bit sRGB
(or linear 16-bit) encoding.

A blurry frame is the mean linear radiance over its exposure window (docs/method.md section 1), here
with many sub-samples (midpoint rule), then photon shot noise and read noise in linear light, the
sRGB transfer curve and 8-bit quantisation.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from fusiongs.frames.response import linear_to_srgb


def exposure_times(t_start: float, t_end: float, n: int) -> np.ndarray:
    """Midpoint-rule sample instants ``t_k = s + (k + 0.5) / n * (e - s)``, ``[n]`` float64 (s)."""
    return t_start + (np.arange(n) + 0.5) / n * (t_end - t_start)


def blur_frame(render: Callable[[float], torch.Tensor], t_start: float, t_end: float, n: int) -> torch.Tensor:
    """Mean of ``n`` sharp linear renders over the exposure ``[t_start, t_end]`` (noise-free).

    Args:
        render: maps an instant (s) to ``[H, W, 3]`` linear radiance.
        t_start, t_end: exposure window (s). n: number of sub-samples.

    Returns:
        ``[H, W, 3]`` float32 mean linear radiance.
    """
    acc = None
    for t in exposure_times(t_start, t_end, n):
        img = render(float(t)).double()
        acc = img if acc is None else acc + img
    return (acc / n).float()


def add_sensor_noise(linear: np.ndarray, read_sigma: float, shot_gain: float,
                     rng: np.random.Generator) -> np.ndarray:
    """Gaussian read noise plus photon shot noise (variance ``shot_gain * L``), in linear light.

    Args:
        linear: ``[H, W, C]`` linear radiance (not modified).
        read_sigma: read-noise standard deviation (linear units).
        shot_gain: shot-noise variance per unit of radiance.
        rng: seeded generator.

    Returns:
        ``[H, W, C]`` float32 noisy radiance, clipped at 0.
    """
    lin = np.clip(np.asarray(linear, dtype=np.float64), 0.0, None)
    sigma = np.sqrt(read_sigma**2 + shot_gain * lin)
    return np.clip(lin + sigma * rng.standard_normal(lin.shape), 0.0, None).astype(np.float32)


def encode_srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear radiance -> sRGB -> 8-bit levels, returned as float32 ``level / 255`` in [0, 1]."""
    v = linear_to_srgb(np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0))
    return (np.rint(v * 255.0) / 255.0).astype(np.float32)


def encode_linear16(linear: np.ndarray) -> np.ndarray:
    """Linear radiance clipped to [0, 1] -> 16-bit levels, returned as float32 ``level / 65535``."""
    v = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return (np.rint(v * 65535.0) / 65535.0).astype(np.float32)
