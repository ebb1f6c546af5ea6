"""gsplat backend (CUDA): maps ``rasterize`` onto ``gsplat.rasterization`` (gsplat 1.5.3).

gsplat is imported lazily and only for CUDA tensors; it is an optional dependency (extra "gpu").
"""

from __future__ import annotations

from torch import Tensor

from fusiongs.errors import InputError, MissingDependencyError


def gsplat_available() -> bool:
    """True when ``import gsplat`` succeeds."""
    try:
        import gsplat  # noqa: F401
    except ImportError:
        return False
    return True


def rasterize_gsplat(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
                     viewmats: Tensor, Ks: Tensor, width: int, height: int, *, sh_degree: int | None,
                     backgrounds: Tensor | None, near_plane: float, far_plane: float,
                     eps2d: float) -> tuple[Tensor, Tensor, dict]:
    """Render with ``gsplat.rasterization`` (packed=False, classic, RGB); same contract as rasterize.

    Returns:
        ``(images [C,H,W,D], alphas [C,H,W,1], fields)`` where ``fields`` holds means2d, radii,
        depths, conics, opacities and colors for :class:`fusiongs.render.RenderMeta`.
    """
    if means.device.type != "cuda":
        raise InputError("rasterize", "backend", "'gsplat' only with CUDA tensors", str(means.device))
    try:
        from gsplat import rasterization
    except ImportError as exc:
        raise MissingDependencyError("gsplat", "the gsplat rendering backend", extra="gpu") from exc
    images, alphas, meta = rasterization(
        means, quats, scales, opacities, colors, viewmats, Ks, width, height,
        near_plane=near_plane, far_plane=far_plane, eps2d=eps2d, sh_degree=sh_degree, packed=False,
        backgrounds=backgrounds, render_mode="RGB", rasterize_mode="classic")
    fields = {k: meta[k] for k in ("means2d", "radii", "depths", "conics", "opacities")}
    fields["colors"] = meta.get("colors", colors)
    return images, alphas, fields
