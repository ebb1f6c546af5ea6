"""The run report: metrics tables, loss curves and picture strips drawn with OpenCV into one PNG
(with or without truth images)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import cv2
import numpy as np

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_COLOURS = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
            (140, 86, 75)]  # RGB


def _to_u8(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img, dtype=np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[-1] == 1:
        a = np.repeat(a, 3, axis=-1)
    return np.round(np.clip(a, 0, 1) * 255).astype(np.uint8)


def _shrink(img: np.ndarray, max_width: int) -> np.ndarray:
    h, w = img.shape[:2]
    if w <= max_width:
        return img
    return cv2.resize(img, (max_width, max(1, round(h * max_width / w))), interpolation=cv2.INTER_AREA)


def _label(img: np.ndarray, text: str, scale: float = 0.4) -> np.ndarray:
    """Put ``text`` on a white band above an RGB uint8 image."""
    band = np.full((16, img.shape[1], 3), 255, np.uint8)
    cv2.putText(band, text[: max(1, img.shape[1] // 7)], (2, 12), _FONT, scale, (0, 0, 0), 1,
                cv2.LINE_AA)
    return np.concatenate([band, img], axis=0)


def picture_strip(columns: Mapping[str, np.ndarray], max_width: int = 480) -> np.ndarray:
    """Images ``[H, W, C]`` in [0, 1] side by side, each under its name; RGB uint8. Images wider
    than ``max_width`` are shrunk (area averaging) to it: the report is an overview, the outputs
    keep every pixel (an HD sensor's strips were 15 megapixels)."""
    tiles = [_label(_shrink(_to_u8(img), max_width), name) for name, img in columns.items()]
    h = max(t.shape[0] for t in tiles)
    tiles = [np.pad(t, ((0, h - t.shape[0]), (0, 4), (0, 0)), constant_values=255) for t in tiles]
    return np.concatenate(tiles, axis=1)


def line_plot(series: Mapping[str, Sequence[tuple[float, float]]], title: str,
              size: tuple[int, int] = (360, 220), log_y: bool = False) -> np.ndarray:
    """A small line plot of named ``(x, y)`` series; RGB uint8 ``[h, w, 3]``."""
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    left, right, top, bottom = 48, 8, 20, 22
    cv2.putText(img, title, (left, 14), _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    pts = {k: np.asarray(v, dtype=np.float64).reshape(-1, 2) for k, v in series.items() if len(v)}
    if not pts:
        return img
    allp = np.concatenate(list(pts.values()))
    ys = allp[:, 1]
    if log_y:
        ys = np.log10(np.maximum(ys, 1e-12))
    finite = np.isfinite(ys)
    if not finite.any():
        return img
    x0, x1 = allp[:, 0].min(), allp[:, 0].max()
    y0, y1 = ys[finite].min(), ys[finite].max()
    x1 = x1 if x1 > x0 else x0 + 1
    y1 = y1 if y1 > y0 else y0 + 1e-6
    cv2.rectangle(img, (left, top), (w - right, h - bottom), (160, 160, 160), 1)
    for frac in (0.0, 1.0):
        yv = y0 + frac * (y1 - y0)
        txt = f"{10 ** yv:.2g}" if log_y else f"{yv:.3g}"
        yy = int(h - bottom - frac * (h - top - bottom))
        cv2.putText(img, txt, (2, yy + 4), _FONT, 0.3, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"{x0:.0f}", (left, h - 6), _FONT, 0.3, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"{x1:.0f}", (w - right - 30, h - 6), _FONT, 0.3, (0, 0, 0), 1, cv2.LINE_AA)
    for i, (name, p) in enumerate(pts.items()):
        y = np.log10(np.maximum(p[:, 1], 1e-12)) if log_y else p[:, 1]
        ok = np.isfinite(y)
        px = left + (p[ok, 0] - x0) / (x1 - x0) * (w - left - right)
        py = h - bottom - (y[ok] - y0) / (y1 - y0) * (h - top - bottom)
        colour = _COLOURS[i % len(_COLOURS)]
        poly = np.stack([px, py], axis=1).round().astype(np.int32)
        cv2.polylines(img, [poly], False, colour, 1, cv2.LINE_AA)
        cv2.putText(img, name, (left + 4 + 70 * i, top + 12), _FONT, 0.3, colour, 1, cv2.LINE_AA)
    return img


def table_image(rows: Sequence[Sequence[str]], width: int) -> np.ndarray:
    """A plain text table, one line per row; RGB uint8."""
    h = 14 * len(rows) + 6
    img = np.full((h, width, 3), 255, np.uint8)
    for i, row in enumerate(rows):
        line = "".join(f"{cell:<16}" for cell in row)
        cv2.putText(img, line, (4, 14 * (i + 1)), cv2.FONT_HERSHEY_PLAIN, 0.9, (0, 0, 0), 1,
                    cv2.LINE_AA)
    return img


def stack_rows(parts: Sequence[np.ndarray]) -> np.ndarray:
    """Stack RGB uint8 images vertically, padding to the widest."""
    w = max(p.shape[1] for p in parts)
    padded = [np.pad(p, ((0, 4), (0, w - p.shape[1]), (0, 0)), constant_values=255) for p in parts]
    return np.concatenate(padded, axis=0)


def side_by_side(parts: Sequence[np.ndarray]) -> np.ndarray:
    """Place RGB uint8 images left to right, padding to the tallest."""
    h = max(p.shape[0] for p in parts)
    padded = [np.pad(p, ((0, h - p.shape[0]), (0, 4), (0, 0)), constant_values=255) for p in parts]
    return np.concatenate(padded, axis=1)


def metric_rows(result: Mapping) -> list[list[str]]:
    """Rows of the report's table: truth metrics (when ``result`` has them; ΔE00 where measured),
    the colour anchor, held-out PSNR and no-reference sharpness (when present)."""
    rows = []
    tables = [("", result)] + ([(" (affine fit)", result["affine_fit"])] if "affine_fit" in result else [])
    if "mean" in result:
        de = any("delta_e00" in m for _, res in tables for by in res["mean"].values() for m in by.values())
        rows.append(["views", "method", "n", "PSNR", "SSIM"] + (["dE00"] if de else []))
        for suffix, res in tables:
            for g, by in res["mean"].items():
                for method, m in by.items():
                    v = m.get("delta_e00")
                    rows.append([g, method + suffix, str(m["n"]), f"{m['psnr']:.2f}", f"{m['ssim']:.3f}"]
                                + ([f"{v:.2f}" if v is not None else "-"] if de else []))
    if result.get("colour_anchor"):  # which anchor fixed the colours, if any
        rows.append(["colour anchor", result["colour_anchor"]["label"]])
    if result.get("heldout"):
        rows.append(["held-out", "method", "n", "PSNR vs frame", ""])
        for method, m in result["heldout"]["mean"].items():
            v = "-" if m["psnr"] is None else f"{m['psnr']:.2f}"
            rows.append([f"held-out K={result['heldout']['holdout']}", method, str(m["n"]), v, ""])
    if result.get("sharpness"):
        rows.append(["no reference", "method", "n", "Tenengrad", ""])
        for method, m in result["sharpness"].items():
            rows.append(["sharpness", method, str(m["n"]), f"{m['tenengrad']:.4g}", ""])
    return rows


def write_report(path, result: Mapping, history, methods: Mapping[str, Mapping[str, np.ndarray]],
                 gt: Mapping[str, np.ndarray], max_strips: int = 4,
                 heldout: Mapping[str, Mapping[str, np.ndarray]] | None = None) -> None:
    """``report.png``: tables, curves (the loss and each of its terms, θ, and the PSNR against the
    truth while training when it was probed) and picture strips.

    With truth (``gt`` not empty) each strip is ``methods | truth``; without, the first
    ``max_strips`` deblurred frames as ``blurry | edi | fusiongs``. ``heldout``
    (``{frame: {column: image}}``, display values in [0, 1]) adds one strip per held-out frame:
    the predictions beside the real frame.
    """
    from fusiongs.eval.metrics import affine_fit
    from fusiongs.frames.image_io import write_png

    rows = metric_rows(result)
    its = history.iteration
    curves = {"loss": list(zip(its, history.loss))}
    for term in ("blur", "event", "event_lowpass", "edi", "intensity", "tv"):  # each term that was ever on
        values = getattr(history, term)
        if any(np.isfinite(v) for v in values if v is not None):
            curves[term] = [(i, v) for i, v in zip(its, values) if v is not None]
    loss = line_plot(curves, "loss and its terms", log_y=True)
    th = {}
    if history.theta_pos:
        tp, tn = np.asarray(history.theta_pos), np.asarray(history.theta_neg)
        for c in range(tp.shape[1]):
            th[f"theta+{c}"] = list(zip(its, tp[:, c]))
            th[f"theta-{c}"] = list(zip(its, tn[:, c]))
    theta = line_plot(th, "contrast threshold")
    plots = [loss, theta]
    if history.truth_iteration:
        plots.append(line_plot({"as rendered": list(zip(history.truth_iteration, history.psnr_truth)),
                                "affine fit": list(zip(history.truth_iteration, history.psnr_truth_fit))},
                               "PSNR against truth (dB)"))
    strips = []
    if gt:
        views = [n for n in sorted(gt) if n.startswith("deblur_")][:max_strips]
        views += [n for n in sorted(gt) if n.startswith("novel_")][: max(1, max_strips // 2)]
        for name in views:
            cols = {f"{m} {name}": imgs[name] for m, imgs in methods.items() if name in imgs}
            if "affine_fit" in result and name in methods.get("fusiongs", {}):
                cols["affine fit"] = affine_fit(methods["fusiongs"][name], gt[name])
            cols["truth"] = gt[name]
            strips.append(picture_strip(cols))
    else:
        ours = methods.get("fusiongs", {})
        for name in [n for n in sorted(ours) if n.startswith("deblur_")][:max_strips]:
            order = ["blurry", "edi"] + [m for m in methods if m not in ("blurry", "edi", "fusiongs")]
            cols = {f"{m} {name}": methods[m][name] for m in order if name in methods.get(m, {})}
            cols[f"fusiongs {name}"] = ours[name]
            strips.append(picture_strip(cols))
    for name, cols in list((heldout or {}).items())[:max_strips]:
        strips.append(picture_strip({f"{c} {name}" if i == 0 else c: img
                                     for i, (c, img) in enumerate(cols.items())}))
    parts = ([table_image(rows, 520)] if rows else []) + [side_by_side(plots)] + strips
    write_png(path, stack_rows(parts))
