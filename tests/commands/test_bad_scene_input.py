"""Bad scene folders as a new user's files arrive: every command that reads a scene refuses each in
one stderr line naming the file (and key), with exit status 2."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from fusiongs import cli
from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.tum import PoseSamples
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.image_io import write_png
from fusiongs.io.scene import Scene
from fusiongs.io.scene_io import save_scene

W, H = 16, 12
INSPECT = ["inspect", "{scene}"]
EDI = ["edi", "{scene}", "-o", "{out}", "--theta", "0.2"]
CALIBRATE = ["calibrate", "{scene}", "-o", "{out}"]
DEBLUR = ["deblur", "{scene}", "-o", "{out}"]


def _scene_folder(root, *, width=W, height=H, channels=3, cfa=None):
    """A small valid scene: 2 frames [0.02, 0.05] and [0.10, 0.13] s, events over [0, 0.2] s,
    a trajectory over [0, 0.2] s."""
    rng = np.random.default_rng(0)
    n = 2000
    ev = EventStream.create(np.sort(rng.integers(0, 200_000, n)), rng.integers(0, width, n),
                            rng.integers(0, height, n), rng.choice([-1, 1], n), width, height, cfa)
    fs = FrameSet(rng.random((2, height, width, channels)).astype(np.float32), np.array([0.02, 0.10]),
                  np.array([0.05, 0.13]), ("000000", "000001"), "linear")
    c2w = np.tile(np.eye(4), (3, 1, 1))
    c2w[:, 0, 3] = [0.0, 0.1, 0.2]
    poses = PoseSamples(np.array([0.0, 0.1, 0.2]), c2w)
    save_scene(Scene(PinholeCamera(width, height, 16.0, 16.0, width / 2, height / 2), ev, fs, poses), root)
    return root


def _edit_json(root, edit):
    doc = json.loads((root / "scene.json").read_text())
    edit(doc)
    (root / "scene.json").write_text(json.dumps(doc))


def _fails_in_one_line(verb, scene, tmp_path, capfd) -> str:
    argv = [a.format(scene=scene, out=tmp_path / "out") for a in verb]
    assert cli.main(argv) == 2
    err = capfd.readouterr().err.strip().splitlines()  # file-descriptor level: libpng/HDF5 too
    assert len(err) == 1, err
    assert err[0].startswith(f"fusiongs {verb[0]}: error: ")
    return err[0]


def test_the_valid_scene_passes_inspect(tmp_path, capfd):
    scene = _scene_folder(tmp_path / "scene")
    assert cli.main(["inspect", str(scene)]) == 0
    out = capfd.readouterr()
    assert "frames       2" in out.out and out.err == ""


# 1. a frame of the wrong size
@pytest.mark.parametrize("verb", [INSPECT, EDI, DEBLUR])
def test_frame_of_the_wrong_size(tmp_path, capfd, verb):
    scene = _scene_folder(tmp_path / "scene")
    write_png(scene / "frames" / "000001.png", np.zeros((6, 8, 3)))
    line = _fails_in_one_line(verb, scene, tmp_path, capfd)
    assert "000001.png" in line and "frames[1].path" in line
    assert "camera size 16x12" in line and "got 8x6" in line


# 2. a truncated or damaged PNG
@pytest.mark.parametrize("verb", [INSPECT, EDI])
@pytest.mark.parametrize("damage", ["truncated", "flipped byte", "not a png", "empty"])
def test_truncated_or_corrupt_png(tmp_path, capfd, verb, damage):
    scene = _scene_folder(tmp_path / "scene")
    p = scene / "frames" / "000001.png"
    data = p.read_bytes()
    if damage == "truncated":
        p.write_bytes(data[: len(data) // 2])
    elif damage == "flipped byte":
        b = bytearray(data)
        b[len(b) // 2] ^= 0xFF
        p.write_bytes(bytes(b))
    elif damage == "not a png":
        p.write_bytes(b"<html>404 not found</html>")
    else:
        p.write_bytes(b"")
    line = _fails_in_one_line(verb, scene, tmp_path, capfd)
    assert "000001.png" in line
    expect = {"truncated": "truncated", "flipped byte": "CRC", "not a png": "PNG", "empty": "empty"}
    assert expect[damage] in line


# 3. a truncated or damaged events.h5
@pytest.mark.parametrize("verb", [INSPECT, EDI, CALIBRATE])
@pytest.mark.parametrize("damage", ["truncated", "garbage"])
def test_truncated_or_corrupt_events_h5(tmp_path, capfd, verb, damage):
    scene = _scene_folder(tmp_path / "scene")
    p = scene / "events.h5"
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2] if damage == "truncated" else b"\x00" * len(data))
    line = _fails_in_one_line(verb, scene, tmp_path, capfd)
    assert "events.h5" in line
    assert (f"truncated: {len(data) // 2} of {len(data)} bytes" if damage == "truncated"
            else "not an HDF5 file") in line


# 4. exposure windows: backwards, overlapping, out of order
def _set_frames(times):
    def edit(doc):
        for f, (t0, t1) in zip(doc["frames"], times):
            f["t_start"], f["t_end"] = t0, t1
    return edit


@pytest.mark.parametrize("verb", [INSPECT, EDI])
@pytest.mark.parametrize("times,words", [
    ([(0.05, 0.02), (0.10, 0.13)], ["frames[0].t_end", "t_end 0.02 <= t_start 0.05 for frames/000000.png"]),
    ([(0.02, 0.05), (0.05, 0.05)], ["frames[1].t_end", "t_end 0.05 <= t_start 0.05 for frames/000001.png"]),
    ([(0.02, 0.05), (0.04, 0.07)], ["frames[1].t_start", "do not overlap", "frames/000001.png",
                                    "frames[0] (frames/000000.png) ends at 0.05 s"]),
    ([(0.10, 0.13), (0.02, 0.05)], ["frames[1].t_start", "time order", "frames/000001.png",
                                    "frames[0] (frames/000000.png) at 0.1 s"]),
])
def test_backwards_overlapping_or_unordered_exposures(tmp_path, capfd, verb, times, words):
    scene = _scene_folder(tmp_path / "scene")
    _edit_json(scene, _set_frames(times))
    line = _fails_in_one_line(verb, scene, tmp_path, capfd)
    assert "scene.json" in line
    for w in words:
        assert w in line


def test_touching_exposures_are_fine(tmp_path, capfd):
    scene = _scene_folder(tmp_path / "scene")
    _edit_json(scene, _set_frames([(0.02, 0.1 + 1e-9), (0.1, 0.13)]))  # touch within 1 µs
    assert cli.main(["inspect", str(scene)]) == 0


# 5. events that miss the frames' time range entirely (µs vs seconds mix-up)
@pytest.mark.parametrize("verb", [INSPECT, EDI, CALIBRATE])
@pytest.mark.parametrize("times,frames_range", [
    ([(20.0, 50.0), (100.0, 130.0)], "[20.000000, 130.000000] s"),  # frames in ms, not seconds
    ([(2e-5, 5e-5), (1e-4, 1.3e-4)], None),  # frames end before the first event
])
def test_events_that_miss_every_frame(tmp_path, capfd, verb, times, frames_range):
    scene = _scene_folder(tmp_path / "scene")
    if frames_range is None:  # move the events later instead: all after the last exposure
        with h5py.File(scene / "events.h5", "a") as f:
            f["events"].attrs["t_offset_us"] = np.int64(1_000_000)
        times = [(0.02, 0.05), (0.10, 0.13)]
        frames_range = "[0.020000, 0.130000] s"
    _edit_json(scene, _set_frames(times))
    line = _fails_in_one_line(verb, scene, tmp_path, capfd)
    assert "events.h5" in line and "events/t" in line
    assert "events in [" in line and f"frames in {frames_range}" in line


def test_events_partly_outside_the_frames_are_a_warning_only(tmp_path, capfd):
    scene = _scene_folder(tmp_path / "scene")
    _edit_json(scene, _set_frames([(0.15, 0.18), (0.19, 0.25)]))  # the last one ends after the events
    assert cli.main(["inspect", str(scene)]) == 0
    assert "warning: 1 frame(s) with exposures outside the event time range" in capfd.readouterr().out


# 6. the event sensor's CFA against the frames and the sensor size
@pytest.mark.parametrize("verb", [INSPECT, EDI, CALIBRATE, DEBLUR])
def test_colour_events_with_monochrome_frames(tmp_path, capfd, verb):
    scene = _scene_folder(tmp_path / "scene", channels=1, cfa="RGGB")
    line = _fails_in_one_line(verb, scene, tmp_path, capfd)
    assert "scene.json: events.cfa:" in line and "'RGGB'" in line
    assert "single-channel frames[0].path frames/000000.png" in line


@pytest.mark.parametrize("verb", [INSPECT, EDI])
@pytest.mark.parametrize("cfa,size,words", [
    ("RGBG", (W, H), ["events.cfa", "RGGB, BGGR, GRBG, GBRG", "'RGBG'"]),
])
def test_unknown_cfa(tmp_path, capfd, verb, cfa, size, words):
    scene = _scene_folder(tmp_path / "scene", width=size[0], height=size[1])

    def edit(doc):
        doc["events"]["cfa"] = cfa
    _edit_json(scene, edit)
    line = _fails_in_one_line(verb, scene, tmp_path, capfd)
    assert "scene.json" in line
    for w in words:
        assert w in line


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_odd_sensor_is_fine(tmp_path, cfa):
    # A 2x2 pattern on an odd-sized sensor just has a partial last row/column (the simulator's
    # 173x130 default sensor is such a one).
    scene = _scene_folder(tmp_path / "scene", width=15, height=13)
    if cfa is not None:
        _edit_json(scene, lambda doc: doc["events"].__setitem__("cfa", cfa))
    assert cli.main(["inspect", str(scene)]) == 0


# 7. trajectory times that do not increase
@pytest.mark.parametrize("verb", [INSPECT, EDI])
def test_non_monotonic_trajectory(tmp_path, capfd, verb):
    scene = _scene_folder(tmp_path / "scene")
    p = scene / "trajectory.txt"
    lines = p.read_text().splitlines()  # line 1 is a comment, poses on lines 2-4
    lines[2], lines[3] = lines[3], lines[2]
    p.write_text("\n".join(lines) + "\n")
    line = _fails_in_one_line(verb, scene, tmp_path, capfd)
    assert "trajectory.txt: line 4: expected strictly increasing times" in line
