"""CUDA figures: the rasteriser's backends on the GPU, and whole ``fusiongs deblur`` runs timed.

Four sub-commands, meant to be run by ``benchmarks/bench_gpu.sh`` on a machine with a CUDA GPU:

``render``: forward + backward (MSE to a random target; gradients for means, quats, scales,
opacities, colours) of ``fusiongs.render.rasterize`` on CUDA tensors, median ms over repeated runs
after warm-up (``torch.cuda.synchronize`` around each step), for the ``gsplat`` backend (when it
imports) against the pure-torch backend measured in the same run on the same scene. Scenes are
``bench_render.make_scene``'s (random Gaussians filling the view, about 15 contributing per pixel;
the scale factor k is calibrated once on the CPU at 10k/128 and kept, since the count per pixel
depends on k alone).

``deblur NAME SCENE OUT [--timeout S] [-- override ...]``: runs ``python -m fusiongs deblur SCENE -o
OUT`` in a child process (its output to ``OUT.log``), times it wall-clock (from process start,
imports and the scene's loading included, to exit; killed after ``--timeout``), and appends one JSON
line to ``OUT/../bench_gpu.jsonl`` with the wall time, the training time and iterations, the device
and backend, the PSNR figures of ``metrics.json`` and the log's last lines.

``table JSONL [JSONL ...]``: prints those lines as a Markdown table.

``profile [--skip N] [--steps N] [--config C] SCENE [-- override ...]``: trains SCENE
(``fusiongs.train.trainer.train``, outputs not written) under ``torch.profiler`` and prints the
operators that take the most host time and, on CUDA, device time, over ``--steps`` iterations
after the first ``--skip`` (the profiler steps with each call of the trainer's ``training_step``,
so set-up is left out). Where the time of a GPU iteration goes (H200: 22 ms at half
resolution, 36 ms at full, for a few ms of rasterisation).

    PYTHONPATH=. python benchmarks/bench_gpu.py render
    PYTHONPATH=. python benchmarks/bench_gpu.py deblur s1000 SCENE OUT device=cuda
    PYTHONPATH=. python benchmarks/bench_gpu.py table OUT/../bench_gpu.jsonl
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_render import calibrate, make_scene, time_ms  # noqa: E402

from fusiongs.render import rasterize  # noqa: E402

GPU_CASES = [("10k/128", 10_000, 128), ("50k/256", 50_000, 256), ("200k/512", 200_000, 512),
             ("1M/1024", 1_000_000, 1024)]
PARAMS = ("means", "quats", "scales", "opacities", "colors")


def to_device(s: dict, device: torch.device) -> dict:
    return {k: (v.to(device) if torch.is_tensor(v) else v) for k, v in s.items()}


def step(s: dict, backend: str) -> None:
    """One forward + backward of an MSE loss, finished on the device (synchronised)."""
    p = {k: s[k].clone().requires_grad_(True) for k in PARAMS}
    size = s["size"]
    img, _, _ = rasterize(p["means"], p["quats"], p["scales"], p["opacities"], p["colors"],
                          s["viewmats"], s["Ks"], size, size, backend=backend)
    torch.nn.functional.mse_loss(img, s["target"]).backward()
    if img.is_cuda:
        torch.cuda.synchronize()


def render_table(reps: int, device: str, n_cases: int) -> None:
    from fusiongs.render.gsplat_backend import gsplat_available

    dev = torch.device(device)
    cuda = dev.type == "cuda"
    backends = (["gsplat"] if cuda and gsplat_available() else []) + ["torch"]
    k = calibrate(10_000, 128)
    name = torch.cuda.get_device_name(dev) if cuda else "cpu"
    print(f"device: {name}; torch {torch.__version__}; k = {k:.3f}; "
          f"backends: {', '.join(backends)} (torch is the reference)")
    rows = []
    for name, n, size in GPU_CASES[:n_cases]:
        s = to_device(make_scene(n, size, k), dev)
        ms = {}
        for b in backends:
            try:
                ms[b] = time_ms(s, b, reps, step=step)
            except torch.cuda.OutOfMemoryError:
                ms[b] = float("nan")
        rows.append((name, n, size * size, ms))
        print(f"{name}: " + ", ".join(f"{b} {v:.2f} ms" for b, v in ms.items()), file=sys.stderr,
              flush=True)
        del s
        if cuda:
            torch.cuda.empty_cache()
    print("| case | N | px | " + " | ".join(f"{b} ms" for b in backends) + " | torch / gsplat |")
    print("|---|---|---|" + "---|" * len(backends) + "---|")
    for name, n, px, ms in rows:
        ratio = f"{ms['torch'] / ms['gsplat']:.1f}x" if "gsplat" in ms else "n/a"
        print(f"| {name} | {n} | {px} | " + " | ".join(f"{ms[b]:.2f}" for b in backends)
              + f" | {ratio} |")


def _psnr_rows(metrics: dict) -> dict:
    """``{method: PSNR}`` of the deblur views (or of the first view group) of ``metrics.json``."""
    mean = metrics.get("mean") or {}
    group = mean.get("deblur") or next(iter(mean.values()), {})
    return {method: m["psnr"] for method, m in group.items() if isinstance(m, dict) and "psnr" in m}


def run_deblur(name: str, scene: str, out: str, overrides: list[str], timeout: float | None) -> dict:
    out_p = Path(out)
    out_p.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "fusiongs", "deblur", scene, "-o", out, "output.progress=false",
           *overrides]
    log_path = out_p.parent / f"{out_p.name}.log"  # beside OUT: deblur refuses a non-empty OUT
    t0 = time.perf_counter()
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            rc = "timeout"
    wall = time.perf_counter() - t0
    text = log_path.read_text()
    rec = {"name": name, "scene": scene, "overrides": overrides, "rc": rc,
           "wall_s": round(wall, 2)}
    metrics_path = out_p / "metrics.json"
    if metrics_path.is_file():
        metrics = json.loads(metrics_path.read_text())
        rec["train_s"] = metrics.get("seconds")
        rec["render_s"] = metrics.get("render_seconds")
        rec["backward_s"] = metrics.get("backward_seconds")
        rec["psnr"] = _psnr_rows(metrics)
        if "affine_fit" in metrics:  # event-only: events fix no brightness or colour balance
            rec["psnr_affine_fit"] = _psnr_rows(metrics["affine_fit"])
        rec["metrics"] = {k: v for k, v in metrics.items() if k != "views"}  # held-out figures too
    cfg_path = out_p / "config.yaml"
    if cfg_path.is_file():
        import yaml

        cfg = yaml.safe_load(cfg_path.read_text())
        rec["device"], rec["backend"] = cfg.get("device"), cfg.get("backend")
        rec["iterations"] = cfg.get("optim", {}).get("iterations")
    if torch.cuda.is_available():
        rec["gpu"] = torch.cuda.get_device_name(0)
    rec["log"] = text.strip().splitlines()[-12:]
    with open(out_p.parent / "bench_gpu.jsonl", "a") as f:
        f.write(json.dumps(rec) + "\n")
    print(json.dumps(rec), flush=True)
    return rec


def table(paths: list[str]) -> None:
    recs = [json.loads(line) for p in paths for line in Path(p).read_text().splitlines() if line.strip()]
    print("| run | device / backend | iterations | training s | wall s | PSNR fusiongs (affine fit) | rc |")
    print("|---|---|---|---|---|---|---|")
    for r in recs:
        ps = r.get("psnr", {}).get("fusiongs")
        fit = r.get("psnr_affine_fit", {}).get("fusiongs")
        train = r.get("train_s")
        print(f"| {r['name']} | {r.get('device')} / {r.get('backend')} | {r.get('iterations')} | "
              f"{'' if train is None else f'{train:.1f}'} | {r['wall_s']:.1f} | "
              f"{'' if ps is None else f'{ps:.2f}'}{'' if fit is None else f' ({fit:.2f})'} | {r['rc']} |")


def profile_training(scene_path: str, overrides: list[str], skip: int, steps: int,
                     config: str | None = None) -> None:
    import tempfile

    from torch.profiler import ProfilerActivity, profile, schedule

    import fusiongs.train.trainer as trainer
    from fusiongs.io import load_scene
    from fusiongs.pipeline.deblur import resolve_config

    cfg = resolve_config(config, ["output.progress=false", "output.checkpoint_every=0",
                                f"optim.iterations={skip + steps + 1}", *overrides])
    cuda = cfg.device.startswith("cuda")
    acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])
    real_step = trainer.training_step
    with profile(activities=acts, schedule=schedule(wait=skip, warmup=1, active=steps, repeat=1)) as prof:
        def stepped(*args, **kwargs):
            out = real_step(*args, **kwargs)
            prof.step()
            return out

        trainer.training_step = stepped
        try:
            with tempfile.TemporaryDirectory() as tmp:
                trainer.train(load_scene(scene_path), cfg, Path(tmp))
        finally:
            trainer.training_step = real_step
    keys = prof.key_averages()
    print(f"{steps} iterations after {skip + 1}; device {cfg.device}, backend {cfg.backend}")
    print(keys.table(sort_by="self_cpu_time_total", row_limit=25))
    if cuda:
        print(keys.table(sort_by="self_cuda_time_total", row_limit=25))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render")
    r.add_argument("--reps", type=int, default=20)
    r.add_argument("--device", default="cuda")
    r.add_argument("--cases", type=int, default=len(GPU_CASES), help="the first N cases only")
    d = sub.add_parser("deblur")
    d.add_argument("name")
    d.add_argument("scene")
    d.add_argument("out")
    d.add_argument("--timeout", type=float, default=None,
                   help="kill the run after this many s (default: $STEP_TIMEOUT, else none)")
    d.add_argument("overrides", nargs="*")
    t = sub.add_parser("table")
    t.add_argument("jsonl", nargs="+")
    pr = sub.add_parser("profile")
    pr.add_argument("scene")
    pr.add_argument("--skip", type=int, default=20)
    pr.add_argument("--steps", type=int, default=20)
    pr.add_argument("--config", default=None, help="a preset or YAML file (default: the deblur one)")
    pr.add_argument("overrides", nargs="*")
    args = ap.parse_args(argv)
    if args.cmd == "deblur" and args.timeout is None and os.environ.get("STEP_TIMEOUT"):
        try:
            args.timeout = float(os.environ["STEP_TIMEOUT"])
        except ValueError:
            ap.error(f"STEP_TIMEOUT: expected seconds, got {os.environ['STEP_TIMEOUT']!r}")
    if args.cmd == "render":
        if args.device.startswith("cuda") and not torch.cuda.is_available():
            print("bench_gpu render: no CUDA device (--device cpu times the torch backend here)",
                  file=sys.stderr)
            return 2
        render_table(args.reps, args.device, args.cases)
    elif args.cmd == "deblur":
        rec = run_deblur(args.name, args.scene, args.out, args.overrides, args.timeout)
        return 0 if rec["rc"] == 0 else 1
    elif args.cmd == "profile":
        profile_training(args.scene, args.overrides, args.skip, args.steps, args.config)
    else:
        table(args.jsonl)
    return 0


if __name__ == "__main__":
    sys.exit(main())
