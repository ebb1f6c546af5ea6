"""Optional image priors: EDI-deblurred frames and HPF intensity images (docs/method.md section 3).

- EDI prior: the mid-exposure render should look like the EDI-deblurred frame (Pan et al., CVPR
  2019), used early in training (as DiET-GS and E2NeRF use event-deblurred images).
- Intensity prior ``l_i`` of Event-3DGS (Han et al., NeurIPS 2024) for event-only mode: an L1 to an
  intensity image reconstructed from the events by the high-pass filter (Scheerlinck et al., ACCV
  2018). Such an image is a *log* image known only up to an offset per channel (the integration
  constant; equivalently an unknown gain in linear light), so the loss compares log renders with it
  after fitting that offset.
"""

from __future__ import annotations

import kornia
import torch

from fusiongs.errors import InputError
from fusiongs.losses.blur import apply_response
from fusiongs.losses.event_lowpass import gaussian_blur


def _check_pair(where: str, a: torch.Tensor, b: torch.Tensor) -> None:
    if a.shape != b.shape or a.ndim < 3:
        raise InputError(where, "render/target", "equal shapes [..., H, W, C]",
                         f"{tuple(a.shape)} and {tuple(b.shape)}")


def edi_prior_loss(
    render_mid: torch.Tensor,
    edi_image: torch.Tensor,
    response: str = "srgb",
    valid: torch.Tensor | None = None,
) -> torch.Tensor:
    """L1 between the mid-exposure render and the EDI-deblurred frame, in an encoded space.

    Both inputs are linear; both are encoded with ``response`` (sRGB by default, the space of the
    blur loss, so dark regions are not drowned by bright ones) before the L1. Pass
    ``response="linear"`` for an L1 in linear light.

    Args:
        render_mid: ``[..., H, W, C]`` linear render at mid-exposure.
        edi_image: ``[..., H, W, C]`` linear EDI estimate of the same frame (no gradient needed).
        response: encoding applied to both before the L1.
        valid: optional ``[..., H, W, C]`` (or broadcastable) bool mask of usable EDI pixels.

    Returns:
        Scalar mean absolute difference over (valid) pixels.
    """
    _check_pair("edi_prior_loss", render_mid, edi_image)
    diff = (apply_response(render_mid, response) - apply_response(edi_image, response)).abs()
    if valid is None:
        return diff.mean()
    m = valid.to(diff.dtype).expand_as(diff)
    return (diff * m).sum() / m.sum().clamp(min=1.0)


def intensity_prior_loss(
    render: torch.Tensor, hpf_log_image: torch.Tensor, eps: float = 1e-3, highpass: float = 0.0
) -> torch.Tensor:
    """Event-3DGS intensity loss ``l_i``: L1 in log space up to a fitted per-channel offset.

    ``mean |log(L + eps) + b_c - J|`` where ``J`` is the HPF log image and ``b_c`` the per-image,
    per-channel median of ``J - log(L + eps)``, the offset minimising the L1 (held without
    gradient: at the minimum the loss is flat in ``b_c``).

    With ``highpass = s > 0`` only the image's fine scales are compared: ``mean |r - G_s * r|``
    for the residual ``r = J - log(L + eps)``, with ``G_s * r`` its normalised-convolution
    Gaussian low-pass of ``s`` pixels (zero weight outside the image, so a constant, and with it
    the offset ``b_c``, is removed exactly up to the border). The HPF image's large scales are the
    leaky integrator's weakest (it forgets slow, large changes), and the events' long windows say
    more about them (:mod:`fusiongs.losses.event_lowpass`).

    Args:
        render: ``[..., H, W, C]`` linear render at the image's time.
        hpf_log_image: ``[..., H, W, C]`` HPF intensity image in natural-log units (any offset).
        eps: log offset, as in the event losses.
        highpass: the Gaussian's standard deviation (pixels), 0 for the whole image.

    Returns:
        Scalar loss in log units.
    """
    _check_pair("intensity_prior_loss", render, hpf_log_image)
    log_r = torch.log(render + eps)
    resid = hpf_log_image - log_r
    if highpass > 0:
        h, w, c = resid.shape[-3:]
        maps = resid.reshape(-1, h, w, c).permute(0, 3, 1, 2).reshape(-1, h, w)  # [N C, H, W]
        low = gaussian_blur(maps, highpass) / gaussian_blur(torch.ones_like(maps[:1]), highpass)
        return (maps - low).abs().mean()
    flat = resid.detach().flatten(-3, -2)  # [..., H*W, C]
    offset = flat.median(dim=-2).values[..., None, None, :]  # [..., 1, 1, C]
    return (log_r + offset - hpf_log_image).abs().mean()


