"""Differentiable Gaussian splatting: ``rasterize`` (backends torch / cpu / gsplat) and SH helpers."""

from fusiongs.render.rasterize import RenderMeta, rasterize
from fusiongs.render.sh import eval_sh, rgb_to_sh, sh_to_rgb

__all__ = ["RenderMeta", "eval_sh", "rasterize", "rgb_to_sh", "sh_to_rgb"]
