"""Where the camera poses are computed during training: on the host (the default) or on the
training device (the reference, as before session 23), timed in the same process.

Each run trains ``SCENE`` with :func:`fusiongs.train.trainer.train` (outputs written to a temporary
folder) and reads the per-iteration ``step_seconds`` of its history; the reference run moves the
trajectory to the training device before the state is built, which is what the trainer did until
the trajectory was kept on the host. Runs alternate between the two placements (``--repeats``
pairs) so that a drift of the machine hits both. Printed: median and mean seconds per iteration,
the median over the iterations with events (``event`` logged), training seconds, and the ratio to
the reference. On a CPU both placements are the same; the figure that matters is CUDA's.

    PYTHONPATH=. python benchmarks/bench_pose_placement.py SCENE [--config NAME] [--repeats N] \\
        [-- override ...]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import fusiongs.train.trainer as trainer  # noqa: E402
from fusiongs.errors import InputError  # noqa: E402
from fusiongs.io import load_scene  # noqa: E402
from fusiongs.train.pipeline import resolve_config  # noqa: E402


def _train_once(scene, cfg, on_device: bool) -> dict:
    real = trainer.build_trajectory

    def on_training_device(scene_, cfg_):
        return real(scene_, cfg_).to(trainer.training_device(cfg_.device))

    if on_device:
        trainer.build_trajectory = on_training_device
    try:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            tr = trainer.train(scene, cfg, Path(tmp))
            wall = time.perf_counter() - t0
    finally:
        trainer.build_trajectory = real
    h = tr.history
    steps = [s for s in h.step_seconds if s is not None]
    with_events = [s for s, e in zip(h.step_seconds, h.event)
                   if s is not None and e is not None and not math.isnan(e)]
    return {"placement": "device (reference)" if on_device else "host",
            "traj_device": str(tr.state.trajectory.knots.device),
            "median_ms": 1e3 * statistics.median(steps), "mean_ms": 1e3 * statistics.fmean(steps),
            "events_median_ms": 1e3 * statistics.median(with_events) if with_events else float("nan"),
            "train_s": h.seconds, "wall_s": wall, "iterations": len(steps)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--config", default=None)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("overrides", nargs="*")
    a = ap.parse_intermixed_args(argv)
    try:
        cfg = resolve_config(a.config, ["output.progress=false", "output.checkpoint_every=0", *a.overrides])
        scene = load_scene(a.scene)
        trainer.check_device(cfg.device)
    except InputError as e:  # a bad scene folder, config name or override: one line
        print(f"bench_pose_placement: {e}", file=sys.stderr)
        return 2
    rows = []
    for _ in range(a.repeats):
        for on_device in (False, True):
            rows.append(_train_once(scene, cfg, on_device))
            print({k: (round(v, 2) if isinstance(v, float) else v) for k, v in rows[-1].items()},
                  flush=True)
    ref = statistics.fmean(r["mean_ms"] for r in rows if r["placement"] != "host")
    dev = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "cpu"
    print(f"\n{a.scene} ({a.config or 'deblur'}; {dev}, training device {cfg.device})")
    print("| poses computed on | trajectory tensors | s/it median (ms) | mean (ms) | median with events (ms) "
          "| training s | mean / reference |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['placement']} | {r['traj_device']} | {r['median_ms']:.1f} | {r['mean_ms']:.1f} | "
              f"{r['events_median_ms']:.1f} | {r['train_s']:.1f} | {r['mean_ms'] / ref:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
