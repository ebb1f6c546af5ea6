"""Everything ``fusiongs deblur`` writes after training (see the README's output list)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from fusiongs.atomic import write_text
from fusiongs.frames.image_io import read_image, write_png
from fusiongs.frames.response import linear_to_srgb, response_to_linear
from fusiongs.io.scene import Scene
from fusiongs.scene.ply import save_ply
from fusiongs.train.config import save_config
from fusiongs.train.state import FusionState
from fusiongs.train.trainer import Trained


@torch.no_grad()
def render_srgb(state: FusionState, camera, times, backend: str = "auto", batch: int = 8) -> np.ndarray:
    """Sharp sRGB renders ``[T, H, W, 3]`` in [0, 1] at instants ``times`` (s)."""
    t = torch.as_tensor(np.asarray(times, dtype=np.float64))
    out = []
    for i in range(0, t.shape[0], batch):
        lin, _, _ = state.render(camera, t[i:i + batch], backend)
        out.append(linear_to_srgb(lin.clamp(0, 1)).cpu().numpy())
    return np.concatenate(out) if out else np.zeros((0, camera.height, camera.width, 3), np.float32)


def frames_srgb(scene: Scene) -> np.ndarray:
    """The captured (blurry) frames as sRGB ``[F, H, W, 3]`` for side-by-side comparison."""
    f = scene.frames
    lin = response_to_linear(f.images.astype(np.float64), f.response)
    if lin.shape[-1] == 1:
        lin = np.repeat(lin, 3, axis=-1)
    return linear_to_srgb(np.clip(lin, 0, 1)).astype(np.float32)


def write_thresholds(state: FusionState, path: Path) -> dict:
    """``thresholds.json``: learned θ per polarity (and colour channel)."""
    with torch.no_grad():
        tp, tn = state.threshold.scalar()
    names = ["grey"] if tp.numel() == 1 else ["R", "G", "B"]
    doc = {"channels": names, "theta_pos": [float(v) for v in tp.reshape(-1)],
           "theta_neg": [float(v) for v in tn.reshape(-1)]}
    write_text(path, json.dumps(doc, indent=2) + "\n")
    return doc


def write_outputs(tr: Trained, scene: Scene, out: Path) -> dict[str, np.ndarray]:
    """Write renders, deblurred frames and video, model, config and thresholds.

    Returns:
        ``{name: sRGB image}`` for every ``renders`` entry and ``deblur/<stem>`` frame.
    """
    from fusiongs.eval.video import write_mp4

    state, cfg = tr.state, tr.config
    cam = scene.camera
    images: dict[str, np.ndarray] = {}
    if scene.renders:
        imgs = render_srgb(state, cam, [r.t for r in scene.renders], cfg.backend)
        for r, img in zip(scene.renders, imgs):
            write_png(out / "renders" / f"{r.name}.png", img)
            images[r.name] = img
    if len(scene.frames):
        mids = scene.frames.mid_times()
        imgs = render_srgb(state, cam, mids, cfg.backend)
        for name, img in zip(scene.frames.names, imgs):
            write_png(out / "deblurred" / f"{name}.png", img)
            images[f"deblur/{name}"] = img
        write_mp4(out / "deblurred.mp4", list(imgs), cfg.output.video_fps)
    save_ply(state.model, out / "model.ply")
    save_config(cfg, out / "config.yaml")
    write_thresholds(state, out / "thresholds.json")
    return images


def read_gt(gt_dir: Path, names) -> dict[str, np.ndarray]:
    """Truth images ``gt_dir/<name>.png`` that exist, as sRGB ``[H, W, 3]``."""
    out = {}
    for name in names:
        p = gt_dir / f"{name}.png"
        if p.is_file():
            img = read_image(p)
            out[name] = np.repeat(img, 3, axis=-1) if img.shape[-1] == 1 else img
    return out
