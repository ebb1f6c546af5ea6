"""Event consistency of long windows at low spatial frequencies.

Over a window ``[t_a, t_b)`` a pixel's events say ``dlog I ~= theta_+ n_+ - theta_- n_-`` (docs/method.md
section 1), but the count carries every event's share of the pixel's threshold mismatch, so the
per-pixel error grows with the number of events: short windows are compared pixel by pixel
(:mod:`fusiongs.losses.event`), and they fix an image's edges, not the level of a large plain area
relative to another far away. That error is independent from pixel to pixel and has zero mean, so
a spatial low-pass of both sides averages it out while keeping what a long window knows about
large scales. The comparison is a normalised convolution (Knutsson & Westin, CVPR 1993) per CFA
channel: ``G * (v m_c) / G * m_c`` with a Gaussian ``G`` of ``sigma`` pixels and ``m_c`` the valid
pixels of channel ``c`` (counts cut short by the sensor's dead time, which are only lower bounds,
and hot pixels are left out rather than averaged with the others).

Shapes: ``H x W`` sensor pixels; ``C`` = 1 (grey sensor) or 3 (the CFA channels of a colour sensor).
"""

from __future__ import annotations

import functools
import math

import kornia
import torch
import torch.nn.functional as F


def gaussian_blur(maps: torch.Tensor, sigma: float) -> torch.Tensor:
    """``[C, H, W]`` maps blurred by a Gaussian of ``sigma`` pixels (kernel ``2 ceil(3 sigma) + 1``
    wide), zeros outside the sensor: kornia's separable filter with the 1-D kernel of
    ``kornia.filters.gaussian_blur2d`` (the same values), made once per size, device and dtype
    rather than in ~40 small operations at every call (each a kernel launch on a GPU)."""
    k = 2 * max(1, math.ceil(3.0 * sigma)) + 1
    kernel = _kernel1d(k, float(sigma), maps.device, maps.dtype)
    return kornia.filters.filter2d_separable(maps[None], kernel, kernel, border_type="constant")[0]


@functools.lru_cache(maxsize=16)
def _kernel1d(size: int, sigma: float, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """``[1, size]`` normalised Gaussian taps (:func:`kornia.filters.get_gaussian_kernel1d`)."""
    return kornia.filters.get_gaussian_kernel1d(size, sigma, device=device, dtype=dtype)


def lowpass_maps(values: torch.Tensor, valid: torch.Tensor, channel: torch.Tensor | None,
                 channels: int, sigma: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Normalised-convolution low-pass of one per-pixel map, per CFA channel (the definition;
    :func:`event_loss_lowpass` computes the same for many windows at once, and the tests compare
    the two).

    Args:
        values: ``[H, W]`` one value per sensor pixel.
        valid: ``[H, W]`` bool, pixels that take part.
        channel: ``[H, W]`` int64 CFA channel of each pixel, or None (one channel).
        channels: ``C``.
        sigma: Gaussian standard deviation (pixels).

    Returns:
        ``(low [C, H, W], support [C, H, W])``: the weighted mean of the valid pixels of each
        channel around every pixel, and the Gaussian weight they hold there (0..1).
    """
    masks = _channel_masks(valid[None], channel, channels)[0].to(values.dtype)
    num = gaussian_blur(masks * values[None], sigma)
    den = gaussian_blur(masks, sigma)
    return num / den.clamp_min(1e-6), den


def _channel_masks(valid: torch.Tensor, channel: torch.Tensor | None, channels: int) -> torch.Tensor:
    """``[B, C, H, W]`` float: valid pixels ``[B, H, W]`` of each channel."""
    m = valid.to(torch.float32)[:, None]
    if channel is None:
        return m
    return F.one_hot(channel.to(torch.int64), channels).permute(2, 0, 1)[None].to(m.dtype) * m


def full_support(channel: torch.Tensor | None, channels: int, sigma: float, height: int, width: int,
                 device: torch.device, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """``[C, H, W]`` Gaussian weight a fully valid neighbourhood of each channel holds around every
    pixel (the denominator of :func:`lowpass_maps` with every pixel valid; less than 1 near the
    border and, on a CFA, the channel's share of the pixels)."""
    full = torch.ones(1, height, width, dtype=torch.bool, device=device)
    with torch.no_grad():
        return gaussian_blur(_channel_masks(full, channel, channels)[0].to(dtype), sigma)


def event_loss_lowpass(delta_pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor,
                       channel: torch.Tensor | None, channels: int, sigma: float,
                       theta: torch.Tensor | float, min_support: float = 0.2,
                       support: torch.Tensor | None = None) -> torch.Tensor:
    """L1 distance of the low-passed rendered and event log changes of ``B`` long windows.

    Per window and channel this is ``|LP(delta_pred) - LP(target)|`` with the low-pass of
    :func:`lowpass_maps`, computed as one normalised convolution of the difference (the
    windows and channels in one blur; :func:`lowpass_maps` is the reference the tests compare).

    Args:
        delta_pred: ``[B, H, W]`` (or ``[H, W]``) rendered log change of each pixel's own channel.
        target: same shape, ``theta_+ n_+ - theta_- n_-`` of each pixel (log units).
        valid: same shape, bool: pixels whose count is trusted (not censored, not hot).
        channel, channels, sigma: as :func:`lowpass_maps`.
        theta: a typical threshold (log units) that turns the distance into count units, the
            units of the band loss it is added to.
        min_support: places where a channel's valid pixels hold less Gaussian weight than this
            share of a fully valid neighbourhood of that channel are left out.
        support: :func:`full_support` of these arguments, when the caller keeps it (it depends
            only on the sensor); computed here when None.

    Returns:
        Scalar: the mean over windows of the support-weighted mean over pixels and channels of
        ``|LP(delta_pred) - LP(target)| / theta`` (count units); a window with no supported
        place adds 0.
    """
    if delta_pred.ndim == 2:
        delta_pred, target, valid = delta_pred[None], target[None], valid[None]
    masks = _channel_masks(valid, channel, channels).to(delta_pred.dtype)  # [B, C, H, W]
    b, c = masks.shape[:2]
    blurred = gaussian_blur(torch.cat([(masks * (delta_pred - target)[:, None]).flatten(0, 1),
                                       masks.flatten(0, 1)]), sigma).reshape(2, b, c, *masks.shape[2:])
    num, den = blurred[0], blurred[1].detach()
    if support is None:
        support = full_support(channel, channels, sigma, *valid.shape[-2:], valid.device, den.dtype)
    w = den * (den >= min_support * support.to(den.dtype))
    # no host read of the totals (a GPU would wait): an empty support gives 0 / eps = 0
    per = (w * (num / den.clamp_min(1e-6)).abs()).sum((1, 2, 3)) / w.sum((1, 2, 3)).clamp_min(1e-12)
    return per.mean() / theta
