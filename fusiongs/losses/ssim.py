"""SSIM for the training loss in a few batched operations (Wang et al., IEEE TIP 2004).

The same map as ``kornia.metrics.ssim(x, y, window_size, max_val, padding="same")`` (a sampled
Gaussian window of sigma 1.5, reflect padding, ``c1 = (0.01 L)^2``, ``c2 = (0.03 L)^2``, ``eps``
added to the denominator), computed as one reflect pad and two 1-D convolutions of the five
stacked moment images ``x, y, x^2, y^2, x y`` with a window built once per device and dtype.
kornia's general version rebuilds its window and filters each moment on its own, about 400 tensor
operations a call: on a GPU each is a launch, and the blur loss calls it every iteration.
kornia stays the reference (``tests/losses/test_ssim.py`` compares maps and gradients).
"""

from __future__ import annotations

import functools

import torch
import torch.nn.functional as F

SIGMA = 1.5  # kornia's (and Wang et al.'s) window sigma, whatever the window size


@functools.lru_cache(maxsize=8)
def _window(size: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """``[size]`` sampled Gaussian of sigma :data:`SIGMA` summing to 1, made on ``device`` (no
    copy from the host, which would stall a GPU the first time)."""
    k = torch.arange(size, dtype=dtype, device=device) - size // 2
    w = torch.exp(-k * k / (2 * SIGMA ** 2))
    return w / w.sum()


def ssim_map(x: torch.Tensor, y: torch.Tensor, window_size: int = 11, max_val: float = 1.0,
             eps: float = 1e-12) -> torch.Tensor:
    """SSIM map of two ``[B, C, H, W]`` images (``'same'`` size, reflect padding).

    Args:
        x, y: images of one shape, float; ``H`` and ``W`` larger than ``window_size // 2``.
        window_size: odd number of taps of the Gaussian window.
        max_val: the images' dynamic range ``L``.
        eps: added to the denominator (kornia's default).

    Returns:
        ``[B, C, H, W]`` SSIM per pixel and channel.
    """
    b, c, h, w = x.shape
    g = _window(window_size, x.device, x.dtype)
    p = window_size // 2
    z = torch.cat([x, y, x * x, y * y, x * y], 1)                       # [B, 5C, H, W]
    z = F.pad(z, (p, p, p, p), mode="reflect")
    n = 5 * c
    z = F.conv2d(z, g.view(1, 1, 1, -1).expand(n, 1, 1, window_size), groups=n)
    z = F.conv2d(z, g.view(1, 1, -1, 1).expand(n, 1, window_size, 1), groups=n)
    mu_x, mu_y, xx, yy, xy = z.split(c, 1)
    mu_xx, mu_yy, mu_xy = mu_x * mu_x, mu_y * mu_y, mu_x * mu_y
    c1, c2 = (0.01 * max_val) ** 2, (0.03 * max_val) ** 2
    num = (2 * mu_xy + c1) * (2 * (xy - mu_xy) + c2)
    den = (mu_xx + mu_yy + c1) * ((xx - mu_xx) + (yy - mu_yy) + c2)
    return num / (den + eps)
