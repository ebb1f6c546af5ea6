"""``fusiongs simulate -o SCENE``: write a synthetic scene folder with events, blurry frames and truth."""

from __future__ import annotations

import argparse

HELP = "Simulate a scene folder (blurry frames, DVS events, trajectory, sharp truth in gt/)."

# Values are parsed in ``run`` (not by argparse types) so that every bad value is one-line error.
# Every option defaults to None ("not given"): SimConfig / DVSParams hold the defaults, and
# --sweep-seed can tell the options it draws itself from those given on the command line.
_NUMBERS = {  # option -> (SimConfig field, type, smallest, largest allowed value)
    "seed": ("seed", int, 0, None), "duration": ("duration", float, 1e-3, None),
    "frames": ("frames", int, 0, None), "exposure": ("exposure", float, 1e-6, None),
    "events_target": ("events_target", int, 1, None), "novel": ("novel", int, 0, None),
    "dvs_rate": ("dvs_rate_hz", float, 1.0, None), "blur_samples": ("blur_samples", int, 1, None),
    "supersample": ("supersample", int, 1, None), "motion_scale": ("motion_scale", float, 1e-3, 10.0),
}
_DVS_NUMBERS = {  # option -> (DVSParams field, factor to its unit, smallest, largest allowed value)
    "theta_on": ("theta_on", 1.0, 1e-6, None), "theta_off": ("theta_off", 1.0, 1e-6, None),
    "theta_sigma": ("theta_sigma", 1.0, 0.0, None), "theta_gradient": ("theta_gradient", 1.0, 0.0, None),
    "refractory_us": ("refractory_s", 1e-6, 0.0, None), "ba_rate": ("ba_rate_hz", 1.0, 0.0, None),
    "hot_pixels": ("hot_pixel_fraction", 1.0, 0.0, 1.0), "hot_rate": ("hot_pixel_rate_hz", 1.0, 0.0, None),
    "leak_rate": ("leak_rate_hz", 1.0, 0.0, None),
}
# With --sweep-seed these may still be given (size, length and cost of the recording); every other
# scene or sensor option is drawn from the seed and refused.
_SWEEP_OVERRIDES = ("duration", "frames", "novel", "dvs_rate", "blur_samples", "supersample")
_SWEEP_DRAWN = ("preset", "cfa", "seed", "frame_response", "exposure", "events_target", "motion_scale",
                *_DVS_NUMBERS)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", required=True, help="scene folder to write")
    parser.add_argument("--preset", default=None,
                        help="scene: boxes, wall, corridor, gallery, dark or depth (default boxes); "
                             "walks whose view keeps changing: hallway, walkway (20 s each: "
                             "--duration 20 --frames 240)")
    parser.add_argument("--cfa", default=None,
                        help="event CFA: RGGB, BGGR, GRBG, GBRG or none (default none: grey)")
    parser.add_argument("--seed", default=None, help="random seed (default 0)")
    parser.add_argument("--size", default=None, help="sensor size WxH (default 173x130)")
    parser.add_argument("--duration", default=None, help="recording length in s (default 1)")
    parser.add_argument("--frames", default=None, help="number of blurry frames (default 12)")
    parser.add_argument("--exposure", default=None, help="exposure time in s (default 0.06)")
    parser.add_argument("--motion-scale", default=None,
                        help="camera speed factor: blur scales with it (default 1)")
    parser.add_argument("--frame-response", default=None,
                        help="frames as srgb (8-bit sRGB) or linear (16-bit linear PNG) (default srgb)")
    parser.add_argument("--events-target", default=None,
                        help="scale the contrast thresholds to get about this many events")
    parser.add_argument("--novel", default=None, help="held-out novel-view instants (default 4)")
    parser.add_argument("--theta-on", default=None, help="nominal ON threshold (default 0.25)")
    parser.add_argument("--theta-off", default=None, help="nominal OFF threshold (default 0.22)")
    parser.add_argument("--theta-sigma", default=None, help="per-pixel threshold spread (default 0.03)")
    parser.add_argument("--theta-gradient", default=None,
                        help="thresholds vary by a factor 1±G from the left to the right edge (default 0)")
    parser.add_argument("--refractory-us", default=None, help="refractory period in µs (default 100)")
    parser.add_argument("--refractory-reset", action="store_true",
                        help="the pixel takes its level again when the refractory period ends, as a "
                             "physical pixel's reset (default: the level keeps every crossing); "
                             "allowed with --sweep-seed")
    parser.add_argument("--ba-rate", default=None, help="background-activity noise, Hz/pixel (default 0.1)")
    parser.add_argument("--hot-pixels", default=None,
                        help="fraction of hot pixels, each firing one polarity at --hot-rate (default 0)")
    parser.add_argument("--hot-rate", default=None, help="event rate of a hot pixel, Hz (default 200)")
    parser.add_argument("--leak-rate", default=None, help="leak (ON) events, Hz/pixel (default 0)")
    parser.add_argument("--sweep-seed", default=None,
                        help="draw preset, CFA, frame response, exposure, speed and sensor from this "
                             "seed of the sweep (fusiongs.sim.sweep); --size, --duration, --frames, "
                             "--novel and the render options may still be given")
    parser.add_argument("--split", default=None,
                        help="sweep split of --sweep-seed: tuning (seeds 0-999) or test (1000-1999) "
                             "(default tuning)")
    parser.add_argument("--dvs-rate", default=None, help="event-model render rate, Hz (default 1000)")
    parser.add_argument("--blur-samples", default=None, help="renders averaged per exposure (default 48)")
    parser.add_argument("--supersample", default=None,
                        help="anti-aliasing samples per pixel axis (default 2)")
    parser.add_argument("--threads", default=None, help="torch CPU threads (default: torch's choice)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing scene")


