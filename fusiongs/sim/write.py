"""Write a simulated scene: the native scene folder plus its sharp truth under ``gt/``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fusiongs.atomic import write_text
from fusiongs.errors import InputError
from fusiongs.frames.image_io import write_png
from fusiongs.io import save_scene
from fusiongs.io.scene import Scene


def write_simulated_scene(scene: Scene, gt: dict[str, np.ndarray], path: str | Path, *,
                          stats: dict | None = None, overwrite: bool = False) -> Path:
    """Write ``scene`` (docs/scene-format.md folder) and ``gt/<name>.png`` (8-bit sRGB) for every truth image.

    Frames are written as 8-bit PNGs, or as 16-bit ones when their response is ``"linear"``
    (8 bits of linear light would crush the shadows).

    Args:
        scene: the simulated scene (``simulate_scene``).
        gt: render name -> ``[H, W, 3]`` float32 sRGB truth in [0, 1].
        path: output folder (created).
        stats: optional simulation facts (thresholds, counts, config) saved as ``gt/sim.json``.
        overwrite: replace an existing scene in ``path``.

    Returns:
        the path of the written ``scene.json``.

    Raises:
        InputError: ``path`` already holds a scene and ``overwrite`` is false, or it is a file.
    """
    root = Path(path)
    if root.exists() and not root.is_dir():
        raise InputError(root, "output", "a folder (or a path to create one)", "an existing file")
    if (root / "scene.json").exists() and not overwrite:
        raise InputError(root, "output", "a folder without a scene (or pass --overwrite)",
                         "scene.json exists")
    missing = [r.name for r in scene.renders if r.name not in gt]
    if missing:
        raise InputError("write_simulated_scene", "gt", "a truth image for every render",
                         f"missing {missing}")
    jp = save_scene(scene, root, images_bits=16 if scene.frames.response == "linear" else 8)
    (root / "gt").mkdir(exist_ok=True)
    for name, img in gt.items():
        write_png(root / "gt" / f"{name}.png", img)
    if stats is not None:
        write_text(root / "gt" / "sim.json", json.dumps(stats, indent=2, default=_jsonable) + "\n")
    return jp


def _jsonable(v):
    if isinstance(v, np.generic):
        return v.item()
    return str(v)