def total_variation_prior(render: torch.Tensor, space: str = "log", eps: float = 1e-3) -> torch.Tensor:
    """Anisotropic total variation of renders: ``mean |∂x f(L)| + mean |∂y f(L)|`` per channel.

    Event-only reconstruction leaves whatever does not change along the camera's motion unobserved
    (texture parallel to the motion, the levels of plain areas). Variational intensity reconstruction
    from events fills that null space with the image of least total variation of the log intensity
    (Bardow et al., CVPR 2016; Munda et al., IJCV 2018); this prior does the same for the renders.

    Args:
        render: ``[..., H, W, C]`` linear renders.
        space: ``"log"`` for ``f(L) = log(L + eps)`` (the events' space), ``"srgb"`` for the sRGB
            encoding of ``L`` clipped to ``[0, 1]`` (the space the results are scored in).
        eps: log offset, as in the event losses.

    Returns:
        Scalar: the two axes' mean absolute differences, added, averaged over images and channels.
    """
    if render.ndim < 3:
        raise InputError("total_variation_prior", "render", "[..., H, W, C]", f"{tuple(render.shape)}")
    if space == "log":
        f = torch.log(render.clamp_min(0) + eps)
    elif space == "srgb":
        f = apply_response(render.clamp(0, 1), "srgb")
    else:
        raise InputError("total_variation_prior", "space", "'log' or 'srgb'", repr(space))
    return kornia.losses.total_variation(f.movedim(-1, -3), reduction="mean").mean()


def smooth_log_gradient(grad: torch.Tensor, render: torch.Tensor, sigma: float, weight: float,
                        eps: float = 1e-3) -> torch.Tensor:
    """A render's gradient with its spatially smoothed copy added, in log intensity (a Sobolev-type
    preconditioner: the steps of plain areas follow the changes their edges ask for).

    ``g' = g + weight · (G_σ * (g · (L + eps))) / (L + eps)``: the gradient with respect to
    ``log(L + eps)`` is ``g · (L + eps)``; its Gaussian low-pass (zeros outside the image) is added
    back in linear units. The objective is unchanged; only the descent direction is (Sundaramoorthi
    et al., "Sobolev active contours", IJCV 2007, for the idea of a smoothed gradient flow).

    Args:
        grad: ``[..., H, W, C]`` gradient of the loss with respect to the linear renders.
        render: ``[..., H, W, C]`` the linear renders (values, no gradient needed).
        sigma: the Gaussian's standard deviation (pixels, > 0).
        weight: how much of the smoothed copy is added.
        eps: log offset, as in the event losses.

    Returns:
        ``[..., H, W, C]`` the new gradient.
    """
    _check_pair("smooth_log_gradient", grad, render)
    scale = render.detach().clamp_min(0) + eps
    g_log = grad * scale
    h, w, c = g_log.shape[-3:]
    maps = g_log.reshape(-1, h, w, c).movedim(-1, 1).reshape(-1, h, w)  # [N C, H, W]
    low = gaussian_blur(maps, sigma).reshape(-1, c, h, w).movedim(1, -1).reshape(g_log.shape)
    return grad + weight * low / scale
