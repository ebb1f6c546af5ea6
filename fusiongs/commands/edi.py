"""``fusiongs edi SCENE -o OUT``: event-based double integral deblurring of every frame."""

from __future__ import annotations

import argparse

HELP = "Deblur every frame of a scene with its events (EDI, Pan et al. CVPR 2019)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="scene folder (or its scene.json)")
    parser.add_argument("-o", "--output", required=True, help="folder for OUT/<frame stem>.png")
    parser.add_argument("--theta", type=float, nargs="+", metavar="THETA",
                        help="contrast threshold, or ON and OFF thresholds (default: estimate them as "
                             "`fusiongs calibrate` does)")
    parser.add_argument("--calibration", default=None, metavar="FILE",
                        help="calibration.json from `fusiongs calibrate` (ON/OFF per channel; where it kept "
                             "the reset pixel model, each event counts the crossings it stands for)")
    parser.add_argument("--samples", type=int, default=32,
                        help="instants the exposure mean is taken over (default 32)")
    parser.add_argument("--bits", type=int, choices=(8, 16), default=8, help="PNG bit depth (default 8)")
    parser.add_argument("--sort", action="store_true", help="sort unsorted event timestamps")
    parser.add_argument("--drop-invalid", action="store_true",
                        help="drop events outside the sensor instead of failing")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from fusiongs.edi import edi_scene
    from fusiongs.errors import InputError
    from fusiongs.frames.image_io import write_png
    from fusiongs.frames.response import linear_to_response
    from fusiongs.io.scene_io import load_scene

    theta = None
    if args.theta is not None:
        if len(args.theta) not in (1, 2):
            raise InputError("command line", "--theta", "one threshold or an ON OFF pair", args.theta)
        theta = args.theta[0] if len(args.theta) == 1 else tuple(args.theta)
    if args.calibration is not None:
        if theta is not None:
            raise InputError("command line", "--calibration", "either --theta or --calibration", "both")
        from fusiongs.events.thresholds import read_calibration

        theta = read_calibration(args.calibration)[0]
    if args.samples < 1:
        raise InputError("command line", "--samples", "a positive integer", args.samples)
    scene = load_scene(args.scene, sort_events=args.sort, drop_invalid_events=args.drop_invalid)
    if theta is None:
        from fusiongs.calibrate.estimate import estimate_thresholds
        from fusiongs.edi import check_scene

        check_scene(scene)
        theta = estimate_thresholds(scene.frames, scene.events)
    sharp = edi_scene(scene, theta=theta, n_samples=args.samples)
    out = Path(args.output)
    enc = np.asarray(linear_to_response(np.clip(sharp, 0.0, 1.0), scene.frames.response))
    for name, img in zip(scene.frames.names, enc):
        write_png(out / f"{name}.png", img, bits=args.bits)
    print(f"wrote {len(enc)} frame(s) to {out} ({scene.frames.response} encoding)")
    return 0
