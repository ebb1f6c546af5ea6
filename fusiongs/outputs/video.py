"""MP4 video output: H.264 through the FFmpeg binary that ``imageio-ffmpeg`` ships.

The file plays in browsers and common players: H.264 (``libx264``), 4:2:0 chroma (``yuv420p``,
BT.709 matrix, limited range, tagged as such), ``+faststart`` (index first). 4:2:0 needs an even
width and height: an odd one gets one more column or row, a copy of the last (never cropped).
"""

from __future__ import annotations

import subprocess
import tempfile
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path

import numpy as np

from fusiongs.atomic import atomic_path
from fusiongs.errors import FusionGSError, MissingDependencyError

CRF = 18  # x264 constant-rate factor: 0 lossless, 18 visually lossless, 23 its default


def even_frame(frame: np.ndarray) -> np.ndarray:
    """An RGB uint8 frame ``[H', W', 3]`` with even ``H'``, ``W'`` from ``frame``.

    Args:
        frame: ``[H, W, 3]``, ``[H, W, 1]`` or ``[H, W]``; uint8, or float in [0, 1] (clipped).

    Returns:
        A new array; an odd height or width is padded by one row or column repeating the last.
    """
    a = np.asarray(frame)
    if a.dtype != np.uint8:
        a = np.round(np.clip(a, 0, 1) * 255).astype(np.uint8)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[-1] == 1:
        a = np.repeat(a, 3, axis=-1)
    h, w = a.shape[:2]
    return np.ascontiguousarray(np.pad(a, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge"))


def _ffmpeg_exe() -> str:
    try:
        import imageio_ffmpeg
    except ImportError:
        raise MissingDependencyError("imageio-ffmpeg", "writing MP4 video") from None
    return imageio_ffmpeg.get_ffmpeg_exe()


def write_mp4(path: str | Path, frames: Sequence[np.ndarray], fps: float) -> None:
    """Write RGB frames ``[H, W, 3]`` (uint8, or float in [0, 1]) as an H.264 MP4, atomically.

    Args:
        path: destination ``.mp4``; written to a temporary file beside it, then renamed.
        frames: frames of one size; ``[H, W]`` or ``[H, W, 1]`` grey frames are repeated to RGB.
        fps: frames per second (> 0).

    Raises:
        FusionGSError: no frames, frames of different sizes, a non-positive ``fps``, or FFmpeg
            failing (its last error line is quoted).
    """
    if not frames:
        raise FusionGSError(f"{path}: no frames to write")
    if not fps > 0:
        raise FusionGSError(f"{path}: fps: expected a positive number, got {fps}")
    size = np.asarray(frames[0]).shape[:2]
    for i, f in enumerate(frames):
        if np.asarray(f).shape[:2] != size:
            raise FusionGSError(f"{path}: frame {i}: expected size {size[1]}x{size[0]}, got "
                                f"{np.asarray(f).shape[1]}x{np.asarray(f).shape[0]}")
    h, w = size[0] + size[0] % 2, size[1] + size[1] % 2
    rate = Fraction(fps).limit_denominator(1001)
    with atomic_path(path) as tmp, tempfile.TemporaryFile() as log:
        cmd = [_ffmpeg_exe(), "-hide_banner", "-nostdin", "-loglevel", "error", "-y",
               "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}", "-r", str(rate), "-i", "-",
               "-an", "-vf", "scale=out_color_matrix=bt709:out_range=tv,format=yuv420p,setparams="
               "colorspace=bt709:color_primaries=bt709:color_trc=bt709:range=tv",
               "-c:v", "libx264", "-crf", str(CRF), "-pix_fmt", "yuv420p", "-movflags", "+faststart",
               "-f", "mp4", str(tmp)]
        proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log)
        try:
            for f in frames:
                proc.stdin.write(even_frame(f).tobytes())
        except BrokenPipeError:
            pass  # ffmpeg stopped early: its return code and log below say why
        except BaseException:
            proc.kill()
            raise
        finally:
            try:
                proc.stdin.close()
            except OSError:
                pass
            rc = proc.wait()
        if rc != 0:
            log.seek(0)
            lines = log.read().decode("utf-8", errors="replace").strip().splitlines()
            raise FusionGSError(f"{path}: ffmpeg could not write the video (exit {rc}): "
                                f"{lines[-1] if lines else 'no message'}")
