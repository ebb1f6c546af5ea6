"""``fusiongs convert IN -o SCENE``: any supported event layout -> a native scene folder."""

from __future__ import annotations

import argparse
import sys

HELP = "Convert an event recording (h5, txt, npz, aedat4, Prophesee raw) into a scene folder."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from fusiongs.events.stream import CFA_PATTERNS

    parser.add_argument("input", help="event file (.h5/.hdf5, .txt, .npz, .aedat4, .raw)")
    parser.add_argument("-o", "--output", required=True, help="scene folder to write")
    add_reader_arguments(parser, CFA_PATTERNS)
    parser.add_argument("--fx", type=float, help="focal length in pixels (default: width)")
    parser.add_argument("--fy", type=float, help="focal length in pixels (default: fx)")
    parser.add_argument("--cx", type=float, help="principal point x (default: width/2)")
    parser.add_argument("--cy", type=float, help="principal point y (default: height/2)")
    parser.add_argument("--keep-clock", action="store_true",
                        help="keep the source clock instead of starting the scene at 0 s")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing scene.json")


def add_reader_arguments(parser: argparse.ArgumentParser, cfa_patterns) -> None:
    """Options shared by ``convert`` and ``inspect`` for reading a raw event file."""
    parser.add_argument("--format", help="input layout: native, dsec, event_utils, evdeblurnerf, "
                        "txt, eventnerf, aedat4, evt2, evt3 (default: detect)")
    parser.add_argument("--width", type=int, help="sensor width when the file does not store it")
    parser.add_argument("--height", type=int, help="sensor height when the file does not store it")
    parser.add_argument("--cfa", choices=cfa_patterns, help="colour filter layout of the events")
    parser.add_argument("--time-unit", choices=("s", "ms", "us", "ns"),
                        help="unit of t where the layout leaves it open (EvDeblurNeRF, EventNeRF, txt)")
    parser.add_argument("--sort", action="store_true", help="sort unsorted timestamps")
    parser.add_argument("--drop-invalid", action="store_true",
                        help="drop events outside the sensor instead of failing")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from fusiongs.camera.pinhole import PinholeCamera
    from fusiongs.errors import InputError
    from fusiongs.events.readers import detect_format, read_aedat4, read_events
    from fusiongs.events.stream import EventStream
    from fusiongs.frames.frameset import FrameSet
    from fusiongs.io.scene import Scene
    from fusiongs.io.scene_io import SCENE_FILE, save_scene

    out = Path(args.output)
    if (out / SCENE_FILE).exists() and not args.overwrite:
        raise InputError(out, SCENE_FILE, "a new scene folder (or --overwrite)", "scene.json exists")
    fmt = args.format or detect_format(args.input)
    kw = {"width": args.width, "height": args.height, "cfa": args.cfa, "sort": args.sort,
          "drop_invalid": args.drop_invalid}
    aps = None
    if fmt == "aedat4":
        ev, aps = read_aedat4(args.input, **kw)
    else:
        ev = read_events(args.input, format=fmt, time_unit=args.time_unit, **kw)
    origin = 0
    if not args.keep_clock:
        starts = [int(ev.t[0])]
        if aps is not None and len(aps):
            starts.append(int((aps.exposure_start if aps.exposure_start is not None else aps.t).min()))
        origin = min(starts)
        t = ev.t if ev.t.flags.writeable and ev.t.flags.owndata else ev.t.copy()
        t -= origin  # in place: the stream was just read, and a copy is 8 bytes an event
        ev = EventStream(t, ev.x, ev.y, ev.p, ev.width, ev.height, ev.cfa)
    w, h = ev.width, ev.height
    if args.fx is None:
        print(f"fusiongs convert: warning: no intrinsics given; using fx=fy={w}, cx={w / 2:g}, "
              f"cy={h / 2:g} (pass --fx/--fy/--cx/--cy)", file=sys.stderr)
    fx = args.fx if args.fx is not None else float(w)
    cam = PinholeCamera(w, h, fx, args.fy if args.fy is not None else fx,
                        args.cx if args.cx is not None else w / 2, args.cy if args.cy is not None else h / 2)
    frames = _aps_frameset(aps, origin, cam, args.input) if aps is not None and len(aps) else \
        FrameSet.empty(h, w, 1 if ev.cfa is None else 3)
    save_scene(Scene(cam, ev, frames), out)
    msg = f"wrote {out}: {len(ev)} events over {ev.duration_us * 1e-6:.3f} s, {w}x{h}, {len(frames)} frame(s)"
    if origin:
        msg += f"; time 0 = {origin} µs on the source clock"
    print(msg)
    return 0


def _aps_frameset(aps, origin: int, cam, source):
    """APS frames as a :class:`FrameSet` (linear response: DAVIS APS values are a linear readout)."""
    import numpy as np

    from fusiongs.errors import InputError
    from fusiongs.frames.frameset import FrameSet

    imgs = aps.images
    if imgs.shape[1:3] != (cam.height, cam.width):
        raise InputError(source, "frames", f"APS frames of the event sensor size {cam.width}x{cam.height}",
                         f"{imgs.shape[2]}x{imgs.shape[1]}")
    scale = 65535.0 if imgs.dtype == np.uint16 else 255.0
    f = imgs.astype(np.float32) / np.float32(scale)
    if f.ndim == 3:
        f = f[..., None]
    elif f.shape[3] == 4:
        f = f[..., :3]
    if aps.exposure_start is None:
        print("fusiongs convert: warning: the frames have no exposure times; using zero-length "
              "exposures at the frame timestamps", file=sys.stderr)
        s = e = aps.t
    else:
        s, e = aps.exposure_start, aps.exposure_end
    return FrameSet(f, (s - origin) * 1e-6, (e - origin) * 1e-6,
                    tuple(f"{i:06d}" for i in range(len(aps))), "linear")
