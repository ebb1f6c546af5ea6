"""``fusiongs simulate -o SCENE``: write a synthetic scene folder with events, blurry frames and truth."""

from __future__ import annotations

import argparse

HELP = "Simulate a scene folder (blurry frames, DVS events, trajectory, sharp truth in gt/)."

# Values are parsed in ``run`` (not by argparse types) so that every bad value is one-line error.
_NUMBERS = {  # option -> (SimConfig field, type, smallest allowed value)
    "seed": ("seed", int, 0), "duration": ("duration", float, 1e-3), "frames": ("frames", int, 0),
    "exposure": ("exposure", float, 1e-6), "events_target": ("events_target", int, 1),
    "novel": ("novel", int, 0), "dvs_rate": ("dvs_rate_hz", float, 1.0),
    "blur_samples": ("blur_samples", int, 1), "supersample": ("supersample", int, 1),
}
_DVS_NUMBERS = {"theta_on": float, "theta_off": float, "theta_sigma": float,
                "refractory_us": float, "ba_rate": float, "theta_gradient": float}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", required=True, help="scene folder to write")
    parser.add_argument("--preset", default="boxes", help="scene: boxes, wall or corridor (default boxes)")
    parser.add_argument("--cfa", default="none", help="event CFA: RGGB, BGGR, GRBG, GBRG or none (grey)")
    parser.add_argument("--seed", default="0", help="random seed (default 0)")
    parser.add_argument("--size", default="173x130", help="sensor size WxH (default 173x130)")
    parser.add_argument("--duration", default="1.0", help="recording length in s (default 1)")
    parser.add_argument("--frames", default="12", help="number of blurry frames (default 12)")
    parser.add_argument("--exposure", default="0.06", help="exposure time in s (default 0.06)")
    parser.add_argument("--events-target", default=None,
                        help="scale the contrast thresholds to get about this many events")
    parser.add_argument("--novel", default="4", help="held-out novel-view instants (default 4)")
    parser.add_argument("--theta-on", default=None, help="nominal ON threshold (default 0.25)")
    parser.add_argument("--theta-off", default=None, help="nominal OFF threshold (default 0.22)")
    parser.add_argument("--theta-sigma", default=None, help="per-pixel threshold spread (default 0.03)")
    parser.add_argument("--theta-gradient", default=None,
                        help="thresholds vary by a factor 1±G from the left to the right edge (default 0)")
    parser.add_argument("--refractory-us", default=None, help="refractory period in µs (default 100)")
    parser.add_argument("--ba-rate", default=None, help="background-activity noise, Hz/pixel (default 0.1)")
    parser.add_argument("--dvs-rate", default="1000", help="event-model render rate, Hz (default 1000)")
    parser.add_argument("--blur-samples", default="48", help="renders averaged per exposure (default 48)")
    parser.add_argument("--supersample", default="2", help="anti-aliasing samples per pixel axis (default 2)")
    parser.add_argument("--threads", default=None, help="torch CPU threads (default: torch's choice)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing scene")


def _parse_number(text: str, option: str, kind: type, lo: float):
    from fusiongs.errors import InputError

    try:
        v = kind(text)
    except (TypeError, ValueError):
        what = "an integer" if kind is int else "a number"
        raise InputError("simulate", f"--{option.replace('_', '-')}", what, repr(text)) from None
    if not v >= lo:
        raise InputError("simulate", f"--{option.replace('_', '-')}", f"a value >= {lo:g}", repr(text))
    return v


def _parse_size(text: str) -> tuple[int, int]:
    from fusiongs.errors import InputError

    parts = str(text).lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts) or min(int(p) for p in parts) < 8:
        raise InputError("simulate", "--size", "WxH with integers >= 8 (e.g. 173x130)", repr(text))
    return int(parts[0]), int(parts[1])


def config_from_args(args: argparse.Namespace):
    """Build a validated ``SimConfig`` from parsed arguments (raises ``InputError``)."""
    import dataclasses

    from fusiongs.errors import InputError
    from fusiongs.events.stream import CFA_PATTERNS
    from fusiongs.sim.dvs import DVSParams
    from fusiongs.sim.presets import PRESETS
    from fusiongs.sim.simulate import SimConfig

    if args.preset not in PRESETS:
        raise InputError("simulate", "--preset", f"one of {', '.join(PRESETS)}", repr(args.preset))
    cfa = None if str(args.cfa).lower() == "none" else str(args.cfa).upper()
    if cfa is not None and cfa not in CFA_PATTERNS:
        raise InputError("simulate", "--cfa", f"one of {', '.join(CFA_PATTERNS)} or none", repr(args.cfa))
    width, height = _parse_size(args.size)
    kw = {}
    for opt, (fld, kind, lo) in _NUMBERS.items():
        text = getattr(args, opt)
        if text is not None:
            kw[fld] = _parse_number(text, opt, kind, lo)
    dvs = {}
    for opt, kind in _DVS_NUMBERS.items():
        text = getattr(args, opt)
        if text is not None:
            v = _parse_number(text, opt, kind, 0.0)
            if opt == "refractory_us":
                dvs["refractory_s"] = v * 1e-6
            elif opt == "ba_rate":
                dvs["ba_rate_hz"] = v
            else:
                dvs[opt] = v
    if dvs.get("theta_on", 1.0) <= 0 or dvs.get("theta_off", 1.0) <= 0:
        raise InputError("simulate", "--theta-on/--theta-off", "positive thresholds")
    cfg = SimConfig(preset=args.preset, width=width, height=height, cfa=cfa,
                    dvs=dataclasses.replace(DVSParams(), **dvs), **kw)
    return cfg.validate()


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import torch

    from fusiongs.errors import InputError
    from fusiongs.sim.simulate import run_simulation
    from fusiongs.sim.write import write_simulated_scene

    cfg = config_from_args(args)
    out = Path(args.output)
    if (out / "scene.json").exists() and not args.overwrite:
        raise InputError(out, "scene.json", "a new scene folder (or --overwrite)", "scene.json exists")
    if args.threads is not None:
        torch.set_num_threads(_parse_number(args.threads, "threads", int, 1))
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, out, stats=res.stats, overwrite=args.overwrite)
    s = res.stats
    print(f"wrote {out}: preset {cfg.preset}, {cfg.width}x{cfg.height}, {cfg.duration:g} s, "
          f"{len(res.scene.frames)} frames, {s['events']} events ({s['events_per_pixel']:.1f}/pixel, "
          f"ON {s['on_fraction']:.2f}), thresholds ON {s['theta_on']:.3f} OFF {s['theta_off']:.3f}, "
          f"mean blur {s['blur_px']:.1f} px, {s['seconds_total']:.1f} s")
    return 0
