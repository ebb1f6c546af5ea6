"""Event-only reconstruction quality on simulated scenes without frames (METHOD.md §2-4).

Renders at held-out instants are scored raw and after a per-channel affine fit (EventNeRF's
protocol: events do not fix absolute brightness or colour balance). Variants: grey and RGGB events,
mse / band / pvc, mask / demosaic, and scalar θ vs θ field on a sensor whose thresholds vary
smoothly across pixels (``theta_gradient``).

    PYTHONPATH=. python benchmarks/bench_event_only.py [--size 96x72] [overrides ...]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

from fusiongs.sim.dvs import DVSParams  # noqa: E402
from fusiongs.sim.simulate import SimConfig, run_simulation  # noqa: E402
from fusiongs.sim.write import write_simulated_scene  # noqa: E402
from fusiongs.train.pipeline import run_deblur  # noqa: E402

# (scene key, run label, overrides)
RUNS = [
    ("wall_s0_grey", "grey band (default)", []),
    ("wall_s0_grey", "grey mse", ["events.loss=mse"]),
    ("wall_s0_grey", "grey pvc", ["events.loss=pvc"]),
    ("boxes_s1_grey", "grey band, boxes", []),
    ("wall_s0_RGGB", "RGGB mask", ["events.colour_mode=mask"]),
    ("wall_s0_RGGB", "RGGB demosaic", ["events.colour_mode=demosaic"]),
    ("wall_s0_grey_grad", "θ varies ±40%: scalar θ", []),
    ("wall_s0_grey_grad", "θ varies ±40%: θ field 3x4", ["threshold.grid=[3,4]"]),
]


def scene(root: Path, key: str, size: str) -> Path:
    path = root / "scenes" / f"{key}_{size}"
    if (path / "scene.json").is_file():
        return path
    preset, seed, cfa = key.split("_")[:3]
    w, h = (int(v) for v in size.split("x"))
    dvs = DVSParams(theta_gradient=0.4) if key.endswith("_grad") else DVSParams()
    cfg = SimConfig(preset=preset, width=w, height=h, duration=0.5, frames=0, novel=6,
                    cfa=None if cfa == "grey" else cfa, seed=int(seed[1:]), dvs=dvs)
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, path, stats=res.stats, overwrite=True)
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="bench_out/event_only")
    p.add_argument("--config", default="configs/event_only.yaml")
    p.add_argument("--size", default="96x72")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("overrides", nargs="*")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    root = Path(args.out)
    print(f"config {args.config} {' '.join(args.overrides)}; size {args.size}; threads {args.threads}")
    print("| run | raw PSNR / SSIM | affine-fit PSNR / SSIM | learned θ+ / θ− | s/it | train s |\n"
          "|---|---|---|---|---|---|")
    results = {}
    for key, label, ov in RUNS:
        sc = scene(root, key, args.size)
        out = root / "runs" / f"{key}_{label.split(':')[-1].strip().replace(' ', '_').replace(',', '')}"
        r = run_deblur(sc, out, config=args.config,
                       overrides=["output.progress=false", *args.overrides, *ov], log=lambda *_: None)
        raw = r["mean"]["novel"]["fusiongs"]
        fit = r["affine_fit"]["mean"]["novel"]["fusiongs"]
        th = json.loads((out / "thresholds.json").read_text())
        tp = "/".join(f"{v:.3f}" for v in th["theta_pos"])
        tn = "/".join(f"{v:.3f}" for v in th["theta_neg"])
        print(f"| {label} | {raw['psnr']:.2f} / {raw['ssim']:.3f} | {fit['psnr']:.2f} / {fit['ssim']:.3f} | "
              f"{tp} / {tn} | {r['seconds'] / max(r['iterations'], 1):.3f} | {r['seconds']:.0f} |",
              flush=True)
        results[label] = r
    (root / "results.json").write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
