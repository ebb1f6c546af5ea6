"""Sharp sRGB renders of a fitted state, and the truth images they are compared with."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from fusiongs.frames.image_io import read_image
from fusiongs.frames.response import linear_to_srgb
from fusiongs.train.state import FusionState


@torch.no_grad()
def render_srgb(state: FusionState, camera, times, backend: str = "auto", batch: int = 8) -> np.ndarray:
    """Sharp sRGB renders ``[T, H, W, 3]`` in [0, 1] at instants ``times`` (s)."""
    t = torch.as_tensor(np.asarray(times, dtype=np.float64))
    out = []
    for i in range(0, t.shape[0], batch):
        lin, _, _ = state.render(camera, t[i:i + batch], backend)
        out.append(linear_to_srgb(lin.clamp(0, 1)).cpu().numpy())
    return np.concatenate(out) if out else np.zeros((0, camera.height, camera.width, 3), np.float32)


def read_gt(gt_dir: Path, names) -> dict[str, np.ndarray]:
    """Truth images ``gt_dir/<name>.png`` that exist, as sRGB ``[H, W, 3]``."""
    out = {}
    for name in names:
        p = gt_dir / f"{name}.png"
        if p.is_file():
            img = read_image(p)
            out[name] = np.repeat(img, 3, axis=-1) if img.shape[-1] == 1 else img
    return out
