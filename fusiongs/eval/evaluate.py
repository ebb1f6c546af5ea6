"""Metrics of a run against truth, per view and mean, for fusiongs beside its baselines (METHOD §8)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from fusiongs.eval.metrics import image_metrics


def compare_methods(methods: Mapping[str, Mapping[str, np.ndarray]], gt: Mapping[str, np.ndarray],
                    *, affine: bool = False) -> dict:
    """PSNR / SSIM of each method's images against truth, grouped by view kind.

    Args:
        methods: ``{method: {view name: sRGB [H, W, 3]}}``; a method may lack some views.
        gt: ``{view name: sRGB [H, W, 3]}``.
        affine: also apply the per-channel affine fit (event-only results; EventNeRF's protocol).

    Returns:
        ``{"views": {name: {method: {"psnr", "ssim"}}}, "mean": {group: {method: {...}}}}`` where
        group is ``"deblur"`` (names ``deblur_*``), ``"novel"`` (``novel_*``) or ``"other"``.
    """
    views: dict[str, dict[str, dict[str, float]]] = {}
    for name, truth in sorted(gt.items()):
        row = {}
        for method, imgs in methods.items():
            if name in imgs:
                row[method] = image_metrics(imgs[name], truth, affine=affine)
        if row:
            views[name] = row
    groups: dict[str, dict[str, list[dict[str, float]]]] = {}
    for name, row in views.items():
        g = "deblur" if name.startswith("deblur_") else "novel" if name.startswith("novel_") else "other"
        for method, m in row.items():
            groups.setdefault(g, {}).setdefault(method, []).append(m)
    mean = {g: {method: {k: _mean([m[k] for m in ms]) for k in ("psnr", "ssim")} | {"n": len(ms)}
                for method, ms in by.items()} for g, by in groups.items()}
    return {"views": views, "mean": mean, "affine": affine}


def _mean(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def format_table(result: dict) -> str:
    """The mean table as text: one line per (group, method)."""
    w = max([10] + [len(m) + 2 for by in result["mean"].values() for m in by])
    lines = [f"{'views':<8}{'method':<{w}}{'n':>4}{'PSNR':>9}{'SSIM':>8}"]
    for g, by in result["mean"].items():
        for method, m in by.items():
            lines.append(f"{g:<8}{method:<{w}}{m['n']:>4}{m['psnr']:>9.2f}{m['ssim']:>8.3f}")
    return "\n".join(lines)
