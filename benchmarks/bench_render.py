"""Benchmark of ``fusiongs.render.rasterize`` on CPU: forward + backward time and extra peak memory.

Cases: (2k Gaussians, 64x64), (10k, 128x128), (50k, 256x256); random Gaussians filling the view at
depth 2.5-3.5, fx = width, scale calibrated so that about 15 Gaussians contribute per pixel (the
measured mean is printed). Each measurement is forward + backward of an MSE loss to a random target,
with gradients for means, quats, scales, opacities and colours. Compared in the same run with a
simple tiled pure-torch compositor (``tiled_reference.py``, 16x16 tiles, dense per-tile lists) and
with the "cpu" backend forced onto its scalar kernels (``cpu-scalar``: the path before the float32
SIMD kernels of ``fusiongs/render/_cpu_simd.py``).

Timing: median of repeated runs after warm-up, 2 torch threads and 2 numba threads, with
``OMP_WAIT_POLICY=PASSIVE`` (set below unless already set): torch's and numba's OpenMP thread
pools otherwise busy-wait against each other, which made CPU-backend steps 3-10x slower here.
Memory: each (case, backend) runs in a fresh subprocess; after a small warm-up render (loads the
numba cache) and the scene set-up, the kernel's peak-RSS mark is reset (``/proc/self/clear_refs``
= 5), one forward + backward runs, and ``VmHWM - VmRSS(before)`` is reported as extra peak memory.

Usage: ``PYTHONPATH=. python benchmarks/bench_render.py [--quick]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

# torch's and numba's OpenMP pools both spin-wait by default and fight over 2 cores; must be set
# before torch / numba load their OpenMP runtimes.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tiled_reference import composite_tiled  # noqa: E402

import fusiongs.render.cpu as cpu_backend  # noqa: E402
from fusiongs.render import rasterize  # noqa: E402
from fusiongs.render.pairs import drawn_pairs  # noqa: E402
from fusiongs.render.projection import project_gaussians  # noqa: E402

CASES = [("2k/64", 2000, 64, 7.0), ("10k/128", 10000, 128, 28.0), ("50k/256", 50000, 256, 144.0)]
THREADS = 2
TARGET_PAIRS = 15.0


def make_scene(n: int, size: int, k: float, seed: int = 0) -> dict:
    """Random Gaussians filling the view of a camera at the origin looking down +z."""
    g = torch.Generator().manual_seed(seed)
    z = 2.5 + torch.rand(n, generator=g)
    xy = (torch.rand(n, 2, generator=g) - 0.5) * z[:, None]  # fx = width: half-FOV tan 0.5
    scales = (k / n ** 0.5) * (0.5 + torch.rand(n, 3, generator=g))
    K = torch.tensor([[size, 0.0, size / 2], [0.0, size, size / 2], [0.0, 0.0, 1.0]])
    return dict(means=torch.cat([xy, z[:, None]], 1), quats=torch.randn(n, 4, generator=g),
                scales=scales, opacities=0.1 + 0.85 * torch.rand(n, generator=g),
                colors=torch.rand(n, 3, generator=g), viewmats=torch.eye(4)[None], Ks=K[None],
                target=torch.rand(1, size, size, 3, generator=g), size=size)


def pairs_per_pixel(s: dict) -> float:
    proj = project_gaussians(s["means"], s["quats"], s["scales"], s["opacities"], s["viewmats"],
                             s["Ks"], s["size"], s["size"], 0.01, 1e10, 0.3)
    with torch.no_grad():
        return len(drawn_pairs(proj, s["size"], s["size"])[0]) / s["size"] ** 2


def calibrate(n: int, size: int) -> float:
    """Scale factor k giving ~TARGET_PAIRS contributing Gaussians per pixel (bisection)."""
    lo, hi = 0.05, 2.0
    for _ in range(12):
        mid = (lo * hi) ** 0.5
        if pairs_per_pixel(make_scene(n, size, mid)) < TARGET_PAIRS:
            lo = mid
        else:
            hi = mid
    return (lo * hi) ** 0.5


@contextmanager
def scalar_kernels():
    """The "cpu" backend on its scalar kernels for float32 too (for comparison only)."""
    saved = cpu_backend._use_simd
    cpu_backend._use_simd = lambda dtype, n_entries: False
    try:
        yield
    finally:
        cpu_backend._use_simd = saved


def step(s: dict, backend: str) -> None:
    """One forward + backward of an MSE loss."""
    if backend == "cpu-scalar":
        with scalar_kernels():
            return step(s, "cpu")
    p = {k: s[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")}
    size = s["size"]
    if backend == "tiled":
        proj = project_gaussians(p["means"], p["quats"], p["scales"], p["opacities"], s["viewmats"],
                                 s["Ks"], size, size, 0.01, 1e10, 0.3)
        img, _ = composite_tiled(proj, p["colors"][None], size, size)
    else:
        img, _, _ = rasterize(p["means"], p["quats"], p["scales"], p["opacities"], p["colors"],
                              s["viewmats"], s["Ks"], size, size, backend=backend)
    torch.nn.functional.mse_loss(img, s["target"]).backward()


def time_ms(s: dict, backend: str, reps: int, step=step) -> float:
    """Median ms of ``step(s, backend)`` over ``reps`` runs after two warm-up runs."""
    step(s, backend)
    step(s, backend)
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        step(s, backend)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def _status_kb(key: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key):
            return int(line.split()[1])
    raise RuntimeError(key)


def measure_memory(backend: str, n: int, size: int, k: float) -> float:
    """Extra peak RSS (MB) of one forward + backward (run in a fresh process)."""
    step(make_scene(64, 16, 0.5), backend)  # loads compiled kernels at negligible size
    s = make_scene(n, size, k)
    before = _status_kb("VmRSS:")
    Path("/proc/self/clear_refs").write_text("5")
    step(s, backend)
    return (_status_kb("VmHWM:") - before) / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repetitions")
    ap.add_argument("--cases", type=int, default=len(CASES), help="the first N cases only")
    ap.add_argument("--mem", nargs=4, metavar=("BACKEND", "N", "SIZE", "K"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    torch.set_num_threads(THREADS)
    numba.set_num_threads(THREADS)
    if args.mem:
        b, n, size, k = args.mem
        print(json.dumps(measure_memory(b, int(n), int(size), float(k))))
        return
    rows = []
    for name, n, size, target in CASES[:args.cases]:
        k = calibrate(n, size)
        s = make_scene(n, size, k)
        ppp = pairs_per_pixel(s)
        reps = 3 if args.quick else (15 if n <= 10000 else 7)
        ms = {b: time_ms(s, b, reps) for b in ("torch", "cpu", "cpu-scalar", "tiled")}
        mem = {}
        for b in ("cpu", "torch", "tiled"):
            out = subprocess.run([sys.executable, __file__, "--mem", b, str(n), str(size), str(k)],
                                 capture_output=True, text=True, check=True)
            mem[b] = json.loads(out.stdout.strip().splitlines()[-1])
        rows.append((name, n, size * size, ms, target, mem, ppp))
        print(f"{name}: k={k:.3f} pairs/px={ppp:.1f}", file=sys.stderr)
    print(f"threads: torch {THREADS}, numba {THREADS}; peak MB = extra peak RSS of one fwd+bwd "
          "(cpu / torch / tiled-ref)")
    print("| case | N | px | pairs/px | torch ms | cpu ms | cpu-scalar ms | tiled-ref ms | target ms "
          "| peak MB |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, n, px, ms, target, mem, ppp in rows:
        print(f"| {name} | {n} | {px} | {ppp:.1f} | {ms['torch']:.1f} | {ms['cpu']:.1f} | "
              f"{ms['cpu-scalar']:.1f} | {ms['tiled']:.1f} | {target:.0f} | {mem['cpu']:.0f} / "
              f"{mem['torch']:.0f} / {mem['tiled']:.0f} |")


if __name__ == "__main__":
    main()
