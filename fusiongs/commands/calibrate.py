"""``fusiongs calibrate SCENE``: the event sensor's ON / OFF contrast thresholds per colour channel."""

from __future__ import annotations

import argparse

HELP = "Estimate the event sensor's ON/OFF contrast thresholds (per CFA channel) from frames and events."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="scene folder (or its scene.json)")
    parser.add_argument("-o", "--output", default="calibration.json",
                        help="calibration file to write, or a folder for OUT/calibration.json "
                             "(default ./calibration.json)")
    parser.add_argument("--json", action="store_true", help="print the calibration as one JSON object")
    parser.add_argument("--samples", type=int, default=None,
                        help="instants per exposure of the EDI ratio (default 12)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the pixel subsets and bootstrap")
    parser.add_argument("--pixel-model", choices=("auto", "step", "reset"), default="auto",
                        help="how the pixels lose events in their dead time: reset (a DVS pixel held "
                             "in reset: each event weighted by the crossings it stands for), step "
                             "(the reference level keeps every crossing: fast pixels gated only), or "
                             "auto: reset when the frames' coefficient on the crossings it adds "
                             "exceeds 0.5 (step without frames; default)")
    parser.add_argument("--ratio", choices=("iv", "round_trip", "auto"), default=None,
                        help="ON/OFF ratio from the IV fit, from the pixels' round trips (frame pairs "
                             "where a pixel came back through many events; the IV fit's scale kept), or "
                             "auto: the round trips' where the two differ by more than 5 %% "
                             "(default: the library's, CalibrateOptions.ratio; see docs/calibration.md)")
    parser.add_argument("--sort", action="store_true", help="sort unsorted event timestamps")
    parser.add_argument("--drop-invalid", action="store_true",
                        help="drop events outside the sensor instead of failing")
    parser.add_argument("--refine", action="store_true",
                        help="then run deblur's frames-only warm-up (--config and key=value as deblur's) "
                             "and raise each threshold to what its renders fit to the event counts, as "
                             "deblur does when its events start (threshold.render_floor): minutes "
                             "instead of seconds; mends estimates that read low, never lowers one "
                             "(see docs/calibration.md, section 'Known limits')")
    parser.add_argument("--config", default=None,
                        help="with --refine: deblur's YAML config, a path or a preset name (default: deblur)")
    parser.add_argument("overrides", nargs="*", metavar="key=value",
                        help="with --refine: deblur config overrides, e.g. events.warmup=800")


def output_file(path: str):
    """``path`` itself when it names a ``.json`` file, else ``path/calibration.json``."""
    from pathlib import Path

    p = Path(path)
    return p if p.suffix.lower() == ".json" else p / "calibration.json"


