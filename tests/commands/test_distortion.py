"""Lens distortion in scene.json: refused (not supported yet) by every command that loads a scene,
unless all coefficients are zero."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fusiongs import cli
from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet
from fusiongs.io.scene import Scene
from fusiongs.io.scene_io import save_scene


def _scene_folder(root, distortion):
    rng = np.random.default_rng(0)
    n, w, h = 2000, 16, 12
    ev = EventStream.create(np.sort(rng.integers(0, 100_000, n)), rng.integers(0, w, n),
                            rng.integers(0, h, n), rng.choice([-1, 1], n), w, h)
    fs = FrameSet(rng.random((1, h, w, 1)).astype(np.float32), np.array([0.02]), np.array([0.05]),
                  ("000000",), "linear")
    save_scene(Scene(PinholeCamera(w, h, 16.0, 16.0, 8.0, 6.0), ev, fs), root)
    doc = json.loads((root / "scene.json").read_text())
    doc["camera"]["distortion"] = distortion
    (root / "scene.json").write_text(json.dumps(doc))
    return root


@pytest.mark.parametrize("verb", [
    ["inspect", "{scene}"],
    ["deblur", "{scene}", "-o", "{out}"],
    ["edi", "{scene}", "-o", "{out}"],
    ["calibrate", "{scene}", "-o", "{out}"],
])
def test_commands_refuse_a_distorted_scene_in_one_line(tmp_path, capsys, verb):
    scene = _scene_folder(tmp_path / "scene", [-0.2, 0.05, 0.0, 0.0, 0.0])
    argv = [a.format(scene=scene, out=tmp_path / "out") for a in verb]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "camera.distortion" in err[0] and "not supported yet" in err[0] and "undistort" in err[0]


def test_inspect_accepts_all_zero_distortion(tmp_path, capsys):
    scene = _scene_folder(tmp_path / "scene", [0.0, 0.0, 0.0, 0.0, 0.0])
    assert cli.main(["inspect", str(scene)]) == 0
    assert "distortion" not in capsys.readouterr().err
