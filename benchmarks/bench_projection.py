"""Benchmark of the CPU backend's EWA projection: the numba kernels (``fusiongs.render.cpu.project_cpu``)
against the pure-torch ``project_gaussians`` (their reference) in the same run.

Forward + backward (a sum of every differentiable output; gradients for means, quaternions, scales
and view matrices) of 18k random Gaussians (the size of an event-only or deblur model at 173x130)
in C cameras: C = 4 (an event-only step's two free windows) and C = 11 (a deblur step's 9
exposure samples and one window). Median ms of 30 repetitions after 5 of warm-up, the two forms
alternating, float32 as in training, torch's and numba's threads as configured (2 and 2 on a
2-core machine; ``OMP_WAIT_POLICY=PASSIVE`` set below unless already set).

Usage: ``PYTHONPATH=. python benchmarks/bench_projection.py [--n 18000] [--reps 30]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from fusiongs.render.cpu import project_cpu  # noqa: E402
from fusiongs.render.projection import project_gaussians  # noqa: E402

WIDTH, HEIGHT = 173, 130


def scene(n: int, cams: int, seed: int = 0) -> tuple:
    """Gaussians in front of ``cams`` cameras 0.1 apart, fx = fy = 150 px, 173x130."""
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g) * 0.5 + torch.tensor([0.0, 0.0, 3.0])
    quats = torch.randn(n, 4, generator=g)
    scales = torch.rand(n, 3, generator=g) * 0.03 + 0.005
    opac = torch.rand(n, generator=g)
    view = torch.eye(4).repeat(cams, 1, 1)
    view[:, 0, 3] = torch.linspace(-0.1, 0.1, cams)
    K = torch.tensor([[150.0, 0.0, WIDTH / 2], [0.0, 150.0, HEIGHT / 2], [0.0, 0.0, 1.0]])
    return means, quats, scales, opac, view, K.repeat(cams, 1, 1)


def step(fn, means, quats, scales, opac, view, Ks) -> tuple[float, float]:
    """Seconds of one forward and one backward."""
    ins = [t.clone().requires_grad_(True) for t in (means, quats, scales, view)]
    t0 = time.perf_counter()
    p = fn(ins[0], ins[1], ins[2], opac, ins[3], Ks, WIDTH, HEIGHT, 0.01, 1e10, 0.3)
    loss = p.means2d.sum() + p.conics.sum() + p.depths.sum()
    t1 = time.perf_counter()
    loss.backward()
    return t1 - t0, time.perf_counter() - t1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=18000)
    ap.add_argument("--reps", type=int, default=30)
    args = ap.parse_args(argv)
    forms = {"numba (project_cpu)": project_cpu, "torch (project_gaussians, reference)": project_gaussians}
    print(f"{args.n} Gaussians, {WIDTH}x{HEIGHT}, float32, {torch.get_num_threads()} torch thread(s)")
    print("| cameras | projection | forward ms | backward ms | total ms (x reference) |")
    print("|---|---|---|---|---|")
    for cams in (4, 11):
        s = scene(args.n, cams)
        times = {k: [] for k in forms}
        for rep in range(args.reps + 5):
            for name, fn in forms.items():
                f, b = step(fn, *s)
                if rep >= 5:
                    times[name].append((f, b))
        med = {k: (statistics.median(f for f, _ in v), statistics.median(b for _, b in v))
               for k, v in times.items()}
        ref = sum(med["torch (project_gaussians, reference)"])
        for name, (f, b) in med.items():
            print(f"| {cams} | {name} | {1e3 * f:.2f} | {1e3 * b:.2f} | {1e3 * (f + b):.2f} "
                  f"({(f + b) / ref:.2f}x) |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
