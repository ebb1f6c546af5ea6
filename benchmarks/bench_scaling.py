"""How the cost of ``fusiongs deblur`` grows with the sensor's pixels and with the number of frames,
beside its quality and EDI with the true thresholds, measured in the same run.

Each case ``WxH:F`` draws the seed's scene from the simulator's sweep (its preset, sensor, events
and frame response) at ``W``x``H`` with ``F`` frames at the sweep's 12 frames a second (so ``F``
frames last ``F / 12`` s and a clip longer than ``chunk.seconds`` is cut in chunks, as the default
does), and deblurs it with the default configuration (plus any overrides) in a child process, so
that its wall time and peak memory (largest resident set of the run and its workers) are its own.
Where the time goes comes from the run's ``history.jsonl``: the seconds of the half-resolution
warm-up steps (no events), of the full-resolution steps with events, and everything else
(calibration, EDI, stereo initialisation, outputs and scoring; not given for a chunked run, whose
chunks' step seconds are summed while they run side by side); "boxes" is how many of the final
Gaussians' projected 3σ boxes cover a pixel on average, which the compositing's work per pixel
follows. The last columns give each case's wall time and seconds per full-resolution step against
the first case's, measured in this run.

    PYTHONPATH=. python benchmarks/bench_scaling.py --split test --seeds 1000 \\
        --cases 173x130:24,346x260:24,640x480:24
    PYTHONPATH=. python benchmarks/bench_scaling.py --split test --seeds 1000 \\
        --cases 173x130:12,173x130:48,173x130:192
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from benchmarks._sweep import SMOKE_SCENE  # noqa: E402
from benchmarks.bench_calibrate import parse_seeds  # noqa: E402
from benchmarks.bench_walk import add_run_arguments, run_variant  # noqa: E402
from fusiongs.sim.simulate import run_simulation  # noqa: E402
from fusiongs.sim.sweep import sweep_scene_config  # noqa: E402
from fusiongs.sim.write import write_simulated_scene  # noqa: E402

FPS = 12.0  # the sweep's frame rate (12 frames in its 1 s scenes)


def parse_case(text: str) -> tuple[int, int, int]:
    """``"173x130:24"`` -> ``(173, 130, 24)``; raises SystemExit naming the bad case."""
    try:
        size, frames = text.split(":")
        w, h = (int(v) for v in size.split("x"))
        return w, h, int(frames)
    except ValueError:
        raise SystemExit(f"bench_scaling: --cases: expected WxH:FRAMES, got {text!r}") from None


def case_scene(root: Path, seed: int, split: str, w: int, h: int, frames: int, smoke: bool = False) -> Path:
    """The seed's scene at ``w`` x ``h`` with ``frames`` frames under ``root`` (simulated on first use)."""
    path = root / (f"{split}_{seed}_{w}x{h}_{frames}f" + ("_smoke" if smoke else ""))
    if not (path / "scene.json").is_file():
        cfg = sweep_scene_config(seed, split)
        cfg = dataclasses.replace(cfg, width=w, height=h, frames=frames, duration=frames / FPS)
        if smoke:
            cfg = dataclasses.replace(cfg, **(SMOKE_SCENE | {"width": w, "height": h, "frames": frames,
                                                             "duration": frames / FPS}))
        res = run_simulation(cfg.validate())
        write_simulated_scene(res.scene, res.gt, path, stats=res.stats, overwrite=True)
    return path


def phase_seconds(out: Path) -> dict[str, float]:
    """Seconds and steps of the warm-up (no events) and event phases, summed over the run's
    ``history.jsonl`` files (one per chunk in a chunked run)."""
    files = [out / "history.jsonl"] if (out / "history.jsonl").is_file() else \
        sorted(out.glob("chunks/*/run/history.jsonl"))
    acc = {"warm_s": 0.0, "warm_steps": 0, "event_s": 0.0, "event_steps": 0}
    for f in files:
        for line in f.read_text().splitlines():
            row = json.loads(line)
            key = "event" if row["event_weight"] else "warm"
            acc[f"{key}_s"] += row["step_seconds"]
            acc[f"{key}_steps"] += 1
    return acc


