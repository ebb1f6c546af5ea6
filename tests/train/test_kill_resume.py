"""``kill -9`` at any moment of ``fusiongs deblur``, then ``--resume``.

One output folder, one real ``fusiongs deblur`` subprocess after another, each SIGKILLed at a
chosen point and the next started with ``--resume``:

1. while the thresholds are estimated (before anything is written),
2. mid-training, while the checkpoint of iteration 6 is half written (that of iteration 3 in place),
3. while ``report.png`` is half written (training done; every other output in place),

then a last ``--resume`` runs to the end. After each kill every file in OUT must be whole (JSON
parses, PNGs decode with valid chunks, the checkpoint loads, ...); a half-written file may exist
only as a temporary of the atomic writer, and the next run clears those away. The resumed run
ends on the same Gaussians and the same deblur PSNR as an uninterrupted run with the same seed.

The points are exact, not timed: the child process runs ``fusiongs.cli.main`` behind a small hook
(:data:`CHILD`) that, on reaching the point, writes a marker file and sleeps; the test then kills
the whole process group with SIGKILL. A half-written file is made by cutting the atomic writer's
finished temporary to half its size just before its rename.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from fusiongs.atomic import is_temporary
from fusiongs.camera.tum import read_tum
from fusiongs.configs.load import load_config
from fusiongs.frames.image_io import read_image
from fusiongs.scene.ply import load_ply
from fusiongs.train.checkpoint import load_checkpoint
from fusiongs.train.settings import DeblurConfig

pytestmark = pytest.mark.skipif(not hasattr(os, "killpg"), reason="needs POSIX process groups")

REPO_ROOT = Path(__file__).resolve().parents[2]
ITERATIONS = 12
# checkpoints at 3, 6, 9 and 12; densification refines at 4 and 8 from statistics gathered across
# the checkpoints, splitting with its own generator; the event loss starts at 4, pose learning at 5;
# the bilinear trajectory skips the spline fit (time)
ARGS = ["trajectory=linear", "init.n_points=300", "blur.n_samples=3", "events.warmup=4",
        "events.pixels=256", f"optim.iterations={ITERATIONS}", "optim.pose_start=5",
        "densify.start=2", "densify.every=4", "densify.stop=11", "output.progress=false",
        "output.checkpoint_every=3"]
TIMEOUT_S = 120.0

# argv: POINT MARKER deblur-arguments... POINT is "none", "estimate" (entering the threshold
# estimate) or "NAME:N:after|half" (the N-th atomic write of OUT/**/NAME in this process: just
# after its rename, or with its temporary cut to half its size instead of the rename)
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
        if Path(dst).name != name:
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


def _run(scene: Path, out: Path, point: str, *, resume: bool) -> str:
    """Run ``fusiongs deblur`` in a subprocess; with a ``point`` other than ``"none"`` SIGKILL it
    there. Returns how it ended (``"killed"`` or ``"finished"``); fails when it ends otherwise."""
    marker = out.parent / f"{out.name}.parked"
    marker.unlink(missing_ok=True)
    log = out.parent / f"{out.name}.log"
    cmd = [sys.executable, "-c", CHILD, point, str(marker), "deblur", str(scene), "-o", str(out),
           *ARGS, *(["--resume"] if resume else [])]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    with open(log, "w") as f:
        proc = subprocess.Popen(cmd, cwd=REPO_ROOT, env=env, stdout=f, stderr=subprocess.STDOUT,
                                start_new_session=True)
    t0 = time.monotonic()
    try:
        while proc.poll() is None and not marker.exists():
            if time.monotonic() - t0 > TIMEOUT_S:
                pytest.fail(f"fusiongs deblur ({point}) still running after {TIMEOUT_S} s:\n"
                            + log.read_text())
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
        pytest.fail(f"fusiongs deblur ended with {proc.returncode} without reaching point {point!r}:\n"
                    + log.read_text())
    return "finished"


def _check_whole(path: Path) -> None:
    """Read ``path`` back by its kind; raises when it is truncated or damaged."""
    kind = path.suffix
    if kind == ".json":
        json.loads(path.read_text())
    elif kind == ".jsonl":
        text = path.read_text()
        assert not text or text.endswith("\n"), f"{path}: last line cut"
        for line in text.splitlines():
            json.loads(line)
    elif kind == ".png":
        read_image(path)  # walks every chunk and checks its CRC first
    elif kind == ".pt":
        load_checkpoint(path)
    elif kind == ".ply":
        load_ply(path)
    elif kind == ".yaml":
        load_config(DeblurConfig, path)
    elif kind == ".txt":
        read_tum(path)
    elif kind == ".mp4":
        from imageio_ffmpeg import count_frames_and_secs

        assert count_frames_and_secs(path)[0] > 0, f"{path}: no frames"
    else:
        raise AssertionError(f"{path}: a file fusiongs deblur does not write")


def _check_out(out: Path) -> list[Path]:
    """Every file under ``out`` is whole, or a temporary of the atomic writer; returns those."""
    temporaries = []
    for path in sorted(p for p in out.rglob("*") if p.is_file()):
        if is_temporary(path):
            temporaries.append(path)
        else:
            _check_whole(path)
    return temporaries


def _deblur_psnr(out: Path) -> float:
    return json.loads((out / "metrics.json").read_text())["mean"]["deblur"]["fusiongs"]["psnr"]


def test_kill_9_then_resume_gives_the_uninterrupted_result(tiny_scene, tmp_path):
    reference = tmp_path / "reference"
    assert _run(tiny_scene, reference, "none", resume=False) == "finished"
    assert _check_out(reference) == []

    out = tmp_path / "out"
    points = ["estimate", "checkpoint.pt:2:half", "report.png:1:half"]
    for i, point in enumerate(points):
        assert _run(tiny_scene, out, point, resume=i > 0) == "killed"
        temporaries = _check_out(out)
        if point.endswith(":half"):  # the half-written file is a temporary, its final name intact
            name = point.split(":")[0]
            assert [p for p in temporaries if p.name.startswith(f".{Path(name).stem}.")], temporaries
        if point == "checkpoint.pt:2:half":  # the previous checkpoint is still there, whole
            assert load_checkpoint(out / "checkpoint.pt")["iteration"] == 3
    assert _run(tiny_scene, out, "none", resume=True) == "finished"
    assert _check_out(out) == []  # the killed runs' temporaries are gone

    ours, ref = load_checkpoint(out / "checkpoint.pt"), load_checkpoint(reference / "checkpoint.pt")
    assert ours["iteration"] == ref["iteration"] == ITERATIONS
    assert ours["history"]["iteration"] == list(range(ITERATIONS))  # each iteration recorded once
    assert len((out / "history.jsonl").read_text().splitlines()) == ITERATIONS
    assert ours["n_gaussians"] == ref["n_gaussians"]
    for key, value in ref["model"].items():
        torch.testing.assert_close(ours["model"][key], value, rtol=1e-4, atol=1e-5, msg=key)
    assert abs(_deblur_psnr(out) - _deblur_psnr(reference)) <= 0.1
    for name in ("renders", "deblurred"):
        assert sorted(p.name for p in (out / name).iterdir()) == \
            sorted(p.name for p in (reference / name).iterdir())