def _flag(option: str) -> str:
    return f"--{option.replace('_', '-')}"


def _parse_number(text: str, option: str, kind: type, lo: float, hi: float | None = None):
    from fusiongs.errors import InputError

    try:
        v = kind(text)
    except (TypeError, ValueError):
        what = "an integer" if kind is int else "a number"
        raise InputError("simulate", _flag(option), what, repr(text)) from None
    if not v >= lo:
        raise InputError("simulate", _flag(option), f"a value >= {lo:g}", repr(text))
    if hi is not None and not v <= hi:
        raise InputError("simulate", _flag(option), f"a value in [{lo:g}, {hi:g}]", repr(text))
    return v


def _parse_size(text: str) -> tuple[int, int]:
    from fusiongs.errors import InputError

    parts = str(text).lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts) or min(int(p) for p in parts) < 8:
        raise InputError("simulate", "--size", "WxH with integers >= 8 (e.g. 173x130)", repr(text))
    return int(parts[0]), int(parts[1])


def _sweep_config(args: argparse.Namespace):
    """The sweep's SimConfig for ``--sweep-seed`` / ``--split``, before the allowed overrides."""
    from fusiongs.errors import InputError
    from fusiongs.sim.sweep import SPLITS, sweep_scene_config

    given = [_flag(o) for o in _SWEEP_DRAWN if getattr(args, o) is not None]
    if given:
        raise InputError("simulate", given[0], "no value with --sweep-seed (the sweep draws it)",
                         repr(getattr(args, given[0][2:].replace("-", "_"))))
    split = "tuning" if args.split is None else str(args.split)
    if split not in SPLITS:
        raise InputError("simulate", "--split", " or ".join(SPLITS), repr(args.split))
    seed = _parse_number(args.sweep_seed, "sweep_seed", int, 0)
    seeds = SPLITS[split]
    if seed not in seeds:
        raise InputError("simulate", "--sweep-seed", f"a {split} seed, {seeds.start} to {seeds.stop - 1} "
                         "(choose the split with --split)", repr(args.sweep_seed))
    return sweep_scene_config(seed, split)


