"""Data-layer loading speeds: native events.h5 and rpg text, against targets and a baseline; and the
Prophesee ``.raw`` reader (faery) against the former numpy decoder, in time and peak memory.

Run: ``PYTHONPATH=. python benchmarks/bench_data.py [--n 10000000] [--repeat 3] [--raw FILE]
[--no-synthetic]``. Prints one row per case: best-of-``repeat`` seconds, the target, and a reference
measured in the same run (plain h5py reads without validation; ``np.loadtxt`` timed on 1/20 of the
lines and scaled up). Cases are a list: add one by appending a :class:`Case`.

The ``.raw`` table (default file: the EVT3 recording of ``../shared/data/real``, when present) runs
each reader in its own process: best-of-``repeat`` seconds, and the peak resident memory
(``ru_maxrss``) above the process's level after its imports, next to the size of the returned
stream's arrays.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from fusiongs.events.h5 import read_events_h5, write_events_h5
from fusiongs.events.readers.text import read_events_txt, write_events_txt
from fusiongs.events.stream import EventStream

W, H = 346, 260
REAL_EVT3 = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "prophesee_evt3_1280x720.raw"
RAW_READERS = {
    "faery, chunk by chunk (fusiongs)": "fusiongs.events.readers.prophesee:read_prophesee_raw",
    "numpy, whole file (former)": "fusiongs.events.readers._evt_reference:read_prophesee_raw_numpy",
}


@dataclass
class Case:
    """One benchmark: ``setup(folder, stream) -> state`` (untimed), ``run(state)`` timed,
    ``reference(state) -> seconds`` (a baseline measured in the same run, or None)."""

    name: str
    setup: Callable
    run: Callable
    target_s: float
    reference: Callable | None = None
    reference_name: str = ""


def synthetic_stream(n: int, seed: int = 0) -> EventStream:
    """``n`` random events over ``n`` µs-ish on a 346x260 sensor (sorted, mixed polarity)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.integers(0, 3, n, dtype=np.int64))
    return EventStream(t, rng.integers(0, W, n, dtype=np.uint16), rng.integers(0, H, n, dtype=np.uint16),
                       np.where(rng.random(n) < 0.5, 1, -1).astype(np.int8), W, H, None)


