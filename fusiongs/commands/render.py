"""``fusiongs render OUT --t ...``: sharp images at any instants from a finished run."""

from __future__ import annotations

import argparse

HELP = "render sharp images at given instants (seconds) from a finished deblur run"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="output folder of `fusiongs deblur` (holds checkpoint.pt)")
    p.add_argument("--t", type=float, nargs="+", required=True, help="instants in seconds")
    p.add_argument("-o", "--out", default=None, help="folder for the PNGs (default RUN/renders_t)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fusiongs.frames.image_io import write_png
    from fusiongs.train.outputs import render_srgb
    from fusiongs.train.restore import restore_state

    state, camera, cfg = restore_state(Path(args.run) / "checkpoint.pt")
    out = Path(args.out) if args.out else Path(args.run) / "renders_t"
    imgs = render_srgb(state, camera, args.t, cfg["backend"])
    for t, img in zip(args.t, imgs):
        path = out / f"t_{t:.6f}.png"
        write_png(path, img)
        print(path)
    return 0
