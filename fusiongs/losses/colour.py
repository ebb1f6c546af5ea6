"""Colour events: CFA layouts, a differentiable bilinear demosaic of float maps, channel weights.

A colour event sensor (Color-DAVIS346) has a 2x2 Bayer colour filter: each pixel measures the log
change of one channel. Two ways to use it (docs/method.md section 1):

- *mask* (EventNeRF, Rudnev et al., CVPR 2023; EvDeblurNeRF, Cannici & Scaramuzza, CVPR 2024):
  compare each pixel's own CFA channel of the rendered log change (see
  :func:`fusiongs.losses.event.select_channel`);
- *demosaic* (Event-3DGS appendix C, Han et al., NeurIPS 2024): demosaic the per-window signed event
  maps (counts or HPF contrast) into three-channel targets, :func:`demosaic_event_maps`.

Layout names give the top-left 2x2 cells in row-major order: ``RGGB`` = R at (even row, even
column), G at (even, odd) and (odd, even), B at (odd, odd) (OpenCV ``COLOR_BayerRGGB2*``, kornia
``CFA.BG``). Channel indices are 0 = R, 1 = G, 2 = B.
"""

from __future__ import annotations

import torch

from fusiongs.errors import InputError
from fusiongs.events.cfa import cfa_channel_index, demosaic

#: Channel weights (R, G, B) of the colour event losses: the two greens of a Bayer cell count once.
DEFAULT_CHANNEL_WEIGHTS = (0.4, 0.2, 0.4)


def cfa_index(pattern: str, height: int, width: int, device: torch.device | None = None) -> torch.Tensor:
    """Channel index of every pixel of a Bayer mosaic, as a tensor.

    A tensor view of :func:`fusiongs.events.cfa.cfa_channel_index` (the one definition of the
    layouts).

    Args:
        pattern: ``"RGGB"``, ``"BGGR"``, ``"GRBG"`` or ``"GBRG"``.
        height, width: sensor size in pixels.
        device: device of the result.

    Returns:
        ``[H, W]`` int64 channel index (0 = R, 1 = G, 2 = B).
    """
    return torch.from_numpy(cfa_channel_index(pattern, height, width)).to(device=device, dtype=torch.int64)


def bilinear_demosaic(mosaic: torch.Tensor, pattern: str) -> torch.Tensor:
    """Bilinear demosaic of float Bayer mosaics (differentiable, any sign).

    The torch path of :func:`fusiongs.events.cfa.demosaic` (``method="bilinear"``), channels
    first. Each channel's samples are spread with the standard bilinear kernels (``[1 2 1]/4`` outer
    product for R and B, the cross ``[0 1 0; 1 4 1; 0 1 0]/4`` for G) as a *normalised*
    convolution ``conv(m * x) / conv(m)`` with zero padding. In the interior ``conv(m)`` is 1, so
    it equals the classic bilinear demosaic (measured samples kept, constants and linear ramps
    reproduced exactly); at the border it averages the neighbours that exist, so constants stay
    exact everywhere.

    Args:
        mosaic: ``[..., H, W]`` float mosaic on the raw grid (e.g. signed event counts).
        pattern: CFA layout (see :func:`cfa_index`).

    Returns:
        ``[..., 3, H, W]`` RGB maps, same dtype and device.
    """
    if mosaic.ndim < 2 or not mosaic.is_floating_point():
        raise InputError("bilinear_demosaic", "mosaic", "a float tensor [..., H, W]", mosaic.dtype)
    return demosaic(mosaic, pattern, "bilinear").movedim(-1, -3)


def demosaic_event_maps(signed_maps: torch.Tensor, pattern: str) -> torch.Tensor:
    """Three-channel contrast targets from per-window signed event maps (Event-3DGS app. C).

    Args:
        signed_maps: ``[..., H, W]`` float signed maps on the raw grid, one per window (signed
            event counts ``n+ - n-``, or HPF contrast ``D_gt``, in count units).
        pattern: CFA layout of the event sensor.

    Returns:
        ``[..., H, W, 3]`` channels-last targets in the same units; flatten ``H, W`` and index
        with the sampled flat pixel indices to get ``[P, 3]`` loss targets.
    """
    return bilinear_demosaic(signed_maps, pattern).movedim(-3, -1)


def channel_weights_for(
    channel_index: torch.Tensor, weights: tuple[float, ...] = DEFAULT_CHANNEL_WEIGHTS
) -> torch.Tensor:
    """Per-pixel weights of mask-mode colour losses: each pixel gets its CFA channel's weight.

    Args:
        channel_index: ``[P]`` int64 channel of each sampled pixel.
        weights: weight per channel (R, G, B).

    Returns:
        ``[P, 1]`` weights (float32 on the index's device).
    """
    # made on the host and copied without waiting (torch.tensor(..., device=cuda) would wait for
    # the queued GPU work)
    w = torch.tensor(weights, dtype=torch.float32, device="cpu").to(channel_index.device, non_blocking=True)
    return w[channel_index][:, None]
