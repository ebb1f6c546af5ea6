"""Threshold estimation (``fusiongs calibrate``) over the simulator's sensor sweep, and deblurring with it.

Scenes are drawn by :func:`fusiongs.sim.sweep.sweep_scene_config` (preset, CFA, sRGB or linear
frames, exposure, camera speed and an event sensor drawn from the whole range: thresholds 0.1-0.6,
OFF/ON 0.5-2, spread, refractory period, background activity, hot pixels, leak). Defaults are
chosen on ``--split tuning``; figures are reported from ``--split test`` only.

Per scene the table prints the true ON/OFF thresholds, the estimate per channel and the relative
error; with ``--deblur`` also deblur-view PSNR of the blurry input, EDI with the true thresholds,
EDI with the estimated ones, fusiongs without events, fusiongs's renders before the exposure-ratio
correction (``render``) and fusiongs (all measured in this run).

    PYTHONPATH=. python benchmarks/bench_calibrate.py --split test --seeds 1000-1011
    PYTHONPATH=. python benchmarks/bench_calibrate.py --split test --seeds 1000-1011 --deblur
    PYTHONPATH=. python benchmarks/bench_calibrate.py --split test --seeds 1000-1011 --refine

``--refine`` also runs ``fusiongs calibrate --refine`` (deblur's frames-only warm-up, then each θ
raised to what its renders fit to the counts) and prints the refined estimate's errors beside the
estimator's, with the warm-up's seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402

from fusiongs.calibrate.estimate import estimate_thresholds  # noqa: E402
from fusiongs.calibrate.options import CalibrateOptions  # noqa: E402
from fusiongs.io.scene_io import load_scene  # noqa: E402
from fusiongs.io.truth import read_sim_facts, true_thresholds  # noqa: E402
from fusiongs.sim.simulate import run_simulation  # noqa: E402
from fusiongs.sim.sweep import sweep_scene_config  # noqa: E402
from fusiongs.sim.write import write_simulated_scene  # noqa: E402


def parse_seeds(text: str) -> list[int]:
    """``"1000-1011"`` or ``"0,3,5"`` -> seeds."""
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            a, b = (int(v) for v in part.split("-"))
            out.extend(range(a, b + 1))
        elif part:
            out.append(int(part))
    return out


def scene_for(root: Path, seed: int, split: str, smoke: bool = False) -> Path:
    """The sweep scene of ``seed`` under ``root`` (simulated on first use); with ``smoke``, shrunk
    by :data:`benchmarks._sweep.SMOKE_SCENE` (CI's smoke run only)."""
    path = root / (f"{split}_{seed}" + ("_smoke" if smoke else ""))
    if not (path / "scene.json").is_file():
        cfg = sweep_scene_config(seed, split)
        if smoke:
            from benchmarks._sweep import smoke_config

            cfg = smoke_config(cfg)
        res = run_simulation(cfg)
        write_simulated_scene(res.scene, res.gt, path, stats=res.stats, overwrite=True)
    return path


def relative_errors(est, truth) -> tuple[np.ndarray, np.ndarray]:
    """``(ON, OFF)`` relative errors ``[C]`` each of an estimate against the truth
    (:class:`~fusiongs.events.thresholds.SensorThresholds` both)."""
    return est.theta_pos / truth.theta_pos - 1, est.theta_neg / truth.theta_neg - 1


def calibrate_row(scene_dir: Path, opts: CalibrateOptions, refine_cfg=None) -> dict:
    """Estimate on one scene: truth, estimate, relative errors and seconds; with ``refine_cfg`` (a
    deblur config) also the refined estimate (:func:`fusiongs.pipeline.refine.refine_calibration`)."""
    scene = load_scene(scene_dir)
    t0 = time.perf_counter()
    est = estimate_thresholds(scene.frames, scene.events, opts)
    seconds = time.perf_counter() - t0
    truth = true_thresholds(scene_dir, scene.events.cfa)
    facts = read_sim_facts(scene_dir) or {}
    err_p, err_n = relative_errors(est, truth)
    refined = None
    if refine_cfg is not None:
        from fusiongs.pipeline.refine import refine_calibration

        t1 = time.perf_counter()
        ref = refine_calibration(scene, est, refine_cfg, scene_dir, log=lambda *_: None)
        rp, rn = relative_errors(ref, truth)
        refined = {"est_pos": ref.theta_pos.tolist(), "est_neg": ref.theta_neg.tolist(),
                   "err_pos": rp.tolist(), "err_neg": rn.tolist(),
                   "max_abs_err": float(np.max(np.abs(np.concatenate([rp, rn])))),
                   "seconds": time.perf_counter() - t1}
    return {"scene": scene_dir.name, "preset": facts.get("preset"), "cfa": scene.events.cfa or "grey",
            "response": scene.frames.response, "events": len(scene.events),
            "sensor": {k: facts.get(k) for k in ("theta_sigma", "refractory_s", "ba_rate_hz",
                                                   "hot_pixel_fraction", "leak_rate_hz", "exposure",
                                                   "blur_px")},
            "true": [float(truth.theta_pos[0]), float(truth.theta_neg[0])],
            "est_pos": est.theta_pos.tolist(), "est_neg": est.theta_neg.tolist(),
            "std_pos": est.std_pos.tolist(), "std_neg": est.std_neg.tolist(),
            "err_pos": err_p.tolist(), "err_neg": err_n.tolist(),
            "max_abs_err": float(np.max(np.abs(np.concatenate([err_p, err_n])))),
            "seconds": seconds, "calibration": est.to_dict(), "refined": refined}


def deblur_row(scene_dir: Path, out: Path, config: str | None, overrides: list[str]) -> dict:
    """Deblur-view PSNR of blurry / EDI (true θ) / EDI (estimated θ) / fusiongs no events / fusiongs.

    Runs go through :func:`bench_deblur.run_one` with ``reuse``: a finished run with the same
    settings is read back, so an interrupted sweep resumes where it stopped.
    """
    from benchmarks.bench_deblur import run_one

    res = {}
    for key, extra in (("no_events", ["events.enabled=false"]), ("fusiongs", [])):
        r = run_one(scene_dir, out / key, config, [*overrides, *extra], reuse=True)
        m = r["mean"]["deblur"]
        res[key] = m["fusiongs"]["psnr"]
        res[f"seconds_{key}"] = r["wall_seconds"]
        if key == "fusiongs":
            for peer in ("blurry", "edi", "edi_true_theta"):
                res[peer] = m[peer]["psnr"] if peer in m else float("nan")
            # the renders before the exposure-ratio correction (the run's own column; absent when off)
            res["render"] = m["fusiongs_render"]["psnr"] if "fusiongs_render" in m else float("nan")
            res["seconds"] = r["seconds"]
    return res


def format_rows(rows: list[dict]) -> str:
    lines = [f"{'scene':<14}{'preset':<9}{'cfa':<6}{'resp':<7}{'sigma':>6}{'refr':>6}{'BA':>6}"
             f"{'true on/off':>13}  {'estimated on/off per channel':<44}{'max err':>8}{'s':>6}"]
    for r in rows:
        s = r["sensor"]
        est = " ".join(f"{p:.3f}/{n:.3f}" for p, n in zip(r["est_pos"], r["est_neg"]))
        lines.append(f"{r['scene']:<14}{r['preset'] or '?':<9}{r['cfa']:<6}{r['response']:<7}"
                     f"{s['theta_sigma'] or 0:>6.3f}{1e3 * (s['refractory_s'] or 0):>5.2f}m"
                     f"{s['ba_rate_hz'] or 0:>6.2f}{r['true'][0]:>7.3f}/{r['true'][1]:.3f}  {est:<44}"
                     f"{100 * r['max_abs_err']:>7.1f}%{r['seconds']:>6.1f}")
    errs = np.array([r["max_abs_err"] for r in rows])
    lines.append(f"{len(rows)} scenes: max |error| {100 * errs.max():.1f} %, mean of per-scene max "
                 f"{100 * errs.mean():.1f} %, within 10 %: {int((errs <= 0.10).sum())}/{len(rows)}; "
                 f"mean {np.mean([r['seconds'] for r in rows]):.1f} s per scene")
    return "\n".join(lines)


def format_refined(rows: list[dict]) -> str:
    """The estimator's and the refined estimate's errors per scene (rows with ``refined``)."""
    lines = [f"{'scene':<14}{'estimated on/off per channel':<44}{'max err':>8}  "
             f"{'refined on/off per channel':<44}{'max err':>8}{'s':>7}"]
    rows = [r for r in rows if r.get("refined")]
    for r in rows:
        f = r["refined"]
        est = " ".join(f"{p:.3f}/{n:.3f}" for p, n in zip(r["est_pos"], r["est_neg"]))
        ref = " ".join(f"{p:.3f}/{n:.3f}" for p, n in zip(f["est_pos"], f["est_neg"]))
        lines.append(f"{r['scene']:<14}{est:<44}{100 * r['max_abs_err']:>7.1f}%  {ref:<44}"
                     f"{100 * f['max_abs_err']:>7.1f}%{f['seconds']:>7.1f}")
    for key, label in (("max_abs_err", "estimator"), ("refined", "refined")):
        e = np.array([r[key] if key == "max_abs_err" else r[key]["max_abs_err"] for r in rows])
        lines.append(f"{label}: within 10 % {int((e <= 0.10).sum())}/{len(rows)}, mean of per-scene max "
                     f"{100 * e.mean():.1f} %, max {100 * e.max():.1f} %")
    return "\n".join(lines)


def format_deblur(rows: list[dict]) -> str:
    keys = ("blurry", "edi_true_theta", "edi", "no_events", "render", "fusiongs")
    lines = [f"{'scene':<14}" + "".join(f"{k:>16}" for k in keys) + f"{'events gain':>13}"]
    for r in rows:
        d = r["deblur"]
        lines.append(f"{r['scene']:<14}" + "".join(f"{d.get(k, float('nan')):>16.2f}" for k in keys)
                     + f"{d['fusiongs'] - d['no_events']:>+13.2f}")
    mean = {k: float(np.mean([r["deblur"].get(k, float("nan")) for r in rows])) for k in keys}
    lines.append(f"{'mean':<14}" + "".join(f"{mean[k]:>16.2f}" for k in keys)
                 + f"{mean['fusiongs'] - mean['no_events']:>+13.2f}")
    gain = mean["fusiongs"] - mean["edi_true_theta"]
    lines.append(f"fusiongs - EDI (true thresholds) on the mean: {gain:+.2f} dB;"
                 f" scenes where events cost PSNR: "
                 f"{sum(r['deblur']['fusiongs'] < r['deblur']['no_events'] for r in rows)}/{len(rows)}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--split", choices=("tuning", "test"), default="test")
    ap.add_argument("--seeds", default="1000-1011", help="e.g. 1000-1011 or 0,1,2")
    ap.add_argument("--root", default="bench_out/sweep", help="scenes and runs are kept here")
    ap.add_argument("--deblur", action="store_true", help="also deblur every scene (with and without events)")
    ap.add_argument("--config", default=None, help="deblur config (default: the defaults)")
    ap.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="CalibrateOptions field override (tuning only)")
    ap.add_argument("--refine", action="store_true",
                    help="also the refined estimate (calibrate --refine, with --config and overrides)")
    ap.add_argument("--json", default=None, help="write all rows to this JSON file")
    ap.add_argument("--smoke", action="store_true",
                    help="tiny scenes (benchmarks/smoke.sh: checks the script runs; no figures)")
    ap.add_argument("overrides", nargs="*", help="deblur config overrides key=value")
    args = ap.parse_args(argv)
    root = Path(args.root)
    opts = CalibrateOptions()
    for kv in args.option:
        k, v = kv.split("=", 1)
        cur = getattr(opts, k)
        val = v.lower() in ("1", "true", "yes") if isinstance(cur, bool) else type(cur)(v)
        opts = type(opts)(**{**opts.__dict__, k: val})
    refine_cfg = None
    if args.refine:
        from fusiongs.pipeline.deblur import resolve_config

        refine_cfg = resolve_config(args.config, ["output.progress=false", *args.overrides])
    rows = []
    for seed in parse_seeds(args.seeds):
        path = scene_for(root / "scenes", seed, args.split, args.smoke)
        row = calibrate_row(path, opts, refine_cfg)
        if args.deblur:
            row["deblur"] = deblur_row(path, root / "runs" / path.name, args.config, args.overrides)
        rows.append(row)
        print(format_rows([row]).splitlines()[1], flush=True)
    print()
    print(format_rows(rows))
    if args.refine:
        print()
        print(format_refined(rows))
    if args.deblur:
        print()
        print(format_deblur(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
