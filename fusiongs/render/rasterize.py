"""``rasterize``: the differentiable Gaussian splatting entry point (gsplat 1.5.3 semantics).

3D Gaussian Splatting (Kerbl et al., SIGGRAPH 2023): EWA projection (Zwicker et al. 2001) and
front-to-back alpha compositing, with gsplat 1.5.3's ``rasterization`` conventions (packed=False,
classic mode, no antialiasing), so that the backends are interchangeable.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import torch
from torch import Tensor

from fusiongs.errors import InputError
from fusiongs.render._checks import WHERE, check_inputs
from fusiongs.render.projection import project_gaussians
from fusiongs.render.sh import eval_sh


@dataclass
class RenderMeta:
    """Per-camera intermediate results of :func:`rasterize` (also readable as ``meta["key"]``).

    Attributes:
        means2d: ``[C, N, 2]`` projected centres in pixels (zero for culled Gaussians). When it
            requires grad, ``retain_grad()`` has been called on it, so after ``backward()``
            ``meta.means2d.grad`` holds the screen-space gradient that densification reads.
        radii: ``[C, N, 2]`` int32 screen half-extents (x, y) in pixels; 0 = culled.
        depths: ``[C, N]`` camera-space z (0 for culled Gaussians).
        conics: ``[C, N, 3]`` inverse 2D covariance (a, b, c) of ``[[a, b], [b, c]]``.
        opacities: ``[C, N]`` opacities per camera.
        colors: ``[C, N, D]`` colours used (after SH evaluation, +0.5 and clamp at 0).
        width, height: image size. n_cameras: C. backend: the backend that rendered.
    """

    means2d: Tensor
    radii: Tensor
    depths: Tensor
    conics: Tensor
    opacities: Tensor
    colors: Tensor
    width: int
    height: int
    n_cameras: int
    backend: str

    def __getitem__(self, key: str):
        if key not in {f.name for f in fields(self)}:
            raise KeyError(key)
        return getattr(self, key)

    def keys(self) -> list[str]:
        return [f.name for f in fields(self)]


def _pick_backend(backend: str, device: torch.device) -> str:
    if backend != "auto":
        return backend
    if device.type == "cpu":
        return "cpu"
    if device.type == "cuda":
        from fusiongs.render.gsplat_backend import gsplat_available

        if gsplat_available():
            return "gsplat"
    return "torch"


def camera_colors(means: Tensor, colors: Tensor, viewmats: Tensor, sh_degree: int | None) -> Tensor:
    """Per-camera colours ``[C, N, D]``: as given, or SH evaluated toward each camera centre.

    SH colours follow gsplat: view direction = mean - camera centre (camera centre from the inverse
    view matrix), value + 0.5, clamped at 0.
    """
    C, N = viewmats.shape[0], means.shape[0]
    if sh_degree is None:
        return colors.expand(C, N, colors.shape[-1]) if colors.dim() == 2 else colors
    campos = torch.linalg.inv(viewmats)[:, :3, 3]  # [C, 3]
    dirs = means[None, :, :] - campos[:, None, :]
    return torch.clamp_min(eval_sh(sh_degree, dirs, colors[None]) + 0.5, 0.0)


def rasterize(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
              viewmats: Tensor, Ks: Tensor, width: int, height: int, *, sh_degree: int | None = None,
              backgrounds: Tensor | None = None, near_plane: float = 0.01, far_plane: float = 1e10,
              eps2d: float = 0.3, backend: str = "auto", check_values: bool = True
              ) -> tuple[Tensor, Tensor, RenderMeta]:
    """Render N 3D Gaussians into C pinhole cameras, differentiably.

    Args:
        means: ``[N, 3]`` world centres. quats: ``[N, 4]`` rotations, wxyz, any norm.
        scales: ``[N, 3]`` activated standard deviations (world units).
        opacities: ``[N]`` activated opacities in [0, 1].
        colors: ``[N, D]`` or ``[C, N, D]`` colours, or SH coefficients ``[N, K, 3]`` when
            ``sh_degree`` is given (``K >= (sh_degree + 1)**2``).
        viewmats: ``[C, 4, 4]`` world->camera transforms. Ks: ``[C, 3, 3]`` intrinsics (px).
        width, height: image size in pixels (pixel centres at +0.5).
        sh_degree: SH degree 0..3 to evaluate, or None for plain colours.
        backgrounds: optional ``[C, D]`` colour added with the remaining transmittance.
        near_plane, far_plane: Gaussians with camera depth outside this range are culled.
        eps2d: added to the 2D covariance diagonal (px²).
        backend: "torch" (pure torch, CPU or CUDA), "cpu" (numba kernels, CPU tensors), "gsplat"
            (CUDA, needs gsplat 1.5.3) or "auto" (gsplat for CUDA tensors when importable, "cpu"
            for CPU tensors, else "torch").
        check_values: check that the tensors hold finite values, opacities in [0, 1] and non-zero
            quaternions; each check reads the values, a host synchronisation on a GPU (the training
            loop, which renders its own parameters, turns them off).

    Returns:
        ``(images [C, H, W, D], alphas [C, H, W, 1], meta)`` with :class:`RenderMeta`.

    Raises:
        InputError: wrong shapes, mismatched N or C, non-finite values, bad sizes or backend.
        MissingDependencyError: backend "gsplat" without gsplat installed.
    """
    C, N, D = check_inputs(means, quats, scales, opacities, colors, viewmats, Ks, width, height,
                           sh_degree, backgrounds, near_plane, far_plane, backend, check_values)
    chosen = _pick_backend(backend, means.device)
    if chosen == "gsplat":
        from fusiongs.render.gsplat_backend import rasterize_gsplat

        images, alphas, m = rasterize_gsplat(means, quats, scales, opacities, colors, viewmats, Ks,
                                             width, height, sh_degree=sh_degree,
                                             backgrounds=backgrounds, near_plane=near_plane,
                                             far_plane=far_plane, eps2d=eps2d)
        return images, alphas, RenderMeta(**m, width=width, height=height, n_cameras=C,
                                          backend="gsplat")
    if chosen == "cpu" and means.device.type != "cpu":
        raise InputError(WHERE, "backend", "'cpu' only with CPU tensors (use 'torch' or 'gsplat')",
                         str(means.device))
    if chosen == "cpu":  # numba kernels both ways (the projection in float64, same values up to rounding)
        from fusiongs.render.cpu import composite_cpu as composite
        from fusiongs.render.cpu import project_cpu as project
    else:
        from fusiongs.render.pairs import composite_pairs as composite

        project = project_gaussians
    proj = project(means, quats, scales, opacities, viewmats, Ks, width, height, near_plane, far_plane, eps2d)
    if proj.means2d.requires_grad:
        proj.means2d.retain_grad()
    cols = camera_colors(means, colors, viewmats, sh_degree)
    images, alphas = composite(proj, cols, width, height)
    if backgrounds is not None:
        images = images + (1.0 - alphas) * backgrounds[:, None, None, :]
    meta = RenderMeta(means2d=proj.means2d, radii=proj.radii, depths=proj.depths, conics=proj.conics,
                      opacities=proj.opacities, colors=cols, width=width, height=height, n_cameras=C,
                      backend=chosen)
    return images, alphas, meta
