"""``fusiongs convert`` and ``fusiongs inspect`` end to end through the CLI entry point."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fusiongs import cli
from fusiongs.events.h5 import write_events_h5
from fusiongs.events.readers import write_events_txt
from fusiongs.events.stream import EventStream
from fusiongs.io.scene_io import load_scene
from tests.conftest import real_file


@pytest.fixture(autouse=True)
def _only_these_verbs(monkeypatch):
    monkeypatch.setattr(cli, "VERBS", ("convert", "inspect"))


def _stream(n=3000, t0=5_000_000):
    rng = np.random.default_rng(1)
    t = t0 + np.sort(rng.integers(0, 400_000, n))
    x, y = rng.integers(0, 32, n), rng.integers(0, 24, n)
    x[:400], y[:400] = 7, 5  # a hot pixel
    return EventStream.create(t, x, y, rng.integers(0, 2, n), 32, 24)


def test_convert_text_to_scene_folder(tmp_path, capsys):
    s = _stream()
    write_events_txt(s, tmp_path / "ev.txt")
    argv = ["convert", str(tmp_path / "ev.txt"), "-o", str(tmp_path / "scene"), "--cfa", "RGGB"]
    assert cli.main(argv) == 0
    err = capsys.readouterr().err
    assert "no intrinsics given; using fx=fy=32" in err
    doc = json.loads((tmp_path / "scene" / "scene.json").read_text())
    assert doc["format"] == "fusiongs-scene" and doc["version"] == 1
    assert doc["camera"] == {"width": 32, "height": 24, "fx": 32.0, "fy": 32.0, "cx": 16.0, "cy": 12.0}
    assert doc["events"] == {"path": "events.h5", "cfa": "RGGB"} and doc["frames"] == []
    scene = load_scene(tmp_path / "scene")
    assert np.array_equal(scene.events.t, s.t - s.t[0]) and np.array_equal(scene.events.x, s.x)


def test_convert_keeps_clock_and_intrinsics_when_asked(tmp_path, capsys):
    s = _stream()
    write_events_h5(s, tmp_path / "ev.h5")
    args = ["convert", str(tmp_path / "ev.h5"), "-o", str(tmp_path / "sc"), "--keep-clock", "--fx", "40",
            "--cx", "15.5"]
    assert cli.main(args) == 0
    assert "warning" not in capsys.readouterr().err
    scene = load_scene(tmp_path / "sc")
    assert np.array_equal(scene.events.t, s.t)
    assert (scene.camera.fx, scene.camera.fy, scene.camera.cx, scene.camera.cy) == (40, 40, 15.5, 12)


def _fails_with_one_line(argv, capsys, match):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and match in err, err
    return err


def test_bad_inputs_exit_2_with_one_line(tmp_path, capsys):
    (tmp_path / "u.txt").write_text("4 4\n0.2 1 1 1\n0.1 1 1 0\n")
    out = str(tmp_path / "o")
    _fails_with_one_line(["convert", str(tmp_path / "u.txt"), "-o", out], capsys, "sorted ascending")
    assert cli.main(["convert", str(tmp_path / "u.txt"), "-o", out, "--sort"]) == 0
    capsys.readouterr()
    _fails_with_one_line(["convert", str(tmp_path / "u.txt"), "-o", out], capsys, "scene.json exists")
    (tmp_path / "b.txt").write_text("4 4\n0.1 9 1 1\n")
    _fails_with_one_line(["inspect", str(tmp_path / "b.txt")], capsys, "inside the 4x4 sensor")
    assert cli.main(["inspect", str(tmp_path / "b.txt"), "--drop-invalid"]) == 2  # then no events
    capsys.readouterr()
    (tmp_path / "e.txt").write_text("4 4\n")
    _fails_with_one_line(["convert", str(tmp_path / "e.txt"), "-o", out + "2"], capsys, "at least one event")
    _fails_with_one_line(["inspect", str(tmp_path / "missing.h5")], capsys, "no such file")


def test_unknown_cfa_is_rejected_by_the_parser(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["convert", "x.txt", "-o", str(tmp_path), "--cfa", "RGBG"])
    assert e.value.code == 2


def test_inspect_scene_reports_and_warns(tmp_path, capsys):
    write_events_txt(_stream(), tmp_path / "ev.txt")
    cli.main(["convert", str(tmp_path / "ev.txt"), "-o", str(tmp_path / "sc")])
    capsys.readouterr()
    assert cli.main(["inspect", str(tmp_path / "sc"), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["events"] == 3000 and (r["width"], r["height"]) == (32, 24) and r["frames"]["count"] == 0
    assert 0 < r["on_fraction"] < 1 and r["rate_ev_per_s"] > 0
    assert any("hot pixel" in w and "(x=7, y=5)" in w for w in r["warnings"])
    assert cli.main(["inspect", str(tmp_path / "sc")]) == 0
    text = capsys.readouterr().out
    assert "3,000" in text and "warning: 1 hot pixel" in text


def test_inspect_raw_event_file(tmp_path, capsys):
    write_events_txt(_stream(), tmp_path / "ev.txt")
    assert cli.main(["inspect", str(tmp_path / "ev.txt"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["kind"] == "events"


def test_convert_real_aedat4_writes_aps_frames_with_exposures(tmp_path, capsys):
    path = real_file("davis346_mono.aedat4")
    assert cli.main(["convert", str(path), "-o", str(tmp_path / "sc"), "--fx", "300"]) == 0
    scene = load_scene(tmp_path / "sc")
    assert len(scene.frames) == 59 and scene.frames.images.shape[1:] == (260, 346, 1)
    assert scene.frames.response == "linear"
    assert np.allclose(scene.frames.t_end - scene.frames.t_start, 500e-6, atol=1e-9)
    assert scene.frames.t_start[0] == 0.0 and len(scene.events) == 78_830
    capsys.readouterr()
    assert cli.main(["inspect", str(tmp_path / "sc"), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["frames"]["count"] == 59 and r["frames"]["exposure_ms_median"] == pytest.approx(0.5)
