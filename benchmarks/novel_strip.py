"""README strip of novel views: a finished run rendered from cameras slid sideways off its path.

The run's refined camera at the middle of its path is moved along its own x axis (right, OpenCV
axes) by ``-D``, ``0`` and ``+D`` scene units, looking the same way, through ``fusiongs render
--poses``; the three renders side by side go to ``STRIP``. The whole path's extent is printed
for scale (a slide beyond it extrapolates past what the recording saw).

    PYTHONPATH=. python benchmarks/novel_strip.py OUT strip.jpg [--slide 0.15]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import cv2
import numpy as np

from fusiongs.camera.tum import PoseSamples, read_tum, write_tum
from fusiongs.cli import main as fusiongs_main
from fusiongs.frames.image_io import read_image


def slid_poses(path: PoseSamples, slide: float) -> PoseSamples:
    """The middle pose of ``path`` moved by ``-slide, 0, +slide`` along its own x axis."""
    c = path.c2w[len(path) // 2]
    offsets = np.array([-slide, 0.0, slide])
    c2w = np.repeat(c[None], offsets.size, 0)
    c2w[:, :3, 3] += offsets[:, None] * c[:3, 0]
    return PoseSamples(np.arange(offsets.size, dtype=np.float64), c2w)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("strip", type=Path)
    ap.add_argument("--slide", type=float, default=0.15, help="sideways move (scene units)")
    args = ap.parse_args()
    path = read_tum(args.run / "trajectory.txt")
    extent = float(np.linalg.norm(np.ptp(path.c2w[:, :3, 3], axis=0)))
    print(f"path extent {extent:.3f} units; slide ±{args.slide:g}")
    with tempfile.TemporaryDirectory() as tmp:
        poses = Path(tmp) / "poses.txt"
        write_tum(poses, slid_poses(path, args.slide))
        if fusiongs_main(["render", str(args.run), "--poses", str(poses), "-o", tmp]) != 0:
            return 2
        imgs = [read_image(p) for p in sorted(Path(tmp).glob("pose_*.png"))]
    strip = np.concatenate(imgs, axis=1)
    bgr = np.ascontiguousarray((np.clip(strip, 0, 1) * 255 + 0.5).astype(np.uint8)[..., ::-1])
    cv2.imwrite(str(args.strip), bgr, [cv2.IMWRITE_JPEG_QUALITY, 88])
    print(args.strip)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
