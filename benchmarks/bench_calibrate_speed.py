"""Time of ``fusiongs calibrate``'s estimator with the pixel model chosen by the frames ("auto": the
pixel model test, then one fit, where the recording has frames and an onset) against one fit with the
model given ("step", the reference) on the same scene, measured in the same run (the
target: an 8 M-event 173x130 scene in <= 30 s on 2 CPU cores).

    PYTHONPATH=. python benchmarks/bench_calibrate_speed.py SCENE [--reps 3]

For the target's scene: ``fusiongs simulate -o SCENE --preset boxes --seed 0 --events-target 8000000``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fusiongs.calibrate.estimate import estimate_thresholds  # noqa: E402
from fusiongs.calibrate.options import CalibrateOptions  # noqa: E402
from fusiongs.io.scene_io import load_scene  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    estimate_thresholds(scene.frames, scene.events, CalibrateOptions(pixel_model="step"))  # compile
    rows = {}
    for _ in range(args.reps):  # interleaved, so both see the same machine
        for model in ("step", "auto"):
            t0 = time.perf_counter()
            th = estimate_thresholds(scene.frames, scene.events, CalibrateOptions(pixel_model=model))
            rows.setdefault(model, []).append((time.perf_counter() - t0, th))
    ref = statistics.median(s for s, _ in rows["step"])
    print(f"scene {args.scene}: {len(scene.events)} events, {scene.events.width}x{scene.events.height}, "
          f"{len(scene.frames)} frames; {args.reps} runs each, interleaved")
    print("| pixel model | estimator s, median (x reference) | model kept | theta ON / OFF (first channel) |")
    print("|---|---|---|---|")
    for model, label in (("step", "step, one fit (reference)"), ("auto", "auto (default)")):
        sec = statistics.median(s for s, _ in rows[model])
        th = rows[model][-1][1]
        print(f"| {label} | {sec:.2f} ({sec / ref:.2f}x) | {th.details['pixel_model']} | "
              f"{th.theta_pos[0]:.4f} / {th.theta_neg[0]:.4f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
