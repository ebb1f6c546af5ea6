"""A second real recording end to end: the DAVIS346 AEDAT4 file through ``fusiongs
convert`` and ``fusiongs deblur``. It is a camera on a tripod looking at a road (59 APS frames of
500 µs, 78,830 events over 2.36 s, no trajectory): structure from motion has no parallax to work
with, so the pose stage must find the camera static instead of stopping."""

from __future__ import annotations

import json

import numpy as np

from fusiongs.cli import main
from fusiongs.io import load_scene
from tests.conftest import TINY, real_file
from tests.pipeline.test_poses import cut_recording


def test_davis346_recording_converts_and_deblurs_with_a_static_camera(tmp_path, capsys):
    src = real_file("davis346_mono.aedat4")
    scene_dir = tmp_path / "scene"
    assert main(["convert", str(src), "-o", str(scene_dir)]) == 0
    full = load_scene(scene_dir)
    fs = full.frames
    assert (full.camera.width, full.camera.height) == (346, 260) and full.poses is None
    assert len(fs) == 59 and len(full.events) == 78830 and full.events.cfa is None
    np.testing.assert_allclose(fs.t_end - fs.t_start, 500e-6, atol=1e-6)  # short exposures
    assert fs.t_start[0] == 0.0 and np.all(np.diff(fs.t_start) > 0.039)  # 25 fps

    cut = cut_recording(scene_dir, tmp_path / "cut", 6)
    out = tmp_path / "run"
    capsys.readouterr()
    assert main(["deblur", str(cut), "-o", str(out), *TINY]) == 0
    log = capsys.readouterr().out
    assert "linked by matches 6/6, failed: none; camera static" in log, log
    doc = json.loads((out / "camera.json").read_text())
    assert doc["trajectory"] == "estimated" and doc["report"]["motion"] == "static"
    assert doc["report"]["reprojection_error_px"] < 0.5  # the matched features do not move
    from fusiongs.camera.tum import read_tum

    for name in ("trajectory_initial.txt", "trajectory.txt"):
        poses = read_tum(out / name)
        assert np.isfinite(poses.c2w).all() and poses.t[0] <= 0.0 and poses.t[-1] >= fs.t_end[5]
    assert np.allclose(read_tum(out / "trajectory_initial.txt").c2w, np.eye(4))
    assert len(list((out / "deblurred").glob("*.png"))) == 6
    assert "sharpness" in json.loads((out / "metrics.json").read_text())
