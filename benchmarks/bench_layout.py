"""Benchmark of the CPU backend's depth order and pixel boxes: the numba ``visible_layout``
(``fusiongs.render._cpu_layout``, a radix sort per camera) against its torch reference
``sorted_visible`` + ``pixel_boxes`` (``fusiongs.render._boxes``) in the same run.

The inputs are :func:`benchmarks.bench_projection.scene`'s 18k Gaussians projected by
``project_cpu`` into C = 4 (an event-only step) and 11 cameras (a deblur step), float32 as in
training. Median ms of 50 repetitions after 5 of warm-up, the two forms alternating; both give the
same entries, order and boxes (checked here, and in ``tests/render/test_cpu_layout.py``).

Usage: ``PYTHONPATH=. python benchmarks/bench_layout.py [--n 18000] [--reps 50]``
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
from benchmarks.bench_projection import HEIGHT, WIDTH, scene  # noqa: E402
from fusiongs.render._boxes import pixel_boxes, sorted_visible  # noqa: E402
from fusiongs.render._cpu_layout import depth_keys, visible_layout  # noqa: E402
from fusiongs.render.cpu import project_cpu  # noqa: E402


def torch_layout(p):
    cam, gid, off = sorted_visible(p.depths, p.radii)
    return gid, pixel_boxes(p.means2d[cam, gid], p.radii[cam, gid], WIDTH, HEIGHT), off


def numba_layout(p):
    keys, bits = depth_keys(p.depths.numpy())
    return tuple(torch.from_numpy(a) for a in visible_layout(keys, bits, p.radii.numpy(),
                                                             p.means2d.numpy(), WIDTH, HEIGHT))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=18000)
    ap.add_argument("--reps", type=int, default=50)
    args = ap.parse_args(argv)
    for name in ("n", "reps"):
        if getattr(args, name) < 1:
            ap.error(f"--{name}: expected an integer >= 1, got {getattr(args, name)}")
    forms = {"numba (visible_layout)": numba_layout,
             "torch (sorted_visible + pixel_boxes, reference)": torch_layout}
    print(f"{args.n} Gaussians, {WIDTH}x{HEIGHT}, float32, {torch.get_num_threads()} torch thread(s)")
    print("| cameras | visible entries | layout | ms (x reference) |")
    print("|---|---|---|---|")
    for cams in (4, 11):
        means, quats, scales, opac, view, Ks = scene(args.n, cams)
        with torch.no_grad():
            p = project_cpu(means, quats, scales, opac, view, Ks, WIDTH, HEIGHT, 0.01, 1e10, 0.3)
        outs = [f(p) for f in forms.values()]
        if not all(torch.equal(a, b) for a, b in zip(*outs)):
            raise SystemExit("the two layouts differ")
        times = {k: [] for k in forms}
        for rep in range(args.reps + 5):
            for name, fn in forms.items():
                t0 = time.perf_counter()
                fn(p)
                if rep >= 5:
                    times[name].append(time.perf_counter() - t0)
        med = {k: statistics.median(v) for k, v in times.items()}
        ref = med["torch (sorted_visible + pixel_boxes, reference)"]
        for name, t in med.items():
            print(f"| {cams} | {len(outs[0][0])} | {name} | {1e3 * t:.2f} ({t / ref:.2f}x) |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
