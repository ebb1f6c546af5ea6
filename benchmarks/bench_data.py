"""Data-layer loading speeds: native events.h5 and rpg text, against targets and a baseline; and the
Prophesee ``.raw`` reader (faery) against the former numpy decoder, in time and peak memory.

Run: ``PYTHONPATH=. python benchmarks/bench_data.py [--n 10000000] [--repeat 3] [--raw FILE]
[--no-synthetic]`` or ``... --evt3-large [N] [--tmp DIR]``. Prints one row per case: best-of-``repeat``
seconds, the target, and a reference measured in the same run (plain h5py reads without validation;
``np.loadtxt`` timed on 1/20 of the lines and scaled up). Cases are a list: add one by appending a
:class:`Case`.

The ``.raw`` table (default file: the EVT3 recording in shared/data/real beside the repository,
when present) runs each reader in its own process: best-of-``repeat`` seconds, and the peak resident memory
(``ru_maxrss``) above the process's level after its imports, next to the size of the returned
stream's arrays.

``--verbs [N]`` (default 1e8; only this table) runs every verb that reads a scene on an N-event
1280x720 scene and prints seconds and peak memory (:mod:`benchmarks.bench_verbs_memory`).

``--evt3-large [N]`` (default N = 1e8; only this table) writes a synthetic EVT 3.0 file of N events
chunk by chunk (:func:`write_evt3`, bounded memory) into a temporary folder (``--tmp``, removed
afterwards), decodes it with fusiongs' reader in a fresh process, and prints the file size, the
seconds, the child's peak RSS (its ``VmHWM``: ``RUSAGE_CHILDREN``'s ``ru_maxrss`` also counts this
process's memory at the spawn) against the 13 bytes/event of the output arrays, and whether the
decoded values' sums equal the written ones.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
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
    "numpy, whole file (former)": "tests.reference.evt_decoder:read_prophesee_raw_numpy",
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


# ---------------------------------------------------------------- synthetic EVT 3.0, large
EVT3_SIZE = (1280, 720)  # an IMX636 (EVK4) sensor
EVT3_CHUNK = 1 << 21     # events generated and encoded at once (~150 MiB of working memory)


def synthetic_evt3_chunks(n: int, width: int = EVT3_SIZE[0], height: int = EVT3_SIZE[1],
                          mean_dt_us: float = 1.0, seed: int = 0, chunk: int = EVT3_CHUNK
                          ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """``n`` random events as ``(t int64 µs, x uint16, y uint16, p uint8 1=ON/0=OFF)`` chunks.

    Time steps are uniform integers in ``[0, 2 mean_dt_us]`` (equal times happen; 1e8 events at the
    default 1 µs span 100 s, several 16.8 s wraps of EVT 3.0's 24-bit clock); each chunk has its own
    generator (``[seed, index]``), so the stream is the same whatever reads it.
    """
    t_last = 0
    for i, start in enumerate(range(0, n, chunk)):
        m = min(chunk, n - start)
        rng = np.random.default_rng([seed, i])
        t = t_last + np.cumsum(rng.integers(0, int(round(2 * mean_dt_us)) + 1, m), dtype=np.int64)
        x = rng.integers(0, width, m, dtype=np.uint16)
        y = rng.integers(0, height, m, dtype=np.uint16)
        p = rng.integers(0, 2, m, dtype=np.uint8)
        t_last = int(t[-1])
        yield t, x, y, p


def evt3_words(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, prev: tuple[int, int]
               ) -> tuple[np.ndarray, tuple[int, int]]:
    """Encode events as EVT 3.0 words (Prophesee's "EVT 3.0 Format"), one EVT_ADDR_X each.

    Before an event: EVT_TIME_HIGH ``0x8`` (``t[23:12]``) when ``t >> 12`` changed, EVT_TIME_LOW
    ``0x6`` (``t[11:0]``) when ``t`` changed, EVT_ADDR_Y ``0x0`` (``y``) when ``y`` changed; then
    EVT_ADDR_X ``0x2`` with the polarity in bit 11 and ``x`` in bits 10..0.

    Args:
        t, x, y, p: ``[E]`` sorted µs times, columns, rows (< 2048) and polarities (1 = ON, 0 = OFF).
        prev: ``(t, y)`` of the previous event (``(-1, -1)`` at the start of a file).

    Returns:
        ``(words [W] uint16, prev)`` with ``prev`` for the next chunk.
    """
    t = np.asarray(t, np.int64)
    prev_t = np.concatenate([[prev[0]], t[:-1]])
    prev_y = np.concatenate([[prev[1]], y[:-1].astype(np.int64)])
    need = [(t >> 12) != (prev_t >> 12), t != prev_t, y != prev_y]
    values = [lambda k: 0x8000 | ((t[k] >> 12) & 0xFFF), lambda k: 0x6000 | (t[k] & 0xFFF), lambda k: y[k]]
    count = 1 + need[0].astype(np.int64) + need[1] + need[2]
    pos = np.cumsum(count) - count
    words = np.empty(int(count[-1] + pos[-1]), np.uint16)
    for flag, value in zip(need, values):
        words[pos[flag]] = value(flag)
        pos += flag
    words[pos] = 0x2000 | (p.astype(np.int64) << 11) | x
    return words, (int(t[-1]), int(y[-1]))


def write_evt3(path: Path, chunks: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
               width: int = EVT3_SIZE[0], height: int = EVT3_SIZE[1]) -> dict[str, int]:
    """Write a Prophesee EVT 3.0 ``.raw`` file chunk by chunk (memory: one chunk).

    Returns:
        ``{"events", "bytes", "sum_t", "sum_x", "sum_y", "sum_p"}`` (``p`` as ±1) to check a decoder.
    """
    info = {"events": 0, "sum_t": 0, "sum_x": 0, "sum_y": 0, "sum_p": 0}
    prev = (-1, -1)
    with open(path, "wb") as fh:
        fh.write(f"% evt 3.0\n% format EVT3;height={height};width={width}\n% geometry {width}x{height}\n"
                 "% end\n".encode("ascii"))
        for t, x, y, p in chunks:
            words, prev = evt3_words(t, x, y, p, prev)
            words.astype("<u2", copy=False).tofile(fh)
            info["events"] += len(t)
            info["sum_t"] += int(t.sum())
            info["sum_x"] += int(x.sum(dtype=np.int64))
            info["sum_y"] += int(y.sum(dtype=np.int64))
            info["sum_p"] += 2 * int(p.sum(dtype=np.int64)) - len(p)
    info["bytes"] = path.stat().st_size
    return info


def _rss_bytes(field: str = "VmRSS") -> int:
    """This process's resident memory now (``VmRSS``) or its peak since ``exec`` (``VmHWM``), from
    Linux's ``/proc/self/status``; elsewhere ``ru_maxrss`` (KiB on Linux, bytes on macOS)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * (1 if sys.platform == "darwin" else 1024)


def _evt3_child(path: str) -> None:
    """In a fresh process: decode ``path`` once with fusiongs' reader; print JSON figures."""
    import faery.extension  # noqa: F401  (imports are not decoding: load before the baseline)

    from fusiongs.events.readers.prophesee import read_prophesee_raw

    before = _rss_bytes()
    t0 = time.perf_counter()
    s = read_prophesee_raw(path)
    seconds = time.perf_counter() - t0
    print(json.dumps({"seconds": seconds, "imports_bytes": before, "peak_bytes": _rss_bytes("VmHWM"),
                      "events": len(s),
                      "out_bytes": sum(a.nbytes for a in (s.t, s.x, s.y, s.p)),
                      "sum_t": int(s.t.sum()), "sum_x": int(s.x.sum(dtype=np.int64)),
                      "sum_y": int(s.y.sum(dtype=np.int64)), "sum_p": int(s.p.sum(dtype=np.int64))}))


def evt3_large_table(n: int, folder: Path | None = None) -> None:
    """Write ``n`` synthetic EVT 3.0 events to a temporary file, decode it in a child process, print
    time and peak memory against the output arrays' size (see the module docstring)."""
    folder = Path(folder or tempfile.gettempdir())
    estimate = 8 * n  # at most 4 words per event; about 3 here
    free = shutil.disk_usage(folder).free
    if free < 2 * estimate:
        raise SystemExit(f"{folder}: {free / 2**30:.1f} GiB free, the EVT3 file may need "
                         f"{estimate / 2**30:.1f} GiB (pass --tmp DIR)")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    with tempfile.TemporaryDirectory(dir=folder, prefix="bench_evt3_") as d:
        path = Path(d) / "synthetic_evt3.raw"
        t0 = time.perf_counter()
        info = write_evt3(path, synthetic_evt3_chunks(n))
        write_s = time.perf_counter() - t0
        res = subprocess.run([sys.executable, __file__, "--evt3-child", str(path)], capture_output=True,
                             text=True, env=env)
        if res.returncode:
            raise SystemExit(f"decoding failed (exit {res.returncode}): {res.stderr.strip()[-2000:]}")
    r = json.loads(res.stdout.strip().splitlines()[-1])
    # the child's own high-water mark: ru_maxrss (RUSAGE_CHILDREN) would also count this process's
    # resident memory at the spawn (Linux hands the pre-exec high-water mark on to the new program)
    child_peak = r["peak_bytes"]
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    same = all(r[k] == info[k] for k in ("events", "sum_t", "sum_x", "sum_y", "sum_p"))
    out, imports = r["out_bytes"], r["imports_bytes"]
    print(f"synthetic EVT 3.0, {EVT3_SIZE[0]}x{EVT3_SIZE[1]}, written in {write_s:.1f} s; one decoding "
          "in a fresh process (fusiongs.events.readers.prophesee)")
    print("| events | file | seconds | peak RSS (child) | RSS after imports | output arrays | "
          "peak / output | values |\n|---|---|---|---|---|---|---|---|")
    print(f"| {r['events']:,} | {info['bytes'] / 2**20:,.0f} MiB | {r['seconds']:.2f} | "
          f"{child_peak / 2**20:,.0f} MiB | {imports / 2**20:,.0f} MiB | {out / 2**20:,.0f} MiB | "
          f"{(child_peak - imports) / max(out, 1):.2f} | {'equal sums' if same else 'DIFFER'} |")
    print(f"(peak / output: the peak above the RSS after imports over the output's size; ru_maxrss of "
          f"the children, which includes this process at the spawn: {children / 2**20:,.0f} MiB)")


def main() -> None:
    if len(sys.argv) == 5 and sys.argv[1] == "--child":
        _raw_child(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return
    if len(sys.argv) == 3 and sys.argv[1] == "--evt3-child":
        _evt3_child(sys.argv[2])
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000_000, help="events per case")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--raw", type=Path, default=REAL_EVT3,
                    help="Prophesee .raw file of the reader table (its header must give the size)")
    ap.add_argument("--no-synthetic", action="store_true", help="only the .raw reader table")
    ap.add_argument("--evt3-large", type=float, nargs="?", const=1e8, default=None, metavar="N",
                    help="only the synthetic EVT 3.0 table with N events (default 1e8)")
    ap.add_argument("--tmp", type=Path, default=None, help="folder for the synthetic EVT 3.0 file")
    ap.add_argument("--verbs", type=float, nargs="?", const=1e8, default=None, metavar="N",
                    help="only the table of every verb on an N-event 1280x720 scene (time, peak memory; "
                         "benchmarks/bench_verbs_memory.py, which takes more options)")
    args = ap.parse_args()
    if args.verbs is not None:  # exec'd: a fresh process, whose children do not inherit this one's
        script = str(Path(__file__).with_name("bench_verbs_memory.py"))  # high-water mark
        os.execv(sys.executable, [sys.executable, script, "--events", str(args.verbs)]
                 + (["--tmp", str(args.tmp)] if args.tmp else []))
    if args.evt3_large is not None:
        evt3_large_table(int(args.evt3_large), args.tmp)
        return
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
