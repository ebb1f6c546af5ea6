"""``fusiongs render OUT --t ...`` or ``--poses FILE``: sharp images from a finished run, at instants
on its fitted camera path or from camera poses of your own (novel views), optionally as a video.

Poses are a TUM text file (``t tx ty tz qx qy qz qw``, camera-to-world, OpenCV axes) in the run's
world frame: that of the run's refined ``trajectory.txt``, so an edited copy of it (a shifted or
rotated camera) renders the scene from there. Its ``t`` column only names and orders the images.
``--depth`` adds each view's depth along the optical axis (scene units: metres only when the
scene's trajectory is metric; an estimated one has its own scale), NaN where the Gaussians'
accumulated opacity is under one half.

These are the model's renders: the exposure-ratio correction of ``fusiongs deblur``'s deblurred
frames needs the scene's frames and is not applied here (docs/method.md). An event-only run's
exposure gain (``exposure.json``) is, and so is a one-frame run's colour anchor
(``colour_anchor.json``), so that these images have the run's own colours.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

from fusiongs.errors import InputError

HELP = "render sharp images at given instants (seconds) or camera poses from a finished deblur run"
VIDEO_FILE = "renders.mp4"
BATCH = 8  # views rendered, written and let go at a time (a long path does not fill the memory)
MAX_SCALE = 8.0  # --scale beyond this is a typo more likely than a wish (64x the pixels)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="output folder of `fusiongs deblur` (holds checkpoint.pt)")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--t", type=float, nargs="+",
                       help="instants in seconds, inside the recording's time range")
    which.add_argument("--poses", metavar="FILE",
                       help="TUM file of camera-to-world poses in the run's world frame (e.g. an "
                            "edited copy of RUN/trajectory.txt): one image per pose")
    p.add_argument("-o", "--output", "--out", dest="out", default=None,
                   help="folder for the PNGs (default RUN/renders_t, or RUN/renders_poses)")
    p.add_argument("--scale", type=float, default=1.0,
                   help=f"render at this many times the camera's resolution (0 < S <= {MAX_SCALE:g}; "
                        "the intrinsics scaled with it)")
    p.add_argument("--depth", action="store_true",
                   help="also write each view's depth along the optical axis (scene units; NaN where "
                        "nothing was rendered) as float32 <name>_depth.npy")
    p.add_argument("--video", action="store_true",
                   help=f"also write the images in order as an H.264 video, OUT/{VIDEO_FILE}")
    p.add_argument("--fps", type=float, default=None,
                   help="frames per second of --video (default the run's output.video_fps)")


def check_instants(times: Sequence[float], t_min: float, t_max: float, where: str = "--t") -> None:
    """Raise unless every instant lies in ``[t_min, t_max]`` s (the trajectory would clamp it).

    Raises:
        InputError: naming ``where``, the first bad value and the valid range.
    """
    for t in times:
        if not (math.isfinite(t) and t_min <= t <= t_max):
            raise InputError("fusiongs render", where, f"instants within the recording's range "
                             f"[{t_min:.6g}, {t_max:.6g}] s", f"{t:g}")


def check_distinct_names(times: Sequence[float], where: str) -> None:
    """Raise unless distinct instants get distinct image names (``{t:.6f}``): two poses a tenth of a
    microsecond apart would otherwise write one file over the other.

    Raises:
        InputError: naming ``where`` and the first two instants that share a name.
    """
    seen: dict[str, float] = {}
    for t in times:
        name = f"{t:.6f}"
        if name in seen and seen[name] != t:
            raise InputError(where, "t", "times that differ within 6 decimals (they name the images)",
                             f"{seen[name]!r} and {t!r}")
        seen[name] = t


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fusiongs.camera.tum import read_tum
    from fusiongs.outputs.colour_anchor import read_anchor
    from fusiongs.outputs.video import write_mp4
    from fusiongs.outputs.write import read_exposure
    from fusiongs.train.restore import restore_state

    if args.fps is not None and not (math.isfinite(args.fps) and args.fps > 0):
        raise InputError("fusiongs render", "--fps", "a positive number of frames per second", args.fps)
    if not (math.isfinite(args.scale) and 0 < args.scale <= MAX_SCALE):
        raise InputError("fusiongs render", "--scale", f"a factor in (0, {MAX_SCALE:g}]", args.scale)
    poses = read_tum(args.poses) if args.poses else None  # bad files fail before the checkpoint loads
    anchor = read_anchor(Path(args.run))  # a one-frame run's colours, as its own renders have them
    state, camera, cfg = restore_state(Path(args.run) / "checkpoint.pt")
    if args.scale != 1.0:
        camera = camera.scaled(args.scale)
    if poses is None:
        check_instants(args.t, state.trajectory.t_min, state.trajectory.t_max)
        times, prefix, default = list(args.t), "t", "renders_t"
    else:
        times, prefix, default = list(poses.t), "pose", "renders_poses"
    check_distinct_names(times, "--t" if poses is None else args.poses)
    out = Path(args.out) if args.out else Path(args.run) / default
    # an event-only run's gain (exposure.json), so that these match its renders
    frames = write_views(state, camera, cfg["backend"], times, None if poses is None else poses.c2w, out,
                         prefix, read_exposure(Path(args.run)), anchor, args.depth, args.video)
    if args.video:
        fps = args.fps if args.fps is not None else float(cfg.get("output", {}).get("video_fps", 12))
        write_mp4(out / VIDEO_FILE, frames, fps)
        print(out / VIDEO_FILE)
    return 0


def write_views(state, camera, backend: str, times: list[float], c2w, out, prefix: str, gain: float,
                anchor, depth: bool, keep: bool) -> list:
    """Render and write ``out/<prefix>_<t>.png`` for every instant of ``times`` (or every pose of
    ``c2w`` ``[T, 4, 4]``, ``times`` then only naming them), :data:`BATCH` views at a time: times the
    exposure ``gain``, the colour ``anchor`` applied, with ``<name>_depth.npy`` when ``depth``.

    Returns:
        with ``keep``, the images as ``[H, W, 3]`` uint8 in order (for a video); else ``[]``.
    """
    import numpy as np

    from fusiongs.atomic import atomic_path
    from fusiongs.frames.image_io import write_png
    from fusiongs.outputs.colour_anchor import apply_anchor
    from fusiongs.train.render_io import render_depth_maps, render_srgb

    frames = []
    for lo in range(0, len(times), BATCH):
        part = slice(lo, lo + BATCH)
        views = {"poses": None if c2w is None else c2w[part]}
        imgs = render_srgb(state, camera, times[part], backend, gain=gain, **views)
        depths = render_depth_maps(state, camera, times[part], backend, **views) if depth else None
        for k, (t, img) in enumerate(zip(times[part], imgs)):
            img = apply_anchor(anchor, img) if anchor.applied else img
            name = f"{prefix}_{t:.6f}"
            write_png(out / f"{name}.png", img)
            print(out / f"{name}.png")
            if depths is not None:
                with atomic_path(out / f"{name}_depth.npy") as tmp:
                    np.save(tmp, depths[k])
                print(out / f"{name}_depth.npy")
            if keep:
                frames.append(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8))
    return frames
