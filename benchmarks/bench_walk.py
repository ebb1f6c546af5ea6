"""Long walks whose view keeps changing: one piece against time chunks, beside EDI with the true
thresholds, measured in the same run.

Each seed draws a walk (preset ``hallway`` or ``walkway``, grey or RGGB events, frame response,
exposure and sensor, from the simulator's sweep with walk presets) of ``--duration`` seconds and
``--frames`` frames at ``--size``, and deblurs it once per ``--chunks`` value (``chunk.seconds``;
0 = one piece), each run in a child process so that its wall time and peak memory (the largest
resident set of the run and its workers) are its own. The table gives, over all frames, the PSNR
of the blurry input, EDI with the true thresholds and fusiongs, the worst frame's margin over its
blurry input, the frames next to a seam against the others (their PSNR; and the gain over EDI of
the frames within ``SEAM_REACH`` of a seam frame against the other frames' gain, in which each
frame's own difficulty cancels), minutes and peak memory. Defaults are chosen on ``--split
tuning``; figures are reported from ``--split test`` only.

    PYTHONPATH=. python benchmarks/bench_walk.py --split test --seeds 1000,1001 --chunks 0,10
    PYTHONPATH=. python benchmarks/bench_walk.py --split tuning --seeds 0 --size 96x72 --duration 10 \\
        --frames 120 --chunks 0,4 -- optim.iterations=1000
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402

from benchmarks._sweep import SMOKE_SCENE  # noqa: E402
from benchmarks.bench_calibrate import parse_seeds  # noqa: E402
from fusiongs.sim.simulate import run_simulation  # noqa: E402
from fusiongs.sim.sweep import SceneRange, sweep_scene_config  # noqa: E402
from fusiongs.sim.write import write_simulated_scene  # noqa: E402

# Runs a command and prints the largest resident set (kB) of it and of every process it waited for
# (the run's worker processes included): a fresh parent per run, so each run's peak is its own.
PEAK = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL); "
        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(r.returncode)")
WALKS = SceneRange(presets=("hallway", "walkway"), motion_scale=(0.8, 1.25), duration=20.0, frames=240)
# A walk's image motion is a few pixels per exposure (hand shake of a few degrees at 1-6 Hz): event
# renders every 2 ms (under half a pixel apart) and 24 renders per exposure resolve it, at half the
# simulator's default cost (its defaults are sized for the fast orbits of the compact presets).
WALK_SIM = {"dvs_rate_hz": 500.0, "blur_samples": 24}


def walk_scene(root: Path, seed: int, split: str, size: str, duration: float, frames: int,
               smoke: bool = False) -> Path:
    """The walk of ``seed`` under ``root`` (simulated on first use)."""
    w, h = (int(v) for v in size.split("x"))
    path = root / (f"{split}_{seed}_{w}x{h}_{duration:g}s_{frames}f" + ("_smoke" if smoke else ""))
    if not (path / "scene.json").is_file():
        cfg = sweep_scene_config(seed, split, scenes=WALKS)
        cfg = dataclasses.replace(cfg, width=w, height=h, duration=duration, frames=frames, **WALK_SIM)
        if smoke:
            cfg = dataclasses.replace(cfg, **(SMOKE_SCENE | {"duration": duration, "frames": frames}))
        res = run_simulation(cfg.validate())
        write_simulated_scene(res.scene, res.gt, path, stats=res.stats, overwrite=True)
    return path


def run_variant(scene: Path, out: Path, chunk: float | None, jobs: int, overrides: list[str]) -> dict:
    """``fusiongs deblur`` in a child process (``chunk.seconds`` set to ``chunk`` unless None); its
    wall time, peak memory and metrics."""
    chunking = [] if chunk is None else [f"chunk.seconds={chunk:g}"]
    cmd = [sys.executable, "-m", "fusiongs", "deblur", str(scene), "-o", str(out), "--jobs", str(jobs),
           "output.progress=false", *chunking, *overrides]
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", PEAK, *cmd], capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"bench_walk: {' '.join(cmd)} failed:\n{proc.stderr[-2000:]}")
    peak_kb = int(proc.stdout.strip().splitlines()[-1])
    metrics = json.loads((out / "metrics.json").read_text())
    return {"wall_s": wall, "peak_gb": peak_kb / 1e6, "metrics": metrics, "chunks": _seams(out)}


def _seams(out: Path) -> list[str]:
    """Frames next to a seam: the last frame taken from one chunk and the first from the next."""
    index = out / "chunks.json"
    if not index.is_file():
        return []
    chunks = json.loads(index.read_text())["chunks"]
    return [name for a, b in zip(chunks, chunks[1:]) for name in (a["frames"][-1:] + b["frames"][:1])]


SEAM_REACH = 5  # frames either side of a seam frame that count as near it


def row_of(seed: int, chunk: float, res: dict) -> dict:
    """One table row: means over all frames, the worst frame over the blurry input, seam frames."""
    views = {n: v for n, v in res["metrics"]["views"].items() if n.startswith("deblur_")}
    per = {m: np.array([v[m]["psnr"] for v in views.values()])
           for m in ("fusiongs", "blurry", "edi_true_theta")}
    names = [n.removeprefix("deblur_") for n in views]
    seam = np.isin(names, res["chunks"])
    # frames within SEAM_REACH of a seam frame: their gain over EDI (which has no seams, so the
    # frames' own difficulty cancels) against the other frames'
    at = np.flatnonzero(seam)
    near = (np.abs(np.arange(len(names))[:, None] - at[None]).min(axis=1) <= SEAM_REACH) if at.size \
        else np.zeros(len(names), bool)
    gain = per["fusiongs"] - per["edi_true_theta"]
    return {"seed": seed, "chunk": chunk, "fusiongs": float(per["fusiongs"].mean()),
            "blurry": float(per["blurry"].mean()), "edi_true": float(per["edi_true_theta"].mean()),
            "worst_vs_blurry": float((per["fusiongs"] - per["blurry"]).min()),
            "seam_vs_others": float(per["fusiongs"][seam].mean() - per["fusiongs"][~seam].mean())
            if seam.any() and (~seam).any() else float("nan"),
            "near_seam_gain_vs_others": float(gain[near].mean() - gain[~near].mean())
            if near.any() and (~near).any() else float("nan"),
            "minutes": res["wall_s"] / 60, "peak_gb": res["peak_gb"], "frames": len(views)}


def format_rows(rows: list[dict]) -> str:
    head = (f"{'seed':>6}{'chunk s':>9}{'frames':>8}{'blurry':>8}{'EDI true θ':>12}{'fusiongs':>10}"
            f"{'vs EDI':>8}{'worst vs blurry':>17}{'seams vs rest':>15}{'near seams vs EDI':>19}"
            f"{'minutes':>9}{'peak GB':>9}  overrides")
    lines = [head]
    for r in rows:
        lines.append(f"{r['seed']:>6}{r['chunk']:>9g}{r['frames']:>8}{r['blurry']:>8.2f}"
                     f"{r['edi_true']:>12.2f}{r['fusiongs']:>10.2f}{r['fusiongs'] - r['edi_true']:>+8.2f}"
                     f"{r['worst_vs_blurry']:>+17.2f}{r['seam_vs_others']:>+15.2f}"
                     f"{r.get('near_seam_gain_vs_others', float('nan')):>+19.2f}{r['minutes']:>9.1f}"
                     f"{r['peak_gb']:>9.2f}  {r.get('tag') or '-'}")
    return "\n".join(lines)


def add_run_arguments(ap: argparse.ArgumentParser, root: str) -> None:
    """The options of the benchmarks that deblur simulated scenes in child processes (this one and
    bench_scaling.py): --jobs, --root, --tag, --json, --smoke and the config overrides."""
    ap.add_argument("--jobs", type=int, default=0, help="--jobs of each run (0: one per core)")
    ap.add_argument("--root", default=root)
    ap.add_argument("--tag", default="", help="names this set of overrides in the run folders and rows")
    ap.add_argument("--json", default=None, help="write the rows here")
    ap.add_argument("--smoke", action="store_true", help="tiny scenes (CI's smoke run)")
    ap.add_argument("overrides", nargs="*", help="config overrides for every run (after --)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("tuning", "test"), default="tuning")
    ap.add_argument("--seeds", default="0", help="e.g. 1000,1001 or 0-3")
    ap.add_argument("--size", default="173x130")
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--frames", type=int, default=240)
    ap.add_argument("--chunks", default="0,10", help="chunk.seconds values to compare (0: one piece)")
    add_run_arguments(ap, "bench_out/walk")
    args = ap.parse_args(argv)
    root = Path(args.root)
    rows = []
    for seed in parse_seeds(args.seeds):
        scene = walk_scene(root / "scenes", seed, args.split, args.size, args.duration, args.frames,
                           args.smoke)
        for chunk in (float(c) for c in args.chunks.split(",")):
            out = root / "runs" / f"{scene.name}_chunk{chunk:g}{'_' + args.tag if args.tag else ''}"
            rows.append(row_of(seed, chunk, run_variant(scene, out, chunk, args.jobs, args.overrides))
                        | {"tag": args.tag})
            print(json.dumps(rows[-1]), flush=True)
    print(format_rows(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
