"""Run ``fusiongs`` in a child process and SIGKILL it at an exact point (kill -9 tests).

The child runs ``fusiongs.cli.main`` behind a small hook (:data:`CHILD`) that, on reaching the
point, writes a marker file and sleeps; :func:`run_killed` then kills the whole process group. A
half-written file is made by cutting the atomic writer's finished temporary to half its size just
before its rename.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 120.0

# argv: POINT MARKER fusiongs-arguments... POINT is "none", "estimate" (entering the threshold
# estimate) or "PATH:N:after|half" (the N-th atomic write of a file whose path ends with PATH, e.g.
# "checkpoint.pt" or "chunks/001/run/checkpoint.pt", in this process: just after its rename, or with
# its temporary cut to half its size instead of the rename)
CHILD = r"""
import os, sys, time
from pathlib import Path

point, marker, argv = sys.argv[1], sys.argv[2], sys.argv[3:]

def park():
    Path(marker).write_text(point)
    time.sleep(600)  # until SIGKILL
    os._exit(3)

if point == "estimate":
    import fusiongs.calibrate.estimate as calibrate

    def estimate_thresholds(*args, **kwargs):
        park()

    calibrate.estimate_thresholds = estimate_thresholds
elif point != "none":
    name, nth, how = point.split(":")
    real_replace, seen = os.replace, [0]

    def replace(src, dst, *args, **kwargs):
        if not ("/" + Path(dst).as_posix()).endswith("/" + name):
            return real_replace(src, dst, *args, **kwargs)
        seen[0] += 1
        if seen[0] != int(nth):
            return real_replace(src, dst, *args, **kwargs)
        if how == "after":
            real_replace(src, dst, *args, **kwargs)
        else:
            with open(src, "r+b") as f:
                f.truncate(os.path.getsize(src) // 2)
        park()

    os.replace = replace

from fusiongs.cli import main

sys.exit(main(argv))
"""


def run_killed(argv: list[str], out: Path, point: str) -> str:
    """Run ``fusiongs ARGV`` (whose output folder is ``out``) in a subprocess; with a ``point``
    other than ``"none"`` SIGKILL it there. Returns how it ended (``"killed"`` or ``"finished"``);
    fails the test when it ends otherwise."""
    marker = out.parent / f"{out.name}.parked"
    marker.unlink(missing_ok=True)
    log = out.parent / f"{out.name}.log"
    cmd = [sys.executable, "-c", CHILD, point, str(marker), *argv]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    with open(log, "w") as f:
        proc = subprocess.Popen(cmd, cwd=REPO_ROOT, env=env, stdout=f, stderr=subprocess.STDOUT,
                                start_new_session=True)
    t0 = time.monotonic()
    try:
        while proc.poll() is None and not marker.exists():
            if time.monotonic() - t0 > TIMEOUT_S:
                pytest.fail(f"fusiongs ({point}) still running after {TIMEOUT_S} s:\n" + log.read_text())
            time.sleep(0.005)
        if marker.exists():
            os.killpg(proc.pid, signal.SIGKILL)
            assert proc.wait() == -signal.SIGKILL
            return "killed"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    if proc.returncode != 0 or point != "none":
        pytest.fail(f"fusiongs ended with {proc.returncode} without reaching point {point!r}:\n"
                    + log.read_text())
    return "finished"
