"""``fusiongs render OUT --t ...``: sharp images at any instants from a finished run.

These are the model's renders: the exposure-ratio correction of ``fusiongs deblur``'s deblurred
frames needs the scene's frames and is not applied here (docs/method.md). An event-only run's
exposure gain (``exposure.json``) is.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

from fusiongs.errors import InputError

HELP = "render sharp images at given instants (seconds) from a finished deblur run"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="output folder of `fusiongs deblur` (holds checkpoint.pt)")
    p.add_argument("--t", type=float, nargs="+", required=True,
                   help="instants in seconds, inside the recording's time range")
    p.add_argument("-o", "--output", "--out", dest="out", default=None,
                   help="folder for the PNGs (default RUN/renders_t)")


def check_instants(times: Sequence[float], t_min: float, t_max: float, where: str = "--t") -> None:
    """Raise unless every instant lies in ``[t_min, t_max]`` s (the trajectory would clamp it).

    Raises:
        InputError: naming ``where``, the first bad value and the valid range.
    """
    for t in times:
        if not (math.isfinite(t) and t_min <= t <= t_max):
            raise InputError("fusiongs render", where, f"instants within the recording's range "
                             f"[{t_min:.6g}, {t_max:.6g}] s", f"{t:g}")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fusiongs.frames.image_io import write_png
    from fusiongs.train.outputs import read_exposure
    from fusiongs.train.render_io import render_srgb
    from fusiongs.train.restore import restore_state

    state, camera, cfg = restore_state(Path(args.run) / "checkpoint.pt")
    check_instants(args.t, state.trajectory.t_min, state.trajectory.t_max)
    out = Path(args.out) if args.out else Path(args.run) / "renders_t"
    # an event-only run's gain (exposure.json), so that these match its renders
    imgs = render_srgb(state, camera, args.t, cfg["backend"], gain=read_exposure(Path(args.run)))
    for t, img in zip(args.t, imgs):
        path = out / f"t_{t:.6f}.png"
        write_png(path, img)
        print(path)
    return 0
