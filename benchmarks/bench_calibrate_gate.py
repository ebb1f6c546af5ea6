"""Issue 13 diagnosis: is a threshold estimate off because of the counts the dead time loses, or
because of which pixel pairs the refractory gate keeps?

The scene's *twin* is the same scene written again with the sensor's dead time set to 0 and
every other sensor field kept (same seed, scene, path, frames, thresholds, spread and noise; the
twin's frames are the scene's). The twin's counts have lost no crossing. The rows:

- ``scene``: the estimator's default on the scene (``fusiongs calibrate``);
- ``scene, step``: the same with the simulator's pixel model forced (the model of its pixel);
- ``twin, no gate``: the twin's counts and the twin's own gate (it has no dead time, so none);
- ``scene, gate off``: the scene's counts, every pixel pair kept (``refractory_gate=0``);
- ``twin counts, scene's gate``: the twin's counts through the gate of the scene's own events
  (the scene's dead time and fast events): the same pixel pairs as ``scene, step``, and none of
  their counts short.

If ``twin counts, scene's gate`` is as far off as ``scene, step``, the error comes from the pairs
the gate selects; if it is near the truth, from the crossings lost in the kept pairs.

Two more rows test the pixel's own gate (the estimator's fallback where the neighbours' gate
leaves no measurement), the only gate in both:

- ``scene, own gate``: the scene's counts, pairs gated by the pixel's own fast events;
- ``twin, own gate``: the twin's counts, gated by the twin's own fast events at the scene's dead
  time: an ideal sensor (no crossing lost anywhere) with the same selection rule. If it is as far
  off as ``scene, own gate``, the own gate's error is its selection on the pixel's own counts,
  which the dead time does not need to make.

Simulated scenes only (the truth and the simulator's configuration are read). The gate is swapped
in this process only (:func:`estimate_with_gate`); no production code path changes.

    PYTHONPATH=. python benchmarks/bench_calibrate_gate.py SCENE [SCENE ...] [--twins DIR] [--json FILE]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

# before torch: spinning OpenMP threads slow a shared CPU
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import fusiongs.eval.calibrate as calibrate  # noqa: E402
from benchmarks.bench_calibrate import relative_errors  # noqa: E402
from fusiongs.eval.calibrate import CalibrateOptions, estimate_thresholds  # noqa: E402
from fusiongs.eval.calibrate_data import gate_inputs  # noqa: E402
from fusiongs.events.stats import interval_floor  # noqa: E402
from fusiongs.events.stream import EventStream  # noqa: E402
from fusiongs.frames.frameset import FrameSet  # noqa: E402


@contextlib.contextmanager
def gate_from(events: EventStream, jump: float, floor_events: EventStream | None = None):
    """Within the block, :func:`estimate_thresholds` takes its dead time (the interval floor of
    ``floor_events``, by default ``events``) and its refractory gate from ``events`` instead of the
    stream it fits."""
    floor = interval_floor(events if floor_events is None else floor_events, jump)
    saved = calibrate.gate_inputs, calibrate.interval_floor
    calibrate.gate_inputs = lambda frames, _ev, opts, dead: gate_inputs(frames, events, opts, dead)
    calibrate.interval_floor = lambda _ev, _jump: floor
    try:
        yield
    finally:
        calibrate.gate_inputs, calibrate.interval_floor = saved


def estimate_with_gate(frames: FrameSet, events: EventStream, gate_events: EventStream,
                       opts: CalibrateOptions, floor_events: EventStream | None = None):
    """:func:`estimate_thresholds` on ``events`` with the gate of ``gate_events`` and the dead time
    of ``floor_events`` (default ``gate_events``; streams of the same sensor size and span)."""
    for other, what in ((gate_events, "gate's"), (floor_events, "dead time's")):
        if other is not None and (other.width, other.height) != (events.width, events.height):
            raise ValueError(f"the {what} stream is {other.width}x{other.height}, the fitted "
                             f"one {events.width}x{events.height}")
    with gate_from(gate_events, opts.dead_time_jump, floor_events):
        return estimate_thresholds(frames, events, opts)


def errors(est, truth) -> np.ndarray:
    """Relative errors ``[2 C]`` (ON per channel, then OFF per channel)."""
    return np.concatenate(relative_errors(est, truth))


def rows(scene: Path, twin: Path) -> list[dict]:
    """The seven estimates of the module docstring on ``scene`` and its ``twin``."""
    from fusiongs.eval.truth import true_thresholds
    from fusiongs.io.scene_io import load_scene

    sc, tw = load_scene(scene), load_scene(twin)
    truth = true_thresholds(scene, sc.events.cfa)
    step = CalibrateOptions(pixel_model="step")
    own = replace(step, refractory_self=True, refractory_radius=0)  # the pixel's own gate only
    runs = [("scene", lambda: estimate_thresholds(sc.frames, sc.events, CalibrateOptions())),
            ("scene, step", lambda: estimate_thresholds(sc.frames, sc.events, step)),
            ("twin, no gate", lambda: estimate_thresholds(sc.frames, tw.events, step)),
            ("scene, gate off", lambda: estimate_thresholds(sc.frames, sc.events,
                                                            replace(step, refractory_gate=0.0))),
            ("twin counts, scene's gate", lambda: estimate_with_gate(sc.frames, tw.events, sc.events, step)),
            ("scene, own gate", lambda: estimate_thresholds(sc.frames, sc.events, own)),
            ("twin, own gate", lambda: estimate_with_gate(sc.frames, tw.events, tw.events, own,
                                                          floor_events=sc.events))]
    out = []
    for name, run in runs:
        est = run()
        err = errors(est, truth)
        per = est.details.get("per_channel", [])
        out.append({"scene": scene.name, "run": name, "errors": [float(v) for v in err],
                    "largest": float(err[np.argmax(np.abs(err))]),
                    "kept": [c.get("kept") for c in per],
                    "gate": per[0].get("refractory_gate") if per else None})
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+", type=Path)
    p.add_argument("--twins", type=Path, default=Path("bench_out/gate_twins"),
                   help="where the dead-time-free twins are written (reused when present)")
    p.add_argument("--json", type=Path, default=None, help="append one JSON line per row")
    args = p.parse_args(argv)
    for scene in args.scenes:
        if not (scene / "gt" / "sim.json").is_file():
            p.error(f"{scene}: expected a scene of fusiongs simulate (its gt/sim.json is read to make "
                    "the twin and score it); not found")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_event_only_diagnose import resimulate

    print("| scene | run | largest error | errors (ON per channel, OFF per channel) | kept pairs | gate |")
    print("|---|---|---|---|---|---|")
    for scene in args.scenes:
        twin = args.twins / f"{scene.name}_d0"
        if not (twin / "scene.json").exists():
            resimulate(scene, twin, "refractory_s=0")
        for r in rows(scene, twin):
            errs = " ".join(f"{100 * v:+.1f}" for v in r["errors"])
            print(f"| {r['scene']} | {r['run']} | {100 * r['largest']:+.1f} % | {errs} | "
                  f"{sum(k or 0 for k in r['kept'])} | {r['gate']} |", flush=True)
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(r) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
