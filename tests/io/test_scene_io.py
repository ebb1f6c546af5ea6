"""Scene folder load/save: round trip and errors naming the file and key."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.tum import PoseSamples
from fusiongs.errors import InputError
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.image_io import write_png
from fusiongs.io import load_scene, save_scene
from fusiongs.io.scene import RenderRequest, Scene
from tests.conftest import real_file

W, H = 12, 8


def _scene(channels=3, cfa="RGGB", bits=8) -> Scene:
    rng = np.random.default_rng(0)
    top = 2 ** bits - 1
    imgs = (rng.integers(0, top + 1, (2, H, W, channels)) / top).astype(np.float32)
    fs = FrameSet(imgs, np.array([0.01, 0.05]), np.array([0.03, 0.08]), ("000000", "000001"), "gamma:2.2")
    n = 500
    ev = EventStream.create(np.sort(rng.integers(0, 100_000, n)), rng.integers(0, W, n),
                            rng.integers(0, H, n), rng.choice([-1, 1], n), W, H, cfa)
    c2w = np.tile(np.eye(4), (3, 1, 1))
    c2w[:, 0, 3] = [0.0, 0.1, 0.2]
    poses = PoseSamples(np.array([0.0, 0.05, 0.1]), c2w)
    cam = PinholeCamera(W, H, 10.0, 11.0, 6.0, 4.0, (0.0,) * 5)  # non-zero: refused on load
    return Scene(cam, ev, fs, poses, (RenderRequest("deblur_0", 0.02), RenderRequest("novel", 0.09)))


@pytest.mark.parametrize("channels,bits,cfa", [(3, 8, "RGGB"), (1, 16, None)])  # grey frames: grey events
def test_save_then_load_round_trips_everything(tmp_path, channels, bits, cfa):
    scene = _scene(channels, cfa, bits=bits)
    jp = save_scene(scene, tmp_path / "s", images_bits=bits)
    assert jp == tmp_path / "s" / "scene.json"
    got = load_scene(tmp_path / "s")
    assert got.camera == scene.camera and got.renders == scene.renders and got.root == tmp_path / "s"
    np.testing.assert_allclose(got.frames.images, scene.frames.images, atol=1e-7)
    np.testing.assert_array_equal(got.frames.t_end, scene.frames.t_end)
    assert got.frames.names == scene.frames.names and got.frames.response == "gamma:2.2"
    for k in "txyp":
        np.testing.assert_array_equal(getattr(got.events, k), getattr(scene.events, k))
    assert got.events.cfa == cfa and (got.events.width, got.events.height) == (W, H)
    np.testing.assert_allclose(got.poses.c2w, scene.poses.c2w, atol=1e-8)
    assert load_scene(jp, load_events=False).events is None  # scene.json path works too


def test_frame_only_scene_round_trips(tmp_path):
    s = _scene()
    scene = Scene(s.camera, None, s.frames)
    save_scene(scene, tmp_path)
    got = load_scene(tmp_path)
    assert got.events is None and got.poses is None and len(got.frames) == 2


def _saved(tmp_path):
    save_scene(_scene(), tmp_path)
    return json.loads((tmp_path / "scene.json").read_text())


def _rewrite(tmp_path, doc):
    (tmp_path / "scene.json").write_text(json.dumps(doc))


def test_missing_or_invalid_scene_json(tmp_path):
    with pytest.raises(InputError, match="scene.json"):
        load_scene(tmp_path)
    (tmp_path / "scene.json").write_text('{"format": ')
    with pytest.raises(InputError, match=r"scene.json: line 1 column \d+: expected valid JSON"):
        load_scene(tmp_path)


def test_missing_frame_file_names_the_key(tmp_path):
    _saved(tmp_path)
    (tmp_path / "frames" / "000001.png").unlink()
    with pytest.raises(InputError, match=r"scene.json: frames\[1\].path: expected an existing"):
        load_scene(tmp_path)


def test_frame_of_wrong_size_names_the_image(tmp_path):
    _saved(tmp_path)
    write_png(tmp_path / "frames" / "000001.png", np.zeros((H, W + 1, 3)))
    with pytest.raises(InputError, match=r"000001.png: frames\[1\].path: expected an image of the camera"):
        load_scene(tmp_path)


def test_frames_with_mixed_channels_are_rejected(tmp_path):
    _saved(tmp_path)
    write_png(tmp_path / "frames" / "000001.png", np.zeros((H, W, 1)))
    with pytest.raises(InputError, match=r"frames\[1\].path: expected 3 channel"):
        load_scene(tmp_path)


def test_undecodable_frame_names_the_image(tmp_path):
    _saved(tmp_path)
    (tmp_path / "frames" / "000000.png").write_bytes(b"garbage")
    with pytest.raises(InputError, match="000000.png"):
        load_scene(tmp_path)


def test_missing_events_and_trajectory_files(tmp_path):
    _saved(tmp_path)
    (tmp_path / "trajectory.txt").write_text("0 0 0 0 0 0 0 2\n")
    with pytest.raises(InputError, match="trajectory.txt: line 1"):
        load_scene(tmp_path)
    (tmp_path / "trajectory.txt").unlink()
    with pytest.raises(InputError, match="scene.json: trajectory: expected an existing"):
        load_scene(tmp_path)
    doc = _saved(tmp_path)
    (tmp_path / "events.h5").unlink()
    with pytest.raises(InputError, match="scene.json: events.path"):
        load_scene(tmp_path)
    _rewrite(tmp_path, {**doc, "events": None})
    assert load_scene(tmp_path).events is None


def test_events_outside_the_camera_are_an_error_unless_dropped(tmp_path):
    doc = _saved(tmp_path)
    doc["camera"]["width"] = 6
    _rewrite(tmp_path, doc)
    for i in range(2):
        write_png(tmp_path / "frames" / f"00000{i}.png", np.zeros((H, 6, 3)))
    with pytest.raises(InputError, match="events.h5"):
        load_scene(tmp_path)
    got = load_scene(tmp_path, drop_invalid_events=True)
    assert int(got.events.x.max()) < 6


def test_save_rejects_duplicate_frame_names(tmp_path):
    s = _scene()
    fs = FrameSet(s.frames.images, s.frames.t_start, s.frames.t_end, ("a", "a"))
    with pytest.raises(InputError, match="names"):
        save_scene(Scene(s.camera, s.events, fs), tmp_path)


def test_raw_frames_load_as_encoded_linear_data(tmp_path):
    src = real_file("kodak_dc50_bayer.kdc")
    shutil.copy(src, tmp_path / "f.kdc")
    doc = {"format": "fusiongs-scene", "version": 1, "frame_response": "linear",
           "camera": {"width": 768, "height": 512, "fx": 500, "fy": 500, "cx": 384, "cy": 256},
           "frames": [{"path": "f.kdc", "t_start": 0, "t_end": 0.01}]}
    _rewrite(tmp_path, doc)
    scene = load_scene(tmp_path)
    assert scene.frames.images.shape == (1, 512, 768, 3) and scene.frames.names == ("f",)
    assert 0 <= scene.frames.images.min() and scene.frames.images.max() <= 1
