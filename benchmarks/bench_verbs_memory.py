"""Time and peak memory of every verb that reads a scene, on streams of 1e7 and 1e8 events.

Writes a closed-form plane-wave scene (:mod:`fusiongs.sim.plane_wave`: a textured plane, a camera
translating along it, events solved exactly; 10 frames, 8-bit sRGB, a trajectory) with ``N``
events at ``--size`` (default 1280x720 over 10 s, as a 1e8-event recording of an HD sensor), then
runs ``fusiongs inspect``, ``convert`` (its events.h5 into a new scene), ``calibrate``, ``edi``
(estimating the thresholds itself) and ``deblur`` (``deblur_fast`` with ``--iterations``) each in
its own process and reads the process's peak resident memory from ``wait4`` (``ru_maxrss``).

The reference, measured in the same run: a process that only reads the four event datasets with
h5py, the least any verb holding the stream in memory can use. The target is 4 GB per verb.

    PYTHONPATH=. python benchmarks/bench_verbs_memory.py --events 1e8 [--size 1280x720]
        [--iterations 3] [--tmp DIR] [--verbs inspect,convert,calibrate,edi,deblur]
"""

from __future__ import annotations

import argparse
import ast
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_BYTES = 4e9
READ_ONLY = ("import sys, h5py\n"
             "with h5py.File(sys.argv[1], 'r') as f:\n"
             "    arrays = [f['events'][k][...] for k in ('t', 'x', 'y', 'p')]\n"
             "print(sum(a.nbytes for a in arrays))\n")


def run_measured(cmd: list[str], env: dict) -> tuple[int, float, int, str]:
    """Run ``cmd``; ``(exit status, seconds, peak RSS bytes of that process, last output lines)``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)
    out = proc.stdout.read().decode(errors="replace")
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    proc.stdout.close()
    tail = " / ".join(out.strip().splitlines()[-2:])
    return proc.returncode, time.perf_counter() - t0, usage.ru_maxrss * 1024, tail


def _rss_now() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmRSS:"))


def verb_commands(scene: Path, work: Path, iterations: int, width: int, height: int) -> dict[str, list[str]]:
    fg = [sys.executable, "-m", "fusiongs.cli"]
    return {
        "inspect": fg + ["inspect", str(scene)],
        "convert": fg + ["convert", str(scene / "events.h5"), "-o", str(work / "converted"),
                         "--format", "native", "--width", str(width), "--height", str(height)],
        "calibrate": fg + ["calibrate", str(scene), "-o", str(work / "calibration.json")],
        "edi": fg + ["edi", str(scene), "-o", str(work / "edi")],
        "deblur": fg + ["deblur", str(scene), "-o", str(work / "run"), "--config", "deblur_fast",
                        f"optim.iterations={iterations}"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=float, default=1e8)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--iterations", type=int, default=3, help="deblur iterations (memory, not quality)")
    ap.add_argument("--verbs", default="inspect,convert,calibrate,edi,deblur")
    ap.add_argument("--tmp", type=Path, default=None, help="folder for the scene (needs 14 B/event)")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    n_events = int(a.events)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1]),
           "OMP_WAIT_POLICY": "PASSIVE"}
    folder = Path(a.tmp or tempfile.gettempdir())
    if shutil.disk_usage(folder).free < 3 * 14 * n_events:
        raise SystemExit(f"{folder}: too little free disk for {n_events:,} events (pass --tmp DIR)")
    # this process stays small (no fusiongs, numpy or torch imported): Linux counts a parent's
    # resident memory at the fork in each child's ru_maxrss
    print(f"this process before the runs: {_rss_now() / 1e9:.3f} GB resident")
    with tempfile.TemporaryDirectory(dir=folder, prefix="bench_verbs_") as d:
        scene, work = Path(d) / "scene", Path(d) / "work"
        work.mkdir()
        t0 = time.perf_counter()
        # written by a child: a parent that had held the scene's arrays would hand its high-water
        # mark on to every child it forks (Linux counts it in the child's ru_maxrss)
        res = subprocess.run([sys.executable, "-m", "fusiongs.sim.plane_wave", str(scene), "--events",
                              str(n_events), "--size", a.size, "--duration", str(a.duration)],
                             env=env, capture_output=True, text=True, check=True)
        info = ast.literal_eval(res.stdout.strip().splitlines()[-1])
        print(f"plane-wave scene {w}x{h}, {a.duration:g} s, {info['events']:,} events, 10 frames, "
              f"theta {info['theta']}: written in {time.perf_counter() - t0:.1f} s")
        read_only = [sys.executable, "-c", READ_ONLY, str(scene / "events.h5")]
        rc, s, ref_peak, nbytes = run_measured(read_only, env)
        arrays = int(nbytes.split()[-1]) if rc == 0 else 0
        print("| verb | exit | seconds | peak RSS | peak - h5py read of the stream | target 4 GB "
              "| last line |\n|---|---|---|---|---|---|---|")
        print(f"| reference: h5py reads the 4 datasets | {rc} | {s:.1f} | {ref_peak / 1e9:.2f} GB | "
              f"(arrays {arrays / 1e9:.2f} GB) | | |")
        for verb, cmd in verb_commands(scene, work, a.iterations, w, h).items():
            if verb not in a.verbs.split(","):
                continue
            rc, s, peak, tail = run_measured(cmd, env)
            ok = "yes" if rc == 0 and peak <= TARGET_BYTES else "NO"
            print(f"| {verb} | {rc} | {s:.1f} | {peak / 1e9:.2f} GB | {(peak - ref_peak) / 1e9:+.2f} GB | "
                  f"{ok} | {tail[:120]} |", flush=True)


if __name__ == "__main__":
    main()
