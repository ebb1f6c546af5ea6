"""``fusiongs inspect SCENE``: what a scene folder (or a raw event file) holds, and what looks wrong."""

from __future__ import annotations

import argparse

HELP = "Summarise a scene folder or an event file: events, frames, trajectory and warnings."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from fusiongs.commands.convert import add_reader_arguments
    from fusiongs.events.stream import CFA_PATTERNS

    parser.add_argument("path", help="scene folder, scene.json, or an event file")
    add_reader_arguments(parser, CFA_PATTERNS)
    parser.add_argument("--json", action="store_true", help="print the report as JSON")


def run(args: argparse.Namespace) -> int:
    import json

    report = build_report(args)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_report(report))
    return 0


def build_report(args: argparse.Namespace) -> dict:
    """The inspection report as plain JSON-able values (times in seconds)."""
    from pathlib import Path

    import numpy as np

    from fusiongs.events import stats

    path = Path(args.path)
    frames_t = traj = None
    kind = "scene"
    if path.is_dir() or path.name == "scene.json":
        ev, frames_t, traj, src = _read_scene(path, args)
    else:
        ev, frames_t, src = _read_file(path, args)
        kind = "events"
    report = {"source": str(src), "kind": kind, **stats.summarize(ev)}
    warnings = stats.stream_warnings(ev)
    if frames_t is not None and len(frames_t[0]):
        s, e = frames_t  # int64 µs
        exp = (e - s) * 1e-3
        report["frames"] = {"count": int(s.size), "first_start_s": float(s.min()) * 1e-6,
                            "last_end_s": float(e.max()) * 1e-6, "exposure_ms_min": float(exp.min()),
                            "exposure_ms_median": float(np.median(exp)), "exposure_ms_max": float(exp.max())}
        bad = stats.frames_outside_events(s, e, int(ev.t[0]), int(ev.t[-1]))
        if bad.size:
            warnings.append(f"{bad.size} frame(s) with exposures outside the event time range "
                            f"[{ev.t[0] * 1e-6:.6f}, {ev.t[-1] * 1e-6:.6f}] s: indices {bad[:10].tolist()}")
        report["frames"]["events_inside_exposures"] = _events_in_windows(ev.t, s, e)
    else:
        report["frames"] = {"count": 0}
    if traj is not None:
        report["trajectory"] = {"poses": int(traj.t.size), "t_first_s": float(traj.t[0]),
                                "t_last_s": float(traj.t[-1])}
        lo, hi = traj.t[0], traj.t[-1]
        if ev.t[0] * 1e-6 < lo or ev.t[-1] * 1e-6 > hi:
            warnings.append(f"the trajectory [{lo:.6f}, {hi:.6f}] s does not cover the events "
                            f"[{ev.t[0] * 1e-6:.6f}, {ev.t[-1] * 1e-6:.6f}] s")
    report["warnings"] = warnings
    return report


def _events_in_windows(t, s, e) -> int:
    """Number of events inside at least one window ``[s_i, e_i)`` (windows may overlap)."""
    import numpy as np

    order = np.argsort(s, kind="stable")
    s, e = s[order], np.maximum.accumulate(e[order])
    # merge overlapping windows, then count with binary searches
    new = np.concatenate([[True], s[1:] > e[:-1]])
    starts, ends = s[new], np.maximum.reduceat(e, np.flatnonzero(new))
    return int((np.searchsorted(t, ends) - np.searchsorted(t, starts)).sum())


def _read_scene(path, args):
    """Events, frame windows (µs) and trajectory of a scene folder, with the checks of
    ``load_scene`` that need no decoded pixels (frame headers, time ranges)."""
    from fusiongs.errors import InputError
    from fusiongs.events.h5 import read_events_h5
    from fusiongs.io.scene_io import (
        check_events_meet_frames,
        check_frame_files,
        read_scene_spec,
        scene_json_path,
    )

    jp = scene_json_path(path)
    spec = read_scene_spec(jp)
    if spec.events_path is None:
        raise InputError(jp, "events", "a scene with an event stream to inspect", "none")
    ep = jp.parent / spec.events_path
    ev = read_events_h5(ep, spec.camera.width, spec.camera.height, spec.cfa,
                        sort=args.sort, drop_invalid=args.drop_invalid)
    check_events_meet_frames(int(ev.t[0]), int(ev.t[-1]), spec, ep)
    check_frame_files(spec, jp.parent, str(jp))
    import numpy as np

    frames_t = (np.rint(np.array([f.t_start for f in spec.frames], np.float64) * 1e6).astype(np.int64),
                np.rint(np.array([f.t_end for f in spec.frames], np.float64) * 1e6).astype(np.int64))
    traj = None
    if spec.trajectory is not None:
        from fusiongs.camera.tum import read_tum

        traj = read_tum(jp.parent / spec.trajectory)
    return ev, frames_t, traj, jp.parent


def _read_file(path, args):
    from fusiongs.events.readers import detect_format, read_aedat4, read_events

    kw = {"width": args.width, "height": args.height, "cfa": args.cfa, "sort": args.sort,
          "drop_invalid": args.drop_invalid}
    fmt = args.format or detect_format(path)
    if fmt == "aedat4":
        ev, aps = read_aedat4(path, **kw)
        frames_t = None
        if len(aps):
            s = aps.exposure_start if aps.exposure_start is not None else aps.t
            e = aps.exposure_end if aps.exposure_end is not None else aps.t
            frames_t = (s, e)
        return ev, frames_t, path
    return read_events(path, format=fmt, time_unit=args.time_unit, **kw), None, path


def format_report(r: dict) -> str:
    """Human-readable text of :func:`build_report`'s dictionary."""
    lines = [f"{r['kind']}: {r['source']}",
             f"  events       {r['events']:,} over {r['duration_s']:.6f} s "
             f"[{r['t_first_s']:.6f}, {r['t_last_s']:.6f}] s",
             f"  rate         {r['rate_ev_per_s'] / 1e6:.4g} Mev/s",
             f"  ON fraction  {r['on_fraction']:.4f}",
             f"  resolution   {r['width']}x{r['height']}, CFA {r['cfa'] or 'none (monochrome)'}"]
    f = r["frames"]
    if f["count"]:
        lines.append(f"  frames       {f['count']} in [{f['first_start_s']:.6f}, {f['last_end_s']:.6f}] s, "
                     f"exposure {f['exposure_ms_min']:.3g}/{f['exposure_ms_median']:.3g}/"
                     f"{f['exposure_ms_max']:.3g} ms (min/median/max), "
                     f"{f['events_inside_exposures']:,} events inside exposures")
    else:
        lines.append("  frames       none")
    t = r.get("trajectory")
    lines.append(f"  trajectory   {t['poses']} poses in [{t['t_first_s']:.6f}, {t['t_last_s']:.6f}] s"
                 if t else "  trajectory   none (poses to be estimated)")
    lines += [f"  warning: {w}" for w in r["warnings"]] or ["  no warnings"]
    return "\n".join(lines)