def config_from_args(args: argparse.Namespace):
    """Build a validated ``SimConfig`` from parsed arguments (raises ``InputError``)."""
    import dataclasses

    from fusiongs.errors import InputError
    from fusiongs.events.stream import CFA_PATTERNS
    from fusiongs.sim.presets import PRESETS
    from fusiongs.sim.simulate import FRAME_RESPONSES, SimConfig

    if args.sweep_seed is not None:
        base = _sweep_config(args)
        numbers = {o: _NUMBERS[o] for o in _SWEEP_OVERRIDES}
    else:
        if args.split is not None:
            raise InputError("simulate", "--split", "only together with --sweep-seed", repr(args.split))
        base, numbers = SimConfig(), _NUMBERS
    kw = {}
    if args.sweep_seed is None:
        preset = "boxes" if args.preset is None else args.preset
        if preset not in PRESETS:
            raise InputError("simulate", "--preset", f"one of {', '.join(PRESETS)}", repr(args.preset))
        cfa = None if args.cfa is None or str(args.cfa).lower() == "none" else str(args.cfa).upper()
        if cfa is not None and cfa not in CFA_PATTERNS:
            raise InputError("simulate", "--cfa", f"one of {', '.join(CFA_PATTERNS)} or none", repr(args.cfa))
        response = "srgb" if args.frame_response is None else str(args.frame_response).lower()
        if response not in FRAME_RESPONSES:
            raise InputError("simulate", "--frame-response", " or ".join(FRAME_RESPONSES),
                             repr(args.frame_response))
        kw.update(preset=preset, cfa=cfa, frame_response=response)
        dvs = {}
        for opt, (fld, unit, lo, hi) in _DVS_NUMBERS.items():
            if getattr(args, opt) is not None:
                dvs[fld] = _parse_number(getattr(args, opt), opt, float, lo, hi) * unit
        kw["dvs"] = dataclasses.replace(base.dvs, **dvs)
    if args.size is not None:
        kw["width"], kw["height"] = _parse_size(args.size)
    for opt, (fld, kind, lo, hi) in numbers.items():
        if getattr(args, opt) is not None:
            kw[fld] = _parse_number(getattr(args, opt), opt, kind, lo, hi)
    if getattr(args, "refractory_reset", False):
        kw["dvs"] = dataclasses.replace(kw.get("dvs", base.dvs), refractory_reset=True)
    cfg = dataclasses.replace(base, **kw)
    if args.sweep_seed is not None and not cfg.exposure <= cfg.duration / max(cfg.frames, 1):
        raise InputError("simulate", "--frames" if args.frames is not None else "--duration",
                         f"at most {int(cfg.duration / cfg.exposure)} frames in {cfg.duration:g} s "
                         f"(the drawn exposure is {cfg.exposure:.4f} s)",
                         f"{cfg.frames} frames in {cfg.duration:g} s")
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
    if args.sweep_seed is not None:
        res.stats["sweep"] = {"seed": cfg.seed, "split": args.split or "tuning"}
    write_simulated_scene(res.scene, res.gt, out, stats=res.stats, overwrite=args.overwrite)
    s = res.stats
    sweep = f" (sweep seed {cfg.seed}, {s['sweep']['split']})" if "sweep" in s else ""
    print(f"wrote {out}: preset {cfg.preset}{sweep}, {cfg.width}x{cfg.height}, {cfg.duration:g} s, "
          f"{len(res.scene.frames)} {cfg.frame_response} frames, {s['events']} events "
          f"({s['events_per_pixel']:.1f}/pixel, ON {s['on_fraction']:.2f}), thresholds ON "
          f"{s['theta_on']:.3f} OFF {s['theta_off']:.3f}, mean blur {s['blur_px']:.1f} px, "
          f"{s['seconds_total']:.1f} s")
    return 0
