"""Exposure-integrated blur model and the blur loss.

A blurry frame ``i`` with exposure ``[s_i, e_i]`` is modelled as
``B_i = CRF(g_i * mean_k L(T(t_k)))`` with ``t_k = s_i + (k + 0.5) / N * (e_i - s_i)``: the sharp
linear renders at N instants are averaged **in linear light**, scaled by an optional per-frame gain
and encoded by the camera response (sRGB by default). This is the physical blur model of
BAD-NeRF / BAD-Gaussians (Wang et al., CVPR 2023; Zhao et al., ECCV 2024) and E2NeRF (Qi et al.,
ICCV 2023); see docs/method.md section 1. The loss is the 3DGS photometric loss
``(1 - lambda) * L1 + lambda * (1 - SSIM)`` (Kerbl et al., SIGGRAPH 2023), lambda = 0.2.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from fusiongs.errors import InputError
from fusiongs.frames.response import linear_to_response
from fusiongs.losses.ssim import ssim_map


def exposure_instants(
    t_start: float | torch.Tensor, t_end: float | torch.Tensor, n: int = 9
) -> torch.Tensor:
    """Instants at which the sharp renders of one exposure are taken (midpoint rule).

    ``t_k = s + (k + 0.5) / n * (e - s)``, k = 0..n-1; for odd ``n`` the middle instant is the
    mid-exposure time.

    Args:
        t_start: exposure start ``s`` in seconds, a float or a tensor ``[...]``.
        t_end: exposure end ``e`` in seconds, same shape as ``t_start``.
        n: number of instants (>= 1; 9 by default).

    Returns:
        ``[..., n]`` instants in seconds (float64 unless ``t_start`` is a float32/16 tensor).
    """
    if int(n) != n or n < 1:
        raise InputError("exposure_instants", "n", "a positive integer", n)
    if isinstance(t_start, torch.Tensor):
        s = t_start if t_start.is_floating_point() else t_start.to(torch.float64)
    else:
        s = torch.tensor(t_start, dtype=torch.float64)
    if isinstance(t_end, torch.Tensor):
        e = t_end.to(device=s.device, dtype=s.dtype)
    else:
        e = torch.tensor(t_end, dtype=s.dtype, device=s.device)
    frac = (torch.arange(n, dtype=s.dtype, device=s.device) + 0.5) / n
    return s[..., None] + frac * (e - s)[..., None]


def exposure_average(renders_linear: torch.Tensor) -> torch.Tensor:
    """Average sharp renders over the exposure, in linear light.

    Args:
        renders_linear: ``[N, H, W, C]`` or ``[B, N, H, W, C]`` linear radiance renders at the N
            exposure instants (unitless, >= 0).

    Returns:
        ``[H, W, C]`` or ``[B, H, W, C]`` mean linear radiance.
    """
    if renders_linear.ndim not in (4, 5):
        raise InputError(
            "exposure_average", "renders_linear", "[N, H, W, C] or [B, N, H, W, C]",
            tuple(renders_linear.shape),
        )
    return renders_linear.mean(dim=-4)


def apply_response(linear: torch.Tensor, response: str = "srgb") -> torch.Tensor:
    """Encode linear irradiance with a camera response curve (differentiable).

    Delegates to :func:`fusiongs.frames.response.linear_to_response` (sRGB of IEC 61966-2-1,
    ``"linear"``, or ``"gamma:G"`` meaning ``value = linear ** (1 / G)``; docs/scene-format.md
    ``frame_response``). Values are not clipped above 1, since clipping would stop the gradients
    of over-bright renders; gradients are finite everywhere, including at 0.

    Args:
        linear: ``[...]`` linear values (1.0 = white).
        response: ``"srgb"``, ``"linear"`` or ``"gamma:G"``.

    Returns:
        ``[...]`` encoded values, same shape and dtype.
    """
    return linear_to_response(linear, response)


def blurry_from_renders(
    renders_linear: torch.Tensor, gain: torch.Tensor | float | None = None, response: str = "srgb"
) -> torch.Tensor:
    """Predicted blurry frame(s) from sharp linear renders over the exposure.

    ``B = CRF(g * mean_k L_k)`` (docs/method.md section 1).

    Args:
        renders_linear: ``[N, H, W, C]`` or ``[B, N, H, W, C]`` linear renders at the instants of
            :func:`exposure_instants`.
        gain: optional per-frame gain ``g``: a float or a tensor ``[]`` for one frame, ``[B]`` for
            a batch (e.g. ``exp`` of a learnable log-gain).
        response: camera response of the frames (see :func:`apply_response`).

    Returns:
        ``[H, W, C]`` or ``[B, H, W, C]`` predicted frame in the frames' response space.
    """
    mean = exposure_average(renders_linear)
    if gain is not None:
        g = torch.as_tensor(gain, dtype=mean.dtype, device=mean.device)
        if g.ndim == 1 and renders_linear.ndim == 5 and g.shape[0] == mean.shape[0]:
            g = g.view(-1, 1, 1, 1)
        elif g.ndim != 0:
            raise InputError(
                "blurry_from_renders", "gain", "a scalar, or [B] for batched renders",
                tuple(g.shape),
            )
        mean = mean * g
    return apply_response(mean, response)


def render_blurry(
    render_fn: Callable[[torch.Tensor], torch.Tensor],
    t_start: float | torch.Tensor,
    t_end: float | torch.Tensor,
    n: int = 9,
    gain: torch.Tensor | float | None = None,
    response: str = "srgb",
) -> torch.Tensor:
    """Render one blurry frame: sharp renders at the exposure instants, averaged, gain, CRF.

    Args:
        render_fn: called once with the instants ``[n]`` (seconds, float64) and returning linear
            renders ``[n, H, W, C]``.
        t_start, t_end: exposure window in seconds.
        n: number of instants.
        gain: optional scalar gain of this frame.
        response: frame response curve.

    Returns:
        ``[H, W, C]`` predicted blurry frame in the response space.
    """
    renders = render_fn(exposure_instants(t_start, t_end, n))
    if renders.ndim != 4 or renders.shape[0] != n:
        raise InputError("render_blurry", "render_fn output", f"[{n}, H, W, C]", tuple(renders.shape))
    return blurry_from_renders(renders, gain, response)


def blur_loss(pred: torch.Tensor, target: torch.Tensor, lam: float = 0.2) -> torch.Tensor:
    """Photometric blur loss ``(1 - lam) * L1 + lam * (1 - SSIM)`` (3DGS, Kerbl et al. 2023).

    SSIM is kornia's map (11x11 gaussian window, sigma 1.5, ``'same'`` padding, ``max_val`` 1),
    computed by :func:`fusiongs.losses.ssim.ssim_map` in a few batched operations, and the term is
    ``1 - mean SSIM`` (not kornia's ``ssim_loss``, which is ``(1 - SSIM) / 2``).

    Args:
        pred: ``[B, H, W, C]`` or ``[H, W, C]`` predicted frame in the frames' response space.
        target: same shape, the observed blurry frame(s) in [0, 1].
        lam: SSIM weight lambda in [0, 1].

    Returns:
        Scalar loss.
    """
    if pred.shape != target.shape or pred.ndim not in (3, 4):
        raise InputError(
            "blur_loss", "pred/target", "equal shapes [B, H, W, C] or [H, W, C]",
            f"{tuple(pred.shape)} and {tuple(target.shape)}",
        )
    l1 = (pred - target).abs().mean()
    if lam == 0:
        return l1
    p = pred if pred.ndim == 4 else pred[None]
    q = target if target.ndim == 4 else target[None]
    s = ssim_map(p.permute(0, 3, 1, 2), q.permute(0, 3, 1, 2), window_size=11, max_val=1.0).mean()
    return (1.0 - lam) * l1 + lam * (1.0 - s)
