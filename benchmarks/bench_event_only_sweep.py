"""Event-only colour over the simulator's sensor sweep, on seeds no default was chosen on.

Each seed's scene is drawn by :func:`fusiongs.sim.sweep.sweep_scene_config` (preset, CFA, camera
path and an event sensor from the whole calibration range) and written without frames
(``fusiongs simulate --sweep-seed N --split S --frames 0 --novel 6``); it is reconstructed with
``fusiongs deblur --config event_only``. Per scene the table prints the sensor, the floor peer (the
leaky-integrator / high-pass intensity image of the events, the anchor of event-only training, at
the same instants) and fusiongs: affine-fit PSNR / SSIM (EventNeRF's protocol: events fix neither
brightness nor colour balance), the colour error ΔE00 after the fit, raw PSNR, and the distance to
the floor, and the grey ceiling (the truth's own luminance affine-fitted per channel: the most any
reconstruction from a grey sensor can score; printed for RGGB sensors too, where it does not bind);
then the means and the targets. ``--frames 1`` writes each scene with one (blurry) frame
instead: the run's colour anchor then fixes each channel's gain and offset, and the table adds how
far the raw PSNR (no fit) lies below the affine-fit one (target: within 1 dB). Defaults are
chosen on ``--split tuning``; figures are reported from ``--split test`` only.

``--sensor FIELD=V,...`` also writes each scene again with those fields of its event sensor changed
(the same seed, scene, path and thresholds: ``refractory_s=0`` removes the dead time), runs the
same configuration on it, and prints the change against the scene as drawn, measured in the same
run (what that part of the sensor model costs on these seeds).

    PYTHONPATH=. python benchmarks/bench_event_only_sweep.py --split test --seeds 1000-1007
    PYTHONPATH=. python benchmarks/bench_event_only_sweep.py --split test --sensor refractory_s=0
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch (numba's spinning threads)

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks._sweep import hpf_floor, parse_sensor, resimulate  # noqa: E402
from benchmarks.bench_calibrate import parse_seeds  # noqa: E402
from fusiongs.cli import main as cli  # noqa: E402
from fusiongs.eval.event_floor import grey_ceiling  # noqa: E402
from fusiongs.io.scene_io import load_scene  # noqa: E402
from fusiongs.io.truth import read_sim_facts, true_thresholds  # noqa: E402
from fusiongs.pipeline.deblur import run_deblur  # noqa: E402


def make_scene(root: Path, split: str, seed: int, size: str, duration: float | None, frames: int = 0) -> Path:
    """The seed's scene (simulated once, then reused): events only, or with ``frames`` frames
    (one frame: the colour anchor fixes each channel's gain and offset)."""
    scene = root / "scenes" / (f"{split}_{seed}" + (f"_f{frames}" if frames else ""))
    if not (scene / "scene.json").is_file():
        extra = ["--duration", str(duration)] if duration else []
        rc = cli(["simulate", "--sweep-seed", str(seed), "--split", split, "--size", size,
                  "--frames", str(frames), "--novel", "6", *extra, "-o", str(scene)])
        if rc != 0:
            raise SystemExit(f"simulate failed for seed {seed}")
    return scene


def sensor_tag(sensor: str) -> str:
    """A folder-name suffix for a ``--sensor`` spec: ``"refractory_s=0,ba_rate_hz=0.5"`` ->
    ``"refractory_s0_ba_rate_hz0p5"``."""
    return sensor.replace("=", "").replace(",", "_").replace(".", "p").replace("-", "m")


def twin_scene(scene: Path, sensor: str) -> Path:
    """``scene`` written again (once, then reused) with the ``sensor`` fields of its event sensor
    changed (:func:`benchmarks._sweep.resimulate`), beside it."""
    twin = scene.parent / f"{scene.name}_{sensor_tag(sensor)}"
    if not (twin / "scene.json").is_file():
        resimulate(scene, twin, sensor)
    return twin


def format_change(rows: list[dict], twins: list[dict], sensor: str) -> str:
    """Affine-fit PSNR of each scene as drawn and with the sensor change, and the change."""
    lines = [f"{'scene':<14}{'preset':<10}{'cfa':<6}{'events':>10}{'events ' + sensor:>28}"
             f"{'as drawn':>10}{'changed':>9}{'change':>8}"]
    diffs = []
    for r, t in zip(rows, twins):
        a, b = r["row"]["affine_psnr"], t["row"]["affine_psnr"]
        diffs.append(b - a)
        lines.append(f"{r['scene']:<14}{r['preset']:<10}{r['cfa']:<6}{r['events']:>10}{t['events']:>28}"
                     f"{a:>10.2f}{b:>9.2f}{b - a:>+8.2f}")
    before, after = (float(np.mean([x["row"]["affine_psnr"] for x in rs])) for rs in (rows, twins))
    lines.append(f"{'mean of ' + str(len(rows)):<58}{before:>10.2f}{after:>9.2f}"
                 f"{float(np.mean(diffs)):>+8.2f}")
    return "\n".join(lines)


def run_scene(scene: Path, out: Path, config: str, overrides: list[str]) -> dict:
    """Train (or read back a finished run with the same settings) and collect the row."""
    saved = out / "bench_result.json"
    key = {"config": config, "overrides": overrides}
    if saved.is_file() and json.loads(saved.read_text()).get("key") == key:
        return json.loads(saved.read_text())["row"]
    t0 = time.perf_counter()
    m = run_deblur(scene, out, config=config, overrides=["output.progress=false", *overrides],
                   log=lambda *_: None)
    wall = time.perf_counter() - t0
    fit = m["affine_fit"]["mean"]["novel"]["fusiongs"]
    glob = m["global_affine_fit"]["mean"]["novel"]["fusiongs"]
    row = {"affine_psnr": fit["psnr"], "affine_ssim": fit["ssim"], "delta_e00": fit.get("delta_e00"),
           "global_psnr": glob["psnr"], "global_ssim": glob["ssim"],
           "raw_psnr": m["mean"]["novel"]["fusiongs"]["psnr"], "train_seconds": m["seconds"],
           "wall_seconds": wall, "iterations": m["iterations"],
           "anchor": m.get("colour_anchor", {}).get("anchor", "none")}
    out.mkdir(parents=True, exist_ok=True)
    saved.write_text(json.dumps({"key": key, "row": row}, indent=2))
    return row


def describe(scene_dir: Path) -> dict:
    """Preset, CFA and the true thresholds of a simulated scene."""
    scene = load_scene(scene_dir)
    facts = read_sim_facts(scene_dir) or {}
    theta = true_thresholds(scene_dir, scene.events.cfa)
    on, off = (float(np.mean(theta.theta_pos)), float(np.mean(theta.theta_neg))) if theta is not None \
        else (float("nan"), float("nan"))
    return {"preset": facts.get("preset", "?"), "cfa": scene.events.cfa or "grey", "theta": [on, off],
            "events": len(scene.events), "motion": facts.get("motion_scale"),
            "sensor": {k: facts.get(k) for k in ("theta_sigma", "refractory_s", "ba_rate_hz", "hot_pixels")}}


def format_table(rows: list[dict]) -> str:
    w = max([14] + [len(r["scene"]) + 2 for r in rows])  # a twin's name is longer
    head = (f"{'scene':<{w}}{'preset':<10}{'cfa':<6}{'motion':>7}{'θ on/off':>12}{'events':>10}{'floor':>8}"
            f"{'affine PSNR':>13}{'SSIM':>7}{'ΔE00':>7}{'global':>8}{'raw':>7}{'vs floor':>10}"
            f"{'grey ceil':>10}"
            f"{'train s':>9}")
    lines = [head]
    for r in rows:
        d = r["row"]
        de = d["delta_e00"] if d["delta_e00"] is not None else float("nan")
        lines.append(f"{r['scene']:<{w}}{r['preset']:<10}{r['cfa']:<6}{r['motion'] or float('nan'):>7.2f}"
                     f"{r['theta'][0]:>6.2f}/{r['theta'][1]:<5.2f}{r['events']:>10}{r['floor']['psnr']:>8.2f}"
                     f"{d['affine_psnr']:>13.2f}{d['affine_ssim']:>7.3f}{de:>7.2f}"
                     f"{d.get('global_psnr', float('nan')):>8.2f}{d['raw_psnr']:>7.2f}"
                     f"{d['affine_psnr'] - r['floor']['psnr']:>+10.2f}{r['ceiling']['psnr']:>10.2f}"
                     f"{d['train_seconds']:>9.0f}")
    psnr = np.array([r["row"]["affine_psnr"] for r in rows])
    gap = psnr - np.array([r["floor"]["psnr"] for r in rows])
    def met(ok: bool) -> str:
        return "met" if ok else "NOT met"

    anchored = [r for r in rows if r["row"].get("anchor") == "frame"]
    if anchored:
        raw_gap = np.array([r["row"]["raw_psnr"] - r["row"]["affine_psnr"] for r in anchored])
        lines.append(f"frame-anchored scenes {len(anchored)}: raw − affine-fit PSNR mean "
                     f"{raw_gap.mean():+.2f}, "
                     f"worst {raw_gap.min():+.2f} (target every scene >= -1: {met(raw_gap.min() >= -1)})")
    glob = np.array([r["row"].get("global_psnr", np.nan) for r in rows])
    lines.append(f"mean of {len(rows)}: one global affine fit per scene (all views) "
                 f"{np.nanmean(glob):.2f} dB")
    lines.append(f"mean of {len(rows)}: affine PSNR {psnr.mean():.2f} dB (target >= 23: "
                 f"{met(psnr.mean() >= 23)}), lowest {psnr.min():.2f} (target >= 20: "
                 f"{met(psnr.min() >= 20)}), over the floor "
                 f"{gap.mean():+.2f} on the mean, lowest {gap.min():+.2f} (target every scene >= +6: "
                 f"{met(gap.min() >= 6)})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--split", choices=("tuning", "test"), default="test")
    ap.add_argument("--seeds", default="1000-1007", help="e.g. 1000-1007 or 0,1,2")
    ap.add_argument("--root", default="bench_out/event_only_sweep", help="scenes and runs are kept here")
    ap.add_argument("--size", default="96x72")
    ap.add_argument("--duration", type=float, default=None, help="seconds of events (default: the sweep's)")
    ap.add_argument("--frames", type=int, default=0,
                    help="frames in each scene (1: the one-frame colour anchor; default 0: events only)")
    ap.add_argument("--config", default="event_only")
    ap.add_argument("--json", default=None, help="write the rows here")
    ap.add_argument("--name", default=None,
                    help="keep this variant's runs in ROOT/runs/NAME/ (the scenes are shared)")
    ap.add_argument("--sensor", default=None,
                    help="also run each scene written again with these DVSParams fields changed, e.g. "
                         "refractory_s=0 (the same seed, scene, path and thresholds), and print the change")
    ap.add_argument("overrides", nargs="*")
    args = ap.parse_args(argv)
    if args.sensor:
        try:
            parse_sensor(args.sensor)
        except ValueError as e:  # one line, exit 2, before anything runs
            ap.error(str(e))
    root = Path(args.root)
    rows, twins = [], []
    for seed in parse_seeds(args.seeds):
        scene = make_scene(root, args.split, seed, args.size, args.duration, args.frames)
        for path, out in [(scene, rows)] + ([(twin_scene(scene, args.sensor), twins)] if args.sensor else []):
            tag = path.name
            row = {"scene": tag, **describe(path), "floor": hpf_floor(path), "ceiling": grey_ceiling(path),
                   "row": run_scene(path, root / "runs" / (args.name or "") / tag, args.config,
                                    list(args.overrides))}
            out.append(row)
            print(json.dumps({"scene": tag, "affine_psnr": round(row["row"]["affine_psnr"], 2),
                              "floor": round(row["floor"]["psnr"], 2)}), flush=True)
    print(format_table(rows))
    if args.sensor:
        print(f"\nthe same scenes written again with {args.sensor}:")
        print(format_table(twins))
        print()
        print(format_change(rows, twins, args.sensor))
    if args.json:
        Path(args.json).write_text(json.dumps(rows + twins, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