def boxes_per_pixel(out: Path, instants: int = 4) -> float:
    """Mean number of the final Gaussians whose pixel box (their projected 3σ extent) covers a
    pixel, over ``instants`` instants spread through the run (its first chunk's, when chunked): the
    compositing's work per pixel grows with it."""
    import numpy as np
    import torch

    from fusiongs.render._cpu_layout import depth_keys, visible_layout
    from fusiongs.render.cpu import project_cpu
    from fusiongs.train.restore import restore_state

    ckpt = out / "checkpoint.pt"
    if not ckpt.is_file():
        ckpt = sorted(out.glob("chunks/*/run/checkpoint.pt"))[0]
    state, cam, _ = restore_state(ckpt)
    traj, m = state.trajectory, state.model
    t = torch.linspace(traj.t_min, traj.t_max, instants, dtype=torch.float64)
    viewmats = traj.w2c(t).to(m.means.dtype)
    Ks = cam.K(dtype=m.means.dtype).expand(instants, 3, 3)
    with torch.no_grad():
        proj = project_cpu(m.means, m.rotations, m.scales, m.opacities, viewmats, Ks, cam.width,
                           cam.height, 0.01, 1e10, 0.3)
        keys, bits = depth_keys(proj.depths.numpy())
        _, box, _ = visible_layout(keys, bits, proj.radii.numpy(), proj.means2d.numpy(), cam.width,
                                   cam.height)
    area = (np.maximum(box[:, 1] - box[:, 0] + 1, 0) * np.maximum(box[:, 3] - box[:, 2] + 1, 0)).sum()
    return float(area) / (instants * cam.width * cam.height)


def row_of(seed: int, w: int, h: int, frames: int, res: dict, out: Path) -> dict:
    mean = res["metrics"]["mean"]["deblur"]
    ph = phase_seconds(out)
    index = out / "chunks.json"
    chunks = len(json.loads(index.read_text())["chunks"]) if index.is_file() else 1
    return {"seed": seed, "size": f"{w}x{h}", "pixels": w * h, "frames": frames, "chunks": chunks,
            "wall_s": res["wall_s"], "peak_gb": res["peak_gb"],
            "warm_s": ph["warm_s"], "event_s": ph["event_s"],
            "warm_s_per_step": ph["warm_s"] / max(ph["warm_steps"], 1),
            "event_s_per_step": ph["event_s"] / max(ph["event_steps"], 1),
            # chunks run side by side: their steps' seconds add up to more than the wall time
            "other_s": res["wall_s"] - ph["warm_s"] - ph["event_s"] if chunks == 1 else float("nan"),
            "boxes_per_pixel": boxes_per_pixel(out),
            "fusiongs": mean["fusiongs"]["psnr"], "blurry": mean["blurry"]["psnr"],
            "edi_true": mean["edi_true_theta"]["psnr"]}


def format_rows(rows: list[dict]) -> str:
    head = (f"{'seed':>6}{'size':>9}{'frames':>7}{'chunks':>7}{'wall s':>8}{'warm-up s':>10}{'s/step':>8}"
            f"{'events s':>9}{'s/step':>8}{'other s':>8}{'boxes':>7}{'peak GB':>8}{'blurry':>7}"
            f"{'EDI true θ':>11}{'fusiongs':>9}{'vs EDI':>7}{'wall ×':>7}{'step ×':>7}")
    lines = [head]
    ref = rows[0] if rows else None
    for r in rows:
        lines.append(f"{r['seed']:>6}{r['size']:>9}{r['frames']:>7}{r['chunks']:>7}{r['wall_s']:>8.0f}"
                     f"{r['warm_s']:>10.0f}{r['warm_s_per_step']:>8.3f}{r['event_s']:>9.0f}"
                     f"{r['event_s_per_step']:>8.3f}{r['other_s']:>8.0f}{r['boxes_per_pixel']:>7.0f}{r['peak_gb']:>8.2f}{r['blurry']:>7.2f}"
                     f"{r['edi_true']:>11.2f}{r['fusiongs']:>9.2f}{r['fusiongs'] - r['edi_true']:>+7.2f}"
                     f"{r['wall_s'] / ref['wall_s']:>7.2f}"
                     f"{r['event_s_per_step'] / max(ref['event_s_per_step'], 1e-9):>7.2f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("tuning", "test"), default="tuning")
    ap.add_argument("--seeds", default="0", help="e.g. 1000 or 1000-1002")
    ap.add_argument("--cases", default="173x130:24,346x260:24,640x480:24",
                    help="WxH:FRAMES,... (the first is the reference of the last two columns)")
    add_run_arguments(ap, "bench_out/scaling")
    args = ap.parse_args(argv)
    root = Path(args.root)
    cases = [parse_case(c) for c in args.cases.split(",")]
    rows = []
    for seed in parse_seeds(args.seeds):
        for w, h, frames in cases:
            scene = case_scene(root / "scenes", seed, args.split, w, h, frames, args.smoke)
            out = root / "runs" / (scene.name + (f"_{args.tag}" if args.tag else ""))
            res = run_variant(scene, out, None, args.jobs, args.overrides)  # chunk.seconds as configured
            rows.append(row_of(seed, w, h, frames, res, out))
            print(json.dumps(rows[-1]), flush=True)
    print(format_rows(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
