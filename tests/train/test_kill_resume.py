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

The points are exact, not timed (:mod:`tests.kill`).
"""

from __future__ import annotations

import json
import os
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
from tests.kill import run_killed

pytestmark = pytest.mark.skipif(not hasattr(os, "killpg"), reason="needs POSIX process groups")

ITERATIONS = 12
# checkpoints at 3, 6, 9 and 12; densification refines at 4 and 8 from statistics gathered across
# the checkpoints, splitting with its own generator; the event loss starts at 4, pose learning at 5;
# the bilinear trajectory skips the spline fit (time)
ARGS = ["trajectory=linear", "init.n_points=300", "blur.n_samples=3", "events.warmup=4",
        "events.pixels=256", f"optim.iterations={ITERATIONS}", "optim.pose_start=5",
        "densify.start=2", "densify.every=4", "densify.stop=11", "output.progress=false",
        "output.checkpoint_every=3"]

def _run(scene: Path, out: Path, point: str, *, resume: bool) -> str:
    """``fusiongs deblur`` with :data:`ARGS`, killed at ``point`` (:func:`tests.kill.run_killed`)."""
    return run_killed(["deblur", str(scene), "-o", str(out), *ARGS, *(["--resume"] if resume else [])],
                      out, point)


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
