"""MP4 video output through OpenCV's bundled FFmpeg."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from fusiongs.atomic import atomic_path
from fusiongs.errors import FusionGSError


def write_mp4(path: str | Path, frames: Sequence[np.ndarray], fps: float) -> None:
    """Write RGB frames ``[H, W, 3]`` (uint8, or float in [0, 1]) as an MPEG-4 video, atomically."""
    if not frames:
        raise FusionGSError(f"{path}: no frames to write")
    h, w = frames[0].shape[:2]
    with atomic_path(path) as tmp:
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (w, h))
        if not writer.isOpened():
            raise FusionGSError(f"{path}: OpenCV could not open an MPEG-4 video writer")
        try:
            for f in frames:
                a = np.asarray(f)
                if a.dtype != np.uint8:
                    a = np.round(np.clip(a, 0, 1) * 255).astype(np.uint8)
                if a.ndim == 2 or a.shape[-1] == 1:
                    a = np.repeat(a.reshape(h, w, 1), 3, axis=-1)
                writer.write(cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGB2BGR))
        finally:
            writer.release()
