"""The exposure ratio carried by the scene's motion: detail the model lacks, deblurred with its blur.

:mod:`fusiongs.outputs.exposure_ratio` writes the true sharp image as the render times a factor
``ρ(x)`` that stays at the pixel over the exposure. But what the model lacks (fine texture, small
colour errors) is on the scene's surfaces, and moves across the pixels with them: during the
exposure, pixel ``x`` at ``t_k`` sees the surface point that the mid-exposure camera sees at
``u_k(x)`` (the fitted depth and camera path, :func:`fusiongs.camera.reproject.reference_grid`).
So the exposure model (docs/method.md §1) with the missing factor attached to the surfaces is

    B(x) = g · mean_k R_k(x) · ρ(u_k(x))        (linear light; ρ on the mid-exposure pixel grid)

linear in ``ρ``: a known, spatially varying blur ``A`` (the fitted motion) weighted by the renders.
It is solved for ``ρ >= 0`` with Richardson–Lucy iterations (Richardson, JOSA 1972; Lucy, AJ 1974),
started from ``ρ = 1``:

    ρ ← ρ · Aᵀ[(B + ε) / (A ρ + ε)] / Aᵀ 1

With ``u_k`` the identity, one iteration is the per-pixel ratio ``(B + ε) / (B̂ + ε)``; with the
motion, the first iteration spreads the frame's residual along the blur paths and the next ones
sharpen it. Few iterations are taken on purpose (early stopping regularises; the count was chosen on
tuning seeds). The sharp image at an instant ``t`` of the exposure
is ``R(t)(x) · ρ(u_t(x))``. ``Aᵀ`` is the exact adjoint, taken by automatic differentiation of ``A``.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F

from fusiongs.losses.event import to_grey


def carry(rho: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """``ρ`` read where each view's pixels see the reference view's surfaces.

    Args:
        rho: ``[H, W, C]`` factor on the reference (mid-exposure) pixel grid.
        grid: ``[T, H, W, 2]`` :func:`~fusiongs.camera.reproject.reference_grid` output.

    Returns:
        ``[T, H, W, C]`` (bilinear; beyond the image the border value).
    """
    t = grid.shape[0]
    src = rho.permute(2, 0, 1)[None].expand(t, *rho.shape[2:], *rho.shape[:2])
    out = F.grid_sample(src, grid.to(rho.dtype), mode="bilinear", padding_mode="border", align_corners=False)
    return out.permute(0, 2, 3, 1)


def blur_operator(renders: torch.Tensor, grid: torch.Tensor, gain: torch.Tensor | float,
                  channels: int, grey_weights: tuple[float, float, float]
                  ) -> Callable[[torch.Tensor], torch.Tensor]:
    """``A``: the blurry frame a factor ``ρ`` on the reference grid gives.

    Args:
        renders: ``[n, H, W, 3]`` linear renders at the exposure's instants.
        grid: ``[n, H, W, 2]`` where each instant's pixels see the reference grid.
        gain: the frame's exposure gain ``g`` (a number or a 0-d tensor).
        channels: the frame's channels ``C`` (1: a monochrome frame ``w · L``, ρ then scales all
            three colours; 3: RGB).
        grey_weights: ``w`` of a monochrome frame.

    Returns:
        ``A(ρ [H, W, C]) -> [H, W, C]`` (linear in ρ).
    """
    def apply(rho: torch.Tensor) -> torch.Tensor:
        seen = carry(rho, grid)                                   # [n, H, W, C]
        pred = (renders * seen.expand(*seen.shape[:3], 3)).mean(0) * gain
        return to_grey(pred, grey_weights) if channels == 1 else pred
    return apply


def adjoint(op: Callable[[torch.Tensor], torch.Tensor], y: torch.Tensor) -> torch.Tensor:
    """``Aᵀ y`` of a linear ``op`` (``[H, W, C] -> [H, W, C]``), by differentiating ``<op(ρ), y>``."""
    with torch.enable_grad():
        rho = torch.ones_like(y, requires_grad=True)
        (out,) = torch.autograd.grad((op(rho) * y).sum(), rho)
    return out


@torch.no_grad()
def motion_ratio(observed: torch.Tensor, renders: torch.Tensor, grid: torch.Tensor,
                 gain: torch.Tensor | float, saturated: torch.Tensor, eps: float, iterations: int,
                 grey_weights: tuple[float, float, float]) -> torch.Tensor:
    """Factor ``ρ`` on the mid-exposure grid that makes the blurred, motion-carried renders the frame.

    Args:
        observed: ``[H, W, C]`` the captured frame, linear (C = 1 or 3).
        renders: ``[n, H, W, 3]`` linear renders at the exposure's instants, same device.
        grid: ``[n, H, W, 2]`` :func:`~fusiongs.camera.reproject.reference_grid` of those instants
            against the mid-exposure camera.
        gain: the frame's exposure gain ``g``.
        saturated: ``[H, W, C]`` bool, clipped frame pixels (they push ρ neither way).
        eps: the ratio's linear offset ``ε`` > 0.
        iterations: Richardson–Lucy iterations (>= 1).
        grey_weights: ``w`` of a monochrome frame.

    Returns:
        ``[H, W, C]`` ρ (> 0 where the frame is; 1 where no pixel's blur path reaches).
    """
    c = observed.shape[-1]
    op = blur_operator(renders, grid, gain, c, grey_weights)
    norm = adjoint(op, torch.ones_like(observed))
    reached = norm > 1e-8 * norm.max().clamp_min(1e-30)
    target = observed.clamp_min(0) + eps
    rho = torch.ones_like(observed)
    for _ in range(iterations):
        with torch.enable_grad():  # A ρ and Aᵀ of the ratio from one forward pass (A is linear)
            at = rho.detach().requires_grad_(True)
            pred = op(at)
            ratio = target / (pred.detach().clamp_min(0) + eps)
            ratio = torch.where(saturated, torch.ones_like(ratio), ratio)
            (back,) = torch.autograd.grad((pred * ratio).sum(), at)
        rho = torch.where(reached, rho * back / norm.clamp_min(1e-30), rho)
    return rho
