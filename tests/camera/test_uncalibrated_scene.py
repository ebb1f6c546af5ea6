"""scene.json without intrinsics and/or trajectory (docs/scene-format.md): loads as an UncalibratedCamera."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fusiongs.camera.pinhole import PinholeCamera, UncalibratedCamera
from fusiongs.errors import InputError
from fusiongs.frames.image_io import write_png
from fusiongs.io import load_scene, save_scene

INTRINSICS = {"fx": 10.0, "fy": 10.0, "cx": 4.0, "cy": 3.0}


def _scene_folder(root, camera_keys: dict):
    write_png(root / "frames" / "a.png", np.full((6, 8, 1), 0.5))
    doc = {"format": "fusiongs-scene", "version": 1, "camera": {"width": 8, "height": 6, **camera_keys},
           "frames": [{"path": "frames/a.png", "t_start": 0.0, "t_end": 0.01}]}
    (root / "scene.json").write_text(json.dumps(doc))
    return root


def test_scene_without_intrinsics_and_trajectory_loads_uncalibrated(tmp_path):
    scene = load_scene(_scene_folder(tmp_path, {}))
    assert isinstance(scene.camera, UncalibratedCamera) and not scene.camera.intrinsics_known
    assert (scene.camera.width, scene.camera.height) == (8, 6)
    assert scene.poses is None
    with pytest.raises(AttributeError):
        scene.camera.fx  # noqa: B018  (no focal length to use by mistake)


def test_scene_with_all_four_intrinsics_stays_a_pinhole_camera(tmp_path):
    scene = load_scene(_scene_folder(tmp_path, INTRINSICS))
    assert scene.camera == PinholeCamera(8, 6, 10.0, 10.0, 4.0, 3.0) and scene.camera.intrinsics_known


@pytest.mark.parametrize("given", [("fx",), ("fx", "fy"), ("fx", "fy", "cx")])
def test_partial_intrinsics_name_the_missing_keys(tmp_path, given):
    _scene_folder(tmp_path, {k: INTRINSICS[k] for k in given})
    missing = [k for k in INTRINSICS if k not in given]
    with pytest.raises(InputError, match=", ".join(f"camera.{k}" for k in missing)) as e:
        load_scene(tmp_path)
    assert f"only {', '.join(given)}" in str(e.value)


def test_uncalibrated_scene_saves_without_intrinsics(tmp_path):
    scene = load_scene(_scene_folder(tmp_path / "a", {}))
    jp = save_scene(scene, tmp_path / "b")
    assert json.loads(jp.read_text())["camera"] == {"width": 8, "height": 6}
    assert isinstance(load_scene(tmp_path / "b").camera, UncalibratedCamera)


def test_guess_is_colmaps_prior_focal_and_the_centre():
    assert UncalibratedCamera(346, 260).guess() == PinholeCamera(346, 260, 415.2, 415.2, 173.0, 130.0)
    with pytest.raises(InputError, match="width"):
        UncalibratedCamera(0, 260)
