"""Quality and speed of ``fusiongs deblur`` on simulated scenes, with blurry input and EDI beside it.

Scenes come from ``fusiongs simulate`` (173x130, 12 frames over 1 s, ~8 million events by default;
grey and RGGB events); each is deblurred with a config, and the table prints mean deblur-view and
novel-view PSNR / SSIM for the blurry input, EDI (threshold from consecutive-frame consistency),
fusiongs's renders and its deblurred frames (the renders after the exposure-ratio correction; novel
instants are renders only), all measured in the same run, plus seconds per iteration and the share
spent rendering.
``--ablation`` adds variants on the first scene (and the first colour scene for mask vs demosaic).

    PYTHONPATH=. python benchmarks/bench_deblur.py --presets boxes,wall --seeds 0,1 --cfa none,RGGB
    PYTHONPATH=. python benchmarks/bench_deblur.py --ablation --presets boxes --seeds 0
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

from fusiongs.configs.load import to_dict  # noqa: E402
from fusiongs.pipeline.deblur import resolve_config, run_deblur  # noqa: E402
from fusiongs.sim.simulate import SimConfig, run_simulation  # noqa: E402
from fusiongs.sim.write import write_simulated_scene  # noqa: E402

ABLATIONS = {
    "no events": ["events.enabled=false"],
    "theta fixed at the EDI estimate": ["threshold.learn=false"],
    "theta fixed at 0.22": ["threshold.learn=false", "threshold.estimate=false"],
    "full (mse, theta learned)": [],
    "band": ["events.loss=band"],
    "pvc": ["events.loss=pvc"],
    "N=1": ["blur.n_samples=1"],
    "N=5": ["blur.n_samples=5"],
    "N=9": ["blur.n_samples=9"],
}
COLOUR_ABLATIONS = {"mask": ["events.colour_mode=mask"], "demosaic": ["events.colour_mode=demosaic"]}


def scene_for(root: Path, preset: str, seed: int, cfa: str | None, args) -> Path:
    name = f"{preset}_s{seed}_{cfa or 'grey'}_{'smoke' if args.smoke else args.size}"
    path = root / "scenes" / name
    if not (path / "scene.json").is_file():
        w, h = (int(v) for v in args.size.split("x"))
        cfg = SimConfig(preset=preset, width=w, height=h, duration=1.0, frames=12, exposure=0.06,
                        cfa=cfa, seed=seed, events_target=args.events or None)
        if args.smoke:  # CI's smoke run: a tiny scene, no figures
            from benchmarks._sweep import smoke_config

            cfg = smoke_config(cfg)
        res = run_simulation(cfg)
        write_simulated_scene(res.scene, res.gt, path, stats=res.stats, overwrite=True)
    return path


def run_one(scene: Path, out: Path, config: str, overrides: list[str], reuse: bool = False) -> dict:
    """Deblur ``scene`` into ``out``; with ``reuse``, a finished run with the same settings is read
    back from its ``bench_result.json`` instead (to resume an interrupted benchmark)."""
    saved = out / "bench_result.json"
    key = {"config": config, "overrides": list(overrides)}
    if reuse and saved.is_file():
        old = json.loads(saved.read_text())
        if old.get("key") == key:
            return old["result"]
    t0 = time.perf_counter()
    result = run_deblur(scene, out, config=config, overrides=["output.progress=false", *overrides],
                        log=lambda *_: None)
    result["wall_seconds"] = time.perf_counter() - t0
    saved.write_text(json.dumps({"key": key, "result": result}, indent=2))
    return result


def settings_key(config: str, overrides: list[str]) -> str:
    """The resolved settings of a run, as text (equal for runs that would train identically)."""
    return json.dumps(to_dict(resolve_config(config, overrides)), sort_keys=True)


def mean_row(results: dict) -> tuple[str, list[str]]:
    """The mean over runs and the quality targets checked on it."""
    def m(getter):
        vals = [getter(r) for r in results.values()]
        return sum(vals) / len(vals)

    fus = m(lambda r: r["mean"]["deblur"]["fusiongs"]["psnr"])
    rend = m(lambda r: r["mean"]["deblur"].get("fusiongs_render", r["mean"]["deblur"]["fusiongs"])["psnr"])
    edi = m(lambda r: r["mean"]["deblur"]["edi"]["psnr"])
    blur = m(lambda r: r["mean"]["deblur"]["blurry"]["psnr"])
    nov = m(lambda r: r["mean"]["novel"]["fusiongs"]["psnr"])
    mins = m(lambda r: r["wall_seconds"] / 60)
    line = (f"| mean of {len(results)} | {blur:.2f} | {edi:.2f} | {rend:.2f} | {fus:.2f} | {nov:.2f} | "
            f"{fus - edi:+.2f} | {fus - blur:+.2f} | {nov - rend:+.2f} | | | {mins:.1f} (wall) |")
    checks = [f"deblur >= EDI + 2 dB: {fus - edi:+.2f} dB -> {'met' if fus - edi >= 2 else 'NOT met'}",
              f"deblur >= blurry + 8 dB: {fus - blur:+.2f} dB -> {'met' if fus - blur >= 8 else 'NOT met'}",
              f"novel within 2 dB of the renders at the deblur views: {nov - rend:+.2f} dB -> "
              f"{'met' if abs(nov - rend) <= 2 else 'NOT met'}; of the corrected deblurred frames: "
              f"{nov - fus:+.2f} dB",
              f"<= 10 min per scene (wall, all included): {mins:.1f} min -> "
              f"{'met' if mins <= 10 else 'NOT met'}"]
    return line, checks


def row(label: str, r: dict) -> str:
    d, n = r["mean"]["deblur"], r["mean"].get("novel", {})
    f = d["fusiongs"]
    edi = d.get("edi", {"psnr": float("nan"), "ssim": float("nan")})
    nov = n.get("fusiongs", {"psnr": float("nan"), "ssim": float("nan")})
    s_it = r["seconds"] / max(r["iterations"], 1)
    share = r["render_seconds"] / max(r["seconds"], 1e-9)
    back = r["backward_seconds"] / max(r["seconds"], 1e-9)
    b = d["blurry"]
    rend = d.get("fusiongs_render", f)  # before the exposure-ratio correction (= f when it is off)
    return (f"| {label} | {b['psnr']:.2f} / {b['ssim']:.3f} | {edi['psnr']:.2f} / {edi['ssim']:.3f} | "
            f"{rend['psnr']:.2f} / {rend['ssim']:.3f} | "
            f"{f['psnr']:.2f} / {f['ssim']:.3f} | {nov['psnr']:.2f} / {nov['ssim']:.3f} | "
            f"{f['psnr'] - edi['psnr']:+.2f} | {f['psnr'] - b['psnr']:+.2f} | "
            f"{nov['psnr'] - rend['psnr']:+.2f} | {s_it:.3f} | {share:.0%} / {back:.0%} | "
            f"{r['seconds'] / 60:.1f} |")


HEADER = ("| run | blurry PSNR/SSIM | EDI | fusiongs render (deblur views) | fusiongs deblur | "
          "fusiongs novel | vs EDI | vs blurry | novel-render | s/it | render fwd/bwd share | train min |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="bench_out/deblur")
    p.add_argument("--config", default="configs/deblur.yaml")
    p.add_argument("--presets", default="boxes,wall")
    p.add_argument("--seeds", default="0,1")
    p.add_argument("--cfa", default="none,RGGB")
    p.add_argument("--size", default="173x130")
    p.add_argument("--events", type=int, default=8_000_000, help="events target (0: nominal thresholds)")
    p.add_argument("--ablation", action="store_true")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--reuse", action="store_true", help="read back finished runs with the same settings")
    p.add_argument("--smoke", action="store_true",
                   help="tiny scenes (benchmarks/smoke.sh: checks the script runs; no figures)")
    p.add_argument("overrides", nargs="*", help="config overrides for every run")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    root = Path(args.out)
    cfas = [None if c.lower() == "none" else c for c in args.cfa.split(",")]
    runs = [(pr, int(s), c) for pr in args.presets.split(",") for s in args.seeds.split(",") for c in cfas]
    print(f"config {args.config} {' '.join(args.overrides)}; torch threads {torch.get_num_threads()}")
    print(HEADER)
    results = {}
    for preset, seed, cfa in runs:
        scene = scene_for(root, preset, seed, cfa, args)
        label = f"{preset} s{seed} {cfa or 'grey'}"
        r = run_one(scene, root / "runs" / scene.name, args.config, args.overrides, args.reuse)
        results[label] = r
        print(row(label, r), flush=True)
        if args.ablation:
            variants = ABLATIONS if cfa is None else COLOUR_ABLATIONS
            done = {settings_key(args.config, args.overrides): r}
            for name, ov in variants.items():
                key = settings_key(args.config, [*args.overrides, *ov])
                if key not in done:  # a variant equal to an earlier run is not trained again
                    out = root / "runs" / f"{scene.name}_{re.sub(r'[^A-Za-z0-9=.-]+', '_', name)}"
                    done[key] = run_one(scene, out, args.config, [*args.overrides, *ov], args.reuse)
                rr = done[key]
                results[f"{label} {name}"] = rr
                print(row(f"{label} {name}", rr), flush=True)
    main_runs = {k: v for k, v in results.items() if k in {f"{pr} s{sd} {c or 'grey'}" for pr, sd, c in runs}}
    if len(main_runs) > 1:
        line, checks = mean_row(main_runs)
        print(line)
        print("\n".join(checks))
    (root / "results.json").write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
