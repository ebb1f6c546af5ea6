"""The frame set container: images with exposure windows and their response curve."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusiongs.errors import InputError


@dataclass(frozen=True, eq=False)
class FrameSet:
    """Frames of one camera with their exposure windows.

    Attributes:
        images: ``[F, H, W, C]`` float32 pixel values in [0, 1] as stored in the files (encoded by
            ``response``; C = 3 for RGB, 1 for a monochrome camera). ``[0, H, W, C]`` when empty.
        t_start, t_end: ``[F]`` float64 exposure start and end in seconds (events' clock / 1e6).
        names: frame stems (``"000000"`` for ``frames/000000.png``), used for output file names.
        response: how stored values relate to linear irradiance: ``"srgb"``, ``"linear"`` or
            ``"gamma:G"``.

    Raises:
        InputError: (source ``"frames"``) on inconsistent lengths, a non-finite time, or an
            exposure window with ``t_end <= t_start`` (naming the frame), or an unknown response.
    """

    images: np.ndarray
    t_start: np.ndarray
    t_end: np.ndarray
    names: tuple[str, ...]
    response: str = "srgb"

    def __post_init__(self) -> None:
        from fusiongs.frames.response import parse_response

        parse_response(self.response, "frames", "response")
        shape = getattr(self.images, "shape", ())
        if len(shape) != 4 or shape[3] not in (1, 3):
            raise InputError("frames", "images", "an array [F, H, W, C] with C = 1 or 3", shape)
        f = shape[0]
        for name in ("t_start", "t_end"):
            v = np.asarray(getattr(self, name))
            if v.shape != (f,):
                raise InputError("frames", name, f"{f} times (one per frame)", v.shape)
            bad = np.flatnonzero(~np.isfinite(v))
            if bad.size:
                raise InputError("frames", f"frames[{bad[0]}].{name}", "a finite time in seconds", v[bad[0]])
        if len(self.names) != f:
            raise InputError("frames", "names", f"{f} names (one per frame)", len(self.names))
        bad = np.flatnonzero(~(np.asarray(self.t_end) > np.asarray(self.t_start)))
        if bad.size:
            i = int(bad[0])
            raise InputError("frames", f"frames[{i}].t_end",
                             f"t_end > t_start for frame {self.names[i]!r}",
                             f"t_start={self.t_start[i]}, t_end={self.t_end[i]}")

    def __len__(self) -> int:
        return int(self.images.shape[0])

    def to_linear(self) -> np.ndarray:
        """``[F, H, W, C]`` float32 linear irradiance, decoded with ``response``."""
        from fusiongs.frames.response import response_to_linear

        return np.asarray(response_to_linear(self.images, self.response), dtype=np.float32)

    def mid_times(self) -> np.ndarray:
        """``[F]`` float64 mid-exposure times in seconds."""
        return 0.5 * (np.asarray(self.t_start, np.float64) + np.asarray(self.t_end, np.float64))

    def exposures(self) -> np.ndarray:
        """``[F]`` float64 exposure durations in seconds."""
        return np.asarray(self.t_end, np.float64) - np.asarray(self.t_start, np.float64)

    @staticmethod
    def empty(height: int, width: int, channels: int = 3, response: str = "srgb") -> FrameSet:
        """A frame set with no frames for an ``height`` x ``width`` camera."""
        return FrameSet(np.zeros((0, height, width, channels), np.float32), np.zeros(0), np.zeros(0),
                        (), response)
