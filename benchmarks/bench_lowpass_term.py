"""The event-only low-pass term of one step: its cost against the pair-by-pair reference.

``fusiongs.train.lowpass_term.lowpass_term`` takes the counts of every cross pair of a step's
window ends from one cumulative count over the step's instants, and each render's log once;
``fusiongs.train._lowpass_reference.lowpass_term_pairwise`` is the same term window pair by window
pair (``count_maps`` and ``censored_map`` over each long window's events). Both are timed here on
the same scene, windows and renders, alternately in one process (forward + backward, median ms
over ``--reps`` steps, each with freshly drawn windows as the trainer draws them), and the torch
calls each makes from Python are counted: on a GPU every call is a kernel launch or more, and
session 22's profile found an event-only GPU step bound by its launches, not its kernels.

    PYTHONPATH=. python benchmarks/bench_lowpass_term.py SCENE [--device cpu] [--reps 30]

SCENE: a scene without frames, e.g. ``fusiongs simulate -o S --sweep-seed 6 --split tuning
--size 173x130 --frames 0 --novel 6`` (the issue-18 time target's scene).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before torch (numba's spinning threads)

import torch  # noqa: E402
from torch.overrides import TorchFunctionMode  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fusiongs.events.stats import dead_time_us  # noqa: E402
from fusiongs.io.scene_io import load_scene  # noqa: E402
from fusiongs.losses.threshold import ContrastThreshold  # noqa: E402
from fusiongs.train._lowpass_reference import lowpass_term_pairwise  # noqa: E402
from fusiongs.train.data import fast_events, prepare_data  # noqa: E402
from fusiongs.train.lowpass_term import lowpass_term  # noqa: E402
from fusiongs.train.pipeline import resolve_config  # noqa: E402
from fusiongs.train.schedules import sample_free_windows  # noqa: E402
from fusiongs.train.step import longest_free_window  # noqa: E402


class _Calls(TorchFunctionMode):
    """Counts the torch functions and tensor methods called from Python (attribute reads aside)."""

    def __init__(self):
        super().__init__()
        self.calls = Counter()

    def __torch_function__(self, func, types, args=(), kwargs=None):
        name = getattr(func, "__name__", str(func))
        if name not in ("__get__", "size", "dim"):
            self.calls[name] += 1
        return func(*args, **(kwargs or {}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--reps", type=int, default=30)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    cfg = resolve_config("event_only", [])
    data = prepare_data(load_scene(args.scene), device, True)
    if data.n_frames:
        ap.error(f"{args.scene}: the low-pass term is for scenes without frames")
    data.fast = fast_events(data.events, cfg.events.censor * dead_time_us(data.events), device)
    channels = 1 if data.cfa_index is None else 3
    state = SimpleNamespace(threshold=ContrastThreshold(channels=channels, init=(0.2, 0.25)).to(device))
    h, w = data.camera.height, data.camera.width
    gen = torch.Generator().manual_seed(0)
    longest = longest_free_window(cfg, data)

    def draw():
        free = sample_free_windows(cfg.events.windows_free, data.t_range, longest, gen,
                                   min(cfg.events.min_window, longest))
        ends = [(2 * i + k, t, i) for i, ab in enumerate(free.tolist()) for k, t in enumerate(ab)]
        lin = (0.05 + torch.rand(len(ends), h, w, 3, generator=gen)).to(device).requires_grad_(True)
        return lin, ends

    def run(fn, lin, ends):
        loss = fn(state, data, cfg, lin, ends, longest)
        if loss is not None:
            loss.backward()
        if device.type == "cuda":
            torch.cuda.synchronize()
        return loss

    fns = {"cumulative (default)": lowpass_term, "pair by pair (reference)": lowpass_term_pairwise}
    times: dict[str, list[float]] = {k: [] for k in fns}
    for rep in range(args.reps + 2):
        lin, ends = draw()
        for name, fn in fns.items():
            lin.grad = None
            t0 = time.perf_counter()
            run(fn, lin, ends)
            if rep >= 2:  # two warm-up steps
                times[name].append((time.perf_counter() - t0) * 1e3)
    calls = {}
    lin, ends = draw()
    for name, fn in fns.items():
        with _Calls() as mode:
            run(fn, lin, ends)
        calls[name] = sum(mode.calls.values())
    print(f"scene {args.scene}: {w}x{h}, {len(data.events)} events, {channels} channel(s); "
          f"{cfg.events.windows_free} free windows a step; device {device}, {args.threads} thread(s)")
    print("| low-pass term | forward + backward, median ms | torch calls from Python, forward + backward |")
    print("|---|---|---|")
    ref = statistics.median(times["pair by pair (reference)"])
    for name in fns:
        med = statistics.median(times[name])
        print(f"| {name} | {med:.2f} ({med / ref:.2f}x) | {calls[name]} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