def best_of(fn: Callable, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def _h5_setup(compression):
    def setup(folder: Path, stream: EventStream):
        path = folder / f"events_{compression or 'none'}.h5"
        write_events_h5(stream, path, compression=compression)
        return path
    return setup


def _raw_h5_read(path: Path) -> None:
    import h5py

    with h5py.File(path, "r") as f:
        for k in ("t", "x", "y", "p"):
            f["events"][k][...]


def _txt_setup(folder: Path, stream: EventStream):
    path = folder / "events.txt"
    write_events_txt(stream, path)
    sub = folder / "events_sub.txt"
    write_events_txt(stream.slice_time(0, int(stream.t[len(stream) // 20])), sub, header=False)
    read_events_txt(sub, W, H)  # numba compile (cached) outside the timing
    return path, sub


def _loadtxt_ref(state, repeat: int) -> float:
    _, sub = state
    return 20 * best_of(lambda: np.loadtxt(sub), 1)


def _hpf_setup(folder: Path, stream: EventStream):
    from fusiongs.events.hpf import high_pass_filter

    times = np.linspace(stream.t[0], stream.t[-1] + 1, 20)
    high_pass_filter(stream.slice_time(0, int(stream.t[100])), times)  # numba compile outside timing
    return stream, times


def _hpf_run(state):
    from fusiongs.events.hpf import high_pass_filter

    return high_pass_filter(state[0], state[1], tau=0.05, contrast=0.2)


def _count_maps_ref(state, repeat: int) -> float:
    stream, times = state
    return best_of(lambda: [stream.count_maps(int(a), int(b)) for a, b in zip(times[:-1], times[1:])],
                   repeat)


def cases(repeat: int) -> list[Case]:
    def timed_h5(state):
        return best_of(lambda: _raw_h5_read(state), repeat)

    return [
        Case("native h5 load (uncompressed)", _h5_setup(None), lambda p: read_events_h5(p, W, H), 0.5,
             timed_h5, "h5py read, no checks"),
        Case("native h5 load (lzf)", _h5_setup("lzf"), lambda p: read_events_h5(p, W, H), 0.5,
             timed_h5, "h5py read, no checks"),
        Case("rpg text load", _txt_setup, lambda s: read_events_txt(s[0]), 5.0,
             lambda s: _loadtxt_ref(s, repeat), "np.loadtxt (x20 of 1/20)"),
        Case("HPF, 20 read-outs", _hpf_setup, _hpf_run, 2.0,
             lambda s: _count_maps_ref(s, repeat), "count maps of the 19 windows"),
    ]


def _raw_child(target: str, path: str, repeat: int) -> None:
    """In a fresh process: time ``target`` on ``path`` and print its peak memory growth as JSON."""
    import importlib

    import faery.extension  # noqa: F401  (imports are not decoding: load before the baseline)

    module, name = target.split(":")
    read = getattr(importlib.import_module(module), name)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        s = read(path)
        times.append(time.perf_counter() - t0)
        events, out_bytes = len(s), sum(a.nbytes for a in (s.t, s.x, s.y, s.p))
        del s
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"seconds": min(times), "peak_kib": peak - before, "events": events,
                      "out_bytes": out_bytes}))


def raw_table(path: Path, repeat: int) -> None:
    """Print the reader comparison on one ``.raw`` file (one subprocess per reader)."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    print(f"\n{path.name} ({path.stat().st_size / 2**20:.1f} MiB), best of {repeat}, one process per reader")
    print("| reader | events | seconds | peak RSS above imports | stream arrays |\n|---|---|---|---|---|")
    for label, target in RAW_READERS.items():
        res = subprocess.run([sys.executable, __file__, "--child", target, str(path), str(repeat)],
                             capture_output=True, text=True, check=True,
                             env=env)
        r = json.loads(res.stdout.strip().splitlines()[-1])
        print(f"| {label} | {r['events']:,} | {r['seconds']:.3f} | {r['peak_kib'] / 1024:.1f} MiB | "
              f"{r['out_bytes'] / 2**20:.1f} MiB |")


def main() -> None:
    if len(sys.argv) == 5 and sys.argv[1] == "--child":
        _raw_child(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000_000, help="events per case")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--raw", type=Path, default=REAL_EVT3,
                    help="Prophesee .raw file of the reader table (its header must give the size)")
    ap.add_argument("--no-synthetic", action="store_true", help="only the .raw reader table")
    args = ap.parse_args()
    if not args.no_synthetic:
        synthetic_table(args.n, args.repeat)
    if args.raw.is_file():
        raw_table(args.raw, args.repeat)
    else:
        print(f"\n(no {args.raw}: .raw reader table skipped)")


def synthetic_table(n: int, repeat: int) -> None:
    stream = synthetic_stream(n)
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for case in cases(repeat):
            state = case.setup(Path(d), stream)
            seconds = best_of(partial(case.run, state), repeat)
            ref = case.reference(state) if case.reference else float("nan")
            size = ""
            p = state[0] if isinstance(state, tuple) else state
            if isinstance(p, Path):
                size = f"{p.stat().st_size / 2**20:.0f} MiB"
            rows.append((case.name, seconds, case.target_s, ref, case.reference_name, size))
    print(f"{n:,} events, best of {repeat}")
    print("| case | seconds | target | ok | reference | file |\n|---|---|---|---|---|---|")
    for name, s, tgt, ref, ref_name, size in rows:
        ok = "yes" if s <= tgt else "NO"
        print(f"| {name} | {s:.3f} | <= {tgt:g} | {ok} | {ref:.3f} s ({ref_name}) | {size} |")


if __name__ == "__main__":
    main()