def run(args: argparse.Namespace) -> int:
    import dataclasses
    import json
    import sys
    import time

    from fusiongs.calibrate.estimate import estimate_thresholds
    from fusiongs.calibrate.options import CalibrateOptions
    from fusiongs.errors import InputError
    from fusiongs.events.thresholds import calibration_document, calibration_warnings, write_calibration
    from fusiongs.io.scene_io import load_scene
    from fusiongs.io.truth import true_thresholds

    opts = CalibrateOptions(seed=args.seed, pixel_model=args.pixel_model)
    if args.ratio is not None:
        opts = dataclasses.replace(opts, ratio=args.ratio)
    if args.samples is not None:
        if args.samples < 2:
            raise InputError("command line", "--samples", "an integer >= 2", args.samples)
        opts = dataclasses.replace(opts, n_samples=args.samples)
    if not args.refine and (args.config is not None or args.overrides):
        raise InputError("command line", "--config / key=value", "only with --refine",
                         args.config or " ".join(args.overrides))
    cfg = None
    if args.refine:  # a bad config is said before the scene is read
        from fusiongs.pipeline.deblur import resolve_config

        cfg = resolve_config(args.config, args.overrides)
    scene = load_scene(args.scene, sort_events=args.sort, drop_invalid_events=args.drop_invalid)
    if scene.events is None or len(scene.events) == 0:
        raise InputError(args.scene, "events", "a scene with events (thresholds are measured from them)",
                         "no events")
    if cfg is not None:
        from fusiongs.pipeline.refine import check_refine

        check_refine(scene, cfg, args.scene)
    t0 = time.perf_counter()
    th = estimate_thresholds(scene.frames, scene.events, opts)
    if cfg is not None:
        from fusiongs.pipeline.refine import refine_calibration

        th = refine_calibration(scene, th, cfg, args.scene, log=lambda m: print(m, file=sys.stderr))
    seconds = time.perf_counter() - t0
    truth = true_thresholds(args.scene, scene.events.cfa)
    extra = {"scene": str(args.scene), "seconds": round(seconds, 3)}
    if truth is not None:
        extra["truth"] = truth.to_dict()
    out = write_calibration(output_file(args.output), th, **extra)
    if args.json:
        print(json.dumps(calibration_document(th, **extra)))
        return 0
    print(format_table(th, truth))
    dead = th.details.get("dead_time_us")
    if isinstance(dead, int | float):
        period = th.details.get("refractory_period_us")
        head = (f"refractory period (where a pixel's event intervals step up): {period:.0f} µs; dead time "
                f"(the gates' unit, the left edge of its histogram bin): {dead:.0f} µs"
                if isinstance(period, int | float) and period != dead else
                f"dead time (floor of the intervals between a pixel's events): {dead:.0f} µs")
        print(f"{head}; deblur takes the counts of pixels firing faster than events.censor (default 2) "
              "times it as lower bounds"
              if dead > 0 else
              "dead time: no refractory floor in the event intervals (no counts are censored)")
    if str(th.details.get("pixel_model", "")).startswith("reset") and dead:
        end = " (+ the blind time after a burst's last event)" if th.details.get("reset_burst_end") else ""
        print("pixel model: reset (held in reset during its dead time): each event counted as the "
              f"threshold crossings it stands for, interval / (interval - dead time){end}")
    test = th.details.get("pixel_model_test")
    if isinstance(test, dict):
        beta = test.get("coefficient")
        print("pixel model test: the frames' coefficient on the crossings a reset pixel's events add: "
              + (f"{beta:.2f}" if isinstance(beta, int | float) else "not measurable")
              + f" (reset above {test['cut']} up to {test['max']}; channels "
              f"{', '.join(test['channels']) or 'none'})")
    spread = th.details.get("threshold_spread")
    if isinstance(spread, dict):
        sd = [float(v) ** 0.5 for v in spread["log_variance"]]
        print(f"threshold spread over pixels (std of log theta, from the events): ON {sd[0]:.3f}, OFF "
              f"{sd[1]:.3f}; the fit's harmonic mean was raised x{spread['factor'][0]:.3f} / "
              f"x{spread['factor'][1]:.3f}")
    gates = [c.get("refractory_gate") for c in th.details.get("per_channel", [])]
    if any(g and g != "neighbours" and g != "off" for g in gates):
        print("refractory gate per channel: " + ", ".join(f"{n} {g}" for n, g in zip(th.channels, gates)))
    if cfg is None:  # a refinement's training said them when it started
        for warning in calibration_warnings(th):
            print(f"warning: {warning}", file=sys.stderr)
    if not th.scale_known:
        why = ("the frames' consistency fit failed on every channel"
               if th.details.get("consistency_fit") else "fewer than two frames")
        print(f"note: {why}, so the thresholds are known only up to a common scale: "
              f"the ON/OFF ratio is measured, the scale assumed ({th.details.get('assumed_scale')})",
              file=sys.stderr)
    refine = th.details.get("refine")
    if isinstance(refine, dict):
        before = refine["before"]
        print(f"refined: the frames-only warm-up ({refine['iterations']} iterations) rendered over "
              f"{refine['windows']} event windows; before: ON "
              + "/".join(f"{v:.4f}" for v in before[0]) + ", OFF " + "/".join(f"{v:.4f}" for v in before[1])
              + ("; raised where the renders fit a larger θ" if any(map(any, refine["raised"]))
                 else "; nothing raised"))
    print(f"wrote {out} ({th.method}; {seconds:.1f} s)")
    return 0


def format_table(th, truth=None) -> str:
    """A small text table: per channel ON, OFF (± one sigma), OFF/ON, and the truth when known."""
    head = f"{'channel':<8} {'theta_on':>16} {'theta_off':>16} {'off/on':>7}"
    if truth is not None:
        head += f" {'true on':>8} {'true off':>8} {'err on':>7} {'err off':>7}"
    rows = [head]
    for c, name in enumerate(th.channels):
        tp, tn = th.theta_pos[c], th.theta_neg[c]
        row = (f"{name:<8} {tp:8.4f} ± {th.std_pos[c]:<5.3f} {tn:8.4f} ± {th.std_neg[c]:<5.3f} "
               f"{tn / tp:7.3f}")
        if truth is not None:
            ttp, ttn = truth.theta_pos[c], truth.theta_neg[c]
            row += f" {ttp:8.4f} {ttn:8.4f} {100 * (tp / ttp - 1):+6.1f}% {100 * (tn / ttn - 1):+6.1f}%"
        rows.append(row)
    return "\n".join(rows)
