"""README strip and no-reference figures of a real-recording run: blurry | EDI | fusiongs.

For each kept frame of ``OUT`` (a ``fusiongs deblur`` output of ``SCENE``), the blurry input,
EDI with the run's calibration (``OUT/calibration.json``) and the fusiongs deblurred frame, all
shown as sRGB of linear light. Prints, over every kept frame, the Tenengrad sharpness and a noise
estimate of each column (:func:`noise_sigma`), and writes a strip of a few frames.

    PYTHONPATH=. python benchmarks/cups_strip.py path/to/eslnet_cups OUT strip.jpg
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from fusiongs.edi import edi_deblur
from fusiongs.eval.holdout import tenengrad
from fusiongs.eval.report import picture_strip, stack_rows
from fusiongs.events.thresholds import read_calibration
from fusiongs.frames.image_io import read_image
from fusiongs.frames.response import linear_to_response
from fusiongs.io.scene_io import load_scene


def srgb(linear: np.ndarray) -> np.ndarray:
    """``[H, W, C]`` linear -> display sRGB in [0, 1], three channels."""
    import torch

    img = linear_to_response(torch.from_numpy(np.clip(linear, 0, 1).astype(np.float32)), "srgb").numpy()
    return np.repeat(img, 3, axis=-1) if img.shape[-1] == 1 else img


def noise_sigma(image: np.ndarray) -> float:
    """Immerkaer's noise estimate (Fast noise variance estimation, CVIU 1996): the mean absolute
    response to the 3x3 mask ``[[1,-2,1],[-2,4,-2],[1,-2,1]]``, which cancels smooth image content
    and edges to first order, scaled to the std of white Gaussian noise. ``image`` ``[H, W]``."""
    mask = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float64)
    r = cv2.filter2D(np.asarray(image, np.float64), -1, mask)[1:-1, 1:-1]
    return float(np.sqrt(np.pi / 2) * np.abs(r).mean() / 6.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("out")
    ap.add_argument("image", help="strip to write (.jpg or .png)")
    ap.add_argument("--frames", default="000002,000012,000022", help="frame names of the strip")
    args = ap.parse_args(argv)
    scene, out = load_scene(args.scene), Path(args.out)
    theta = read_calibration(out / "calibration.json")[0]
    held = json.loads((out / "heldout.json").read_text()) if (out / "heldout.json").is_file() else {}
    held_names = set(held.get("frames", {}))  # frames left out of training
    fs = scene.frames
    lin = fs.to_linear()
    cols = {"blurry": [], "EDI": [], "fusiongs": []}
    names = []
    for i, name in enumerate(fs.names):
        png = out / "deblurred" / f"{name}.png"
        if name in held_names or not png.is_file():
            continue
        names.append(name)
        cols["blurry"].append(srgb(lin[i]))
        edi = edi_deblur(lin[i], scene.events, float(fs.t_start[i]), float(fs.t_end[i]), theta, 32)
        cols["EDI"].append(srgb(edi))
        img = read_image(png)
        cols["fusiongs"].append(np.repeat(img, 3, axis=-1) if img.shape[-1] == 1 else img)
    print(f"{len(names)} frames of {out}")
    print(f"{'column':<10}{'Tenengrad':>11}{'noise sigma':>13}")
    for k, imgs in cols.items():
        ten = np.mean([tenengrad(a) for a in imgs])
        sig = np.mean([noise_sigma(a.mean(-1)) for a in imgs])
        print(f"{k:<10}{ten:>11.4f}{sig:>13.4f}")
    rows = [picture_strip({f"{k} {n}": cols[k][names.index(n)] for k in cols})
            for n in args.frames.split(",") if n in names]
    img = stack_rows(rows)
    Path(args.image).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(args.image, img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
    print(f"wrote {args.image} ({img.shape[1]}x{img.shape[0]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
