"""Simulator speed and event counts at the quality size (173x130, 12 frames over 1 s).

Usage: ``PYTHONPATH=. python benchmarks/bench_simulate.py [--presets boxes,wall] [--cfa RGGB]
[--events-target 8000000] [--threads 2]``.

Prints one row per preset: events, thresholds used, mean blur, time per stage and in total against
the 180 s target. The same-run reference is the bare ray-casting cost (median of 20 renders times
the number of renders the simulation makes): the floor the pipeline cannot go below.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch: no spinning OpenMP pools

import numpy as np  # noqa: E402
import torch  # noqa: E402

from fusiongs.camera.pinhole import PinholeCamera  # noqa: E402
from fusiongs.sim.motion import make_trajectory  # noqa: E402
from fusiongs.sim.presets import get_preset  # noqa: E402
from fusiongs.sim.raycast import RayCaster, fov_focal  # noqa: E402
from fusiongs.sim.simulate import SimConfig, novel_instants, run_simulation  # noqa: E402

TARGET_S = 180.0


def render_reference(cfg: SimConfig) -> float:
    """Median seconds of one bare render at the config's size and supersampling."""
    pr = get_preset(cfg.preset)
    f = fov_focal(cfg.width, pr.hfov_deg)
    cam = PinholeCamera(cfg.width, cfg.height, f, f, cfg.width / 2, cfg.height / 2)
    caster = RayCaster(pr.world, cam, cfg.supersample, 0)
    poses = make_trajectory(pr.motion, cfg.duration, np.random.default_rng(0)).c2w(np.linspace(0, 1, 21))
    caster.render(poses[0])
    times = []
    for p in poses[1:]:
        t0 = time.perf_counter()
        caster.render(p)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", default="boxes")
    ap.add_argument("--cfa", default="RGGB")
    ap.add_argument("--events-target", type=int, default=8_000_000, help="0: nominal thresholds")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--smoke", action="store_true",
                    help="a tiny scene (benchmarks/smoke.sh: checks the script runs; no figures)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"threads {args.threads}, load average {os.getloadavg()[0]:.1f} (2-core machine shared with "
          "other jobs: timings are pessimistic)")
    print("| preset | size | frames | events | theta on/off | blur px | renders s | dvs s | frames+gt s "
          "| total s | target s | reference s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.presets.split(","):
        cfg = SimConfig(preset=name, cfa=None if args.cfa == "none" else args.cfa,
                        events_target=args.events_target or None)
        if args.smoke:
            from benchmarks._sweep import smoke_config

            cfg = smoke_config(cfg)
        n_renders = (round(cfg.duration * cfg.dvs_rate_hz) + 1 + cfg.frames * (cfg.blur_samples + 1)
                     + len(novel_instants(cfg)))
        ref = render_reference(cfg) * n_renders
        s = run_simulation(cfg).stats
        print(f"| {name} | {cfg.width}x{cfg.height} | {cfg.frames} | {s['events']:,} | "
              f"{s['theta_on']:.3f}/{s['theta_off']:.3f} | {s['blur_px']:.1f} | "
              f"{s['seconds_event_renders']:.1f} | {s['seconds_dvs']:.1f} | "
              f"{s['seconds_frames_truth']:.1f} | {s['seconds_total']:.1f} | "
              f"{TARGET_S:.0f} | {ref:.1f} |", flush=True)


if __name__ == "__main__":
    main()
