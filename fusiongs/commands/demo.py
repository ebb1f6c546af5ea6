"""``fusiongs demo``: simulate a small scene, deblur it and print blurry / EDI / fusiongs metrics."""

from __future__ import annotations

import argparse

HELP = "simulate a small blurry scene with events, deblur it, and print the comparison table"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", "--out", dest="out", default="fusiongs-demo",
                   help="output folder (scene/ and run/)")
    p.add_argument("--preset", default="boxes", help="simulator preset")
    p.add_argument("--cfa", default=None, help="Bayer pattern of a colour event sensor (e.g. RGGB)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("overrides", nargs="*", metavar="key=value", help="deblur config overrides")


def run(args: argparse.Namespace) -> int:
    import time
    from pathlib import Path

    from fusiongs.configs import config_file
    from fusiongs.pipeline.deblur import run_deblur
    from fusiongs.sim.simulate import SimConfig, run_simulation
    from fusiongs.sim.write import write_simulated_scene

    out = Path(args.out)
    t0 = time.perf_counter()
    sim = SimConfig(preset=args.preset, width=96, height=72, duration=0.5, frames=6, exposure=0.05,
                    cfa=args.cfa, seed=args.seed, blur_samples=24, dvs_rate_hz=600.0)
    res = run_simulation(sim)
    write_simulated_scene(res.scene, res.gt, out / "scene", stats=res.stats, overwrite=True)
    print(f"simulated {out / 'scene'} in {time.perf_counter() - t0:.1f} s")
    run_deblur(out / "scene", out / "run", config=config_file("deblur_fast.yaml"),
               overrides=args.overrides)
    print(f"report: {out / 'run' / 'report.png'}  ({time.perf_counter() - t0:.1f} s in all)")
    return 0
