"""``fusiongs view``'s reading of a run folder: what is checked, where the frames come from (frames.json,
else the scene's scene.json), and the panel's images; no browser, no viser."""

from __future__ import annotations

import json
import socket

import numpy as np
import pytest

from fusiongs.cli import main
from fusiongs.errors import InputError
from fusiongs.frames.image_io import write_png
from fusiongs.view.run import check_run_folder, run_frames, side_by_side, to_uint8
from fusiongs.view.server import FRUSTUM_SHARE, FRUSTUM_SPACING, Latest, check_port, enlarged, frustum_scale


def _scene(root, names=("a", "b"), response="srgb"):
    """A scene.json of frames named ``names`` (0.1 s apart, 0.02 s exposures) and one render
    instant; frame images 4x3 (only scene.json is read unless a frame is shown)."""
    frames = [{"path": f"frames/{n}.png", "t_start": 0.1 * i, "t_end": 0.1 * i + 0.02}
              for i, n in enumerate(names)]
    doc = {"format": "fusiongs-scene", "version": 1, "camera": {"width": 4, "height": 3},
           "frames": frames, "frame_response": response, "renders": [{"name": "novel", "t": 0.05}]}
    root.mkdir(parents=True, exist_ok=True)
    (root / "scene.json").write_text(json.dumps(doc))
    return root


def _run(root, deblurred=("a", "b"), frames_json=None):
    """A run folder with the files the checks look for (empty checkpoint and PLY)."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "checkpoint.pt").write_bytes(b"")
    (root / "model.ply").write_bytes(b"")
    for n in deblurred:
        write_png(root / "deblurred" / f"{n}.png", np.full((3, 4, 3), 0.5, np.float32))
    if frames_json is not None:
        (root / "frames.json").write_text(json.dumps(frames_json))
    return root


def test_a_folder_that_is_not_a_finished_run_is_named_with_what_is_missing(tmp_path, capsys):
    with pytest.raises(InputError, match="checkpoint.pt"):
        check_run_folder(tmp_path)
    (tmp_path / "checkpoint.pt").write_bytes(b"")
    with pytest.raises(InputError, match="model.ply"):
        check_run_folder(tmp_path)
    (tmp_path / "chunks.json").write_text("{}")
    (tmp_path / "checkpoint.pt").unlink()
    with pytest.raises(InputError, match="chunks/NNN/run"):
        check_run_folder(tmp_path)
    assert main(["view", str(tmp_path / "nothing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nothing" in err[0] and "fusiongs view: error:" in err[0]


def test_a_port_in_use_is_one_line_and_exit_2(tmp_path, capsys):
    run = _run(tmp_path / "run")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        with pytest.raises(InputError, match="in use"):
            check_port("127.0.0.1", port)
        assert main(["view", str(run), "--port", str(port)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--port" in err[0] and str(port) in err[0]
    with pytest.raises(InputError, match="--port"):
        check_port("127.0.0.1", 70000)


def test_frames_json_places_the_frames_and_names_the_scene(tmp_path):
    scene = _scene(tmp_path / "scene")
    doc = {"scene": str(scene), "renders": [{"name": "novel", "t": 0.05}],
           "frames": [{"name": "a", "t_start": 0.0, "t_end": 0.02, "t_mid": 0.01, "trained": True},
                      {"name": "b", "t_start": 0.1, "t_end": 0.12, "t_mid": 0.11, "trained": False}]}
    rf = run_frames(_run(tmp_path / "run", frames_json=doc))
    assert [f.name for f in rf.frames] == ["a", "b"] and [f.trained for f in rf.frames] == [True, False]
    assert rf.frames[1].t_mid == 0.11 and rf.renders == (("novel", 0.05),)
    assert rf.scene == scene and rf.notes == ()
    moved = run_frames(_run(tmp_path / "run2", frames_json={**doc, "scene": str(tmp_path / "gone")}))
    assert moved.scene is None and "--scene" in moved.notes[0]
    bad = _run(tmp_path / "run3", frames_json={**doc, "frames": [{"name": "a", "t_start": "x"}]})
    with pytest.raises(InputError, match=r"frames\[0\].t_start"):
        run_frames(bad)


def test_a_run_older_than_frames_json_is_placed_from_its_scene_or_says_what_is_missing(tmp_path):
    scene = _scene(tmp_path / "scene")
    old = _run(tmp_path / "old")
    rf = run_frames(old, scene)
    assert [f.name for f in rf.frames] == ["a", "b"]
    assert [f.t_mid for f in rf.frames] == pytest.approx([0.01, 0.11])
    assert rf.scene == scene and "no frames.json" in rf.notes[0]
    assert all(f.trained for f in rf.frames)
    (old / "heldout.json").write_text(json.dumps({"holdout": 2, "frames": {"b": {"fusiongs": 30.0}}}))
    assert [f.trained for f in run_frames(old, scene).frames] == [True, False]
    bare = run_frames(old)
    assert bare.frames == () and "--scene" in bare.notes[0] and "2 frames" in bare.notes[0]
    with pytest.raises(InputError, match="frames"):
        run_frames(old, _scene(tmp_path / "other", names=("x", "y", "z")))
    assert run_frames(_run(tmp_path / "event_only", deblurred=())).notes == ()  # nothing missing


def test_panel_images_side_by_side_and_enlarged():
    a = to_uint8(np.zeros((3, 4, 1)))
    b = to_uint8(np.ones((3, 4, 3)))
    pair = side_by_side(a, b, gap=2)
    assert pair.shape == (3, 10, 3) and pair[:, :4].max() == 0 and pair[:, 6:].min() == 255
    assert side_by_side(None, b, gap=2)[:, :4].max() == 96 and side_by_side(None, None) is None
    big = enlarged(pair, width=30)
    assert big.shape == (9, 30, 3) and np.array_equal(big[::3, ::3], pair)
    assert enlarged(np.zeros((300, 400, 3), np.uint8), width=320).shape == (300, 400, 3)


def test_latest_drops_the_requests_queued_behind_a_running_call():
    import threading
    import time

    seen, started, release = [], threading.Event(), threading.Event()

    def slow(v):
        seen.append(v)
        if v == 1:
            started.set()
            release.wait(5)

    latest = Latest(slow)
    first = threading.Thread(target=latest, args=(1,))
    first.start()
    started.wait(5)
    waiting = []
    for v in (2, 3, 4):  # each waits on the running call; the newest request is 4
        waiting.append(threading.Thread(target=latest, args=(v,)))
        waiting[-1].start()
        deadline = time.monotonic() + 5
        while latest.wanted != v and time.monotonic() < deadline:
            time.sleep(0.001)
    release.set()
    for t in [first, *waiting]:
        t.join(5)
    assert seen == [1, 4]


def test_frustums_stay_smaller_than_the_steps_between_frames():
    c2w = np.tile(np.eye(4), (4, 1, 1))
    c2w[:, 0, 3] = [0.0, 0.1, 0.2, 0.3]  # 0.1 apart
    assert frustum_scale(c2w, depth=100.0) == pytest.approx(FRUSTUM_SPACING * 0.1)
    assert frustum_scale(c2w, depth=0.01) == pytest.approx(FRUSTUM_SHARE * 0.01)
    assert frustum_scale(c2w[:1], depth=2.0) == pytest.approx(FRUSTUM_SHARE * 2.0)  # one frame
