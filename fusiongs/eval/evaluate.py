"""Metrics of a run against truth, per view and mean, for fusiongs beside its baselines (METHOD §8)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from fusiongs.eval.metrics import global_affine_fit, image_metrics

METRIC_KEYS = ("psnr", "ssim", "delta_e00")


def compare_methods(methods: Mapping[str, Mapping[str, np.ndarray]], gt: Mapping[str, np.ndarray],
                    *, affine: bool = False, delta_e: bool | None = None) -> dict:
    """PSNR / SSIM (and ΔE00) of each method's images against truth, grouped by view kind.

    Args:
        methods: ``{method: {view name: sRGB [H, W, 3]}}``; a method may lack some views.
        gt: ``{view name: sRGB [H, W, 3]}``.
        affine: also apply the per-channel affine fit (event-only results; EventNeRF's protocol).
        delta_e: add the mean CIEDE2000 colour error ``"delta_e00"``; default: with ``affine``.

    Returns:
        ``{"views": {name: {method: {"psnr", "ssim"[, "delta_e00"]}}}, "mean": {group: {method:
        {...}}}}`` where group is ``"deblur"`` (names ``deblur_*``), ``"novel"`` (``novel_*``) or
        ``"other"``.
    """
    views: dict[str, dict[str, dict[str, float]]] = {}
    for name, truth in sorted(gt.items()):
        row = {}
        for method, imgs in methods.items():
            if name in imgs:
                row[method] = image_metrics(imgs[name], truth, affine=affine, delta_e=delta_e)
        if row:
            views[name] = row
    groups: dict[str, dict[str, list[dict[str, float]]]] = {}
    for name, row in views.items():
        g = "deblur" if name.startswith("deblur_") else "novel" if name.startswith("novel_") else "other"
        for method, m in row.items():
            groups.setdefault(g, {}).setdefault(method, []).append(m)
    mean = {g: {method: {k: _mean([m[k] for m in ms]) for k in METRIC_KEYS if k in ms[0]} | {"n": len(ms)}
                for method, ms in by.items()} for g, by in groups.items()}
    return {"views": views, "mean": mean, "affine": affine}


def compare_global_affine(methods: Mapping[str, Mapping[str, np.ndarray]],
                          gt: Mapping[str, np.ndarray]) -> dict:
    """Like :func:`compare_methods` with ``affine=True``, but each method's views of one group
    (``deblur_*``, ``novel_*``, other) share one per-channel affine fit
    (:func:`fusiongs.eval.metrics.global_affine_fit`, the protocol of EventNeRF and Robust e-NeRF).

    Returns:
        ``{"mean": {group: {method: {"psnr", "ssim", "delta_e00", "n"}}}, "affine": "global"}``.
    """
    mean: dict[str, dict[str, dict[str, float]]] = {}
    for method, imgs in methods.items():
        by_group: dict[str, list[str]] = {}
        for name in sorted(gt):
            if name in imgs:
                by_group.setdefault(_group(name), []).append(name)
        for g, names in by_group.items():
            fitted = global_affine_fit([imgs[n] for n in names], [gt[n] for n in names])
            ms = [image_metrics(f, gt[n], delta_e=True) for f, n in zip(fitted, names)]
            means = {k: _mean([m[k] for m in ms]) for k in METRIC_KEYS}
            mean.setdefault(g, {})[method] = means | {"n": len(ms)}
    return {"mean": mean, "affine": "global"}


def _group(name: str) -> str:
    """The view group of a truth image's name: ``deblur``, ``novel`` or ``other``."""
    return "deblur" if name.startswith("deblur_") else "novel" if name.startswith("novel_") else "other"


def _mean(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def format_table(result: dict) -> str:
    """The mean table as text: one line per (group, method); a ΔE00 column when measured."""
    w = max([10] + [len(m) + 2 for by in result["mean"].values() for m in by])
    de = any("delta_e00" in m for by in result["mean"].values() for m in by.values())
    lines = [f"{'views':<8}{'method':<{w}}{'n':>4}{'PSNR':>9}{'SSIM':>8}" + (f"{'dE00':>8}" if de else "")]
    for g, by in result["mean"].items():
        for method, m in by.items():
            lines.append(f"{g:<8}{method:<{w}}{m['n']:>4}{m['psnr']:>9.2f}{m['ssim']:>8.3f}"
                         + (f"{m.get('delta_e00', float('nan')):>8.2f}" if de else ""))
    return "\n".join(lines)


def colour_metrics(methods: Mapping[str, Mapping[str, np.ndarray]], gt: Mapping[str, np.ndarray],
                   anchor, unanchored: Mapping[str, np.ndarray] | None = None) -> dict:
    """What ``metrics.json`` adds for a run whose colours the events alone do not fix.

    Args:
        methods: as :func:`compare_methods` (``"fusiongs"`` with ``anchor`` applied).
        gt: truth images.
        anchor: the run's :class:`fusiongs.outputs.colour_anchor.ColourAnchor`.
        unanchored: fusiongs' images before the anchor (used when the anchor is applied).

    Returns:
        ``{"affine_fit": ..., "global_affine_fit": ..., "colour_anchor": {...}}``: the metrics after
        the per-channel affine fit of each image (PSNR, SSIM, ΔE00), after one fit per channel over
        all views of a group (:func:`compare_global_affine`), and the anchor (kind, label, gains)
        with, when applied, ``"before"``: fusiongs' raw metrics without it (what the anchor changed).
    """
    doc = anchor.as_dict()
    if anchor.applied and unanchored is not None:
        doc["before"] = compare_methods({"fusiongs": unanchored}, gt, delta_e=True)["mean"]
    return {"affine_fit": compare_methods(methods, gt, affine=True),
            "global_affine_fit": compare_global_affine(methods, gt), "colour_anchor": doc}
