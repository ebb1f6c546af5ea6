"""``fusiongs calibrate --refine`` and deblur's ``calibration_refined.json``: the thresholds raised
to the frames-only warm-up's render floor, from the very state ``deblur`` has when its events start."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

import fusiongs.train.render_threshold as rt
from fusiongs.cli import main
from fusiongs.events.thresholds import SensorThresholds, read_calibration
from fusiongs.train.render_threshold import REFINED_SYSTEMATIC, RenderFloor, refined_thresholds
from tests.conftest import TINY

# θ starts far below the fixed floor below (ON 0.05 > 0.005; OFF 0.002 < 0.005 stays)
START = ["threshold.estimate=false", "threshold.init=0.005", "threshold.learn=false"]


@pytest.fixture
def recorded_floor(monkeypatch):
    """The floor replaced by a fixed one (the tiny run's renders after 4 iterations fit nothing),
    recording the state it was called on: the Gaussians' means, colours and the trajectory."""
    calls = []

    def fixed(state, data, windows, *args, **kwargs):
        calls.append({"means": state.model.means.detach().clone(),
                      "colours": state.model.sh0.detach().clone(),
                      "trajectory": [p.detach().clone() for p in state.trajectory.parameters()],
                      "windows": len(windows)})
        return RenderFloor(torch.tensor([[0.05], [0.002]]), torch.tensor([[500.0], [500.0]]))

    monkeypatch.setattr(rt, "render_floor", fixed)
    return calls


def _tiny_cfg(extra=()):
    from fusiongs.pipeline.deblur import resolve_config

    return resolve_config(None, [*TINY, *START, *extra])


def test_refine_renders_the_state_deblur_has_when_its_events_start(tiny_scene, tmp_path, recorded_floor):
    """The warm-up stopped at ``events.warmup`` keeps every schedule of the whole run, so the floor
    sees the same Gaussians and trajectory, bit for bit, as in a full ``deblur`` run; and the
    run's ``calibration_refined.json`` holds what the refinement returns."""
    from fusiongs.io.scene_io import load_scene
    from fusiongs.pipeline.refine import REFINED_FILE, refine_calibration

    assert main(["deblur", str(tiny_scene), "-o", str(tmp_path / "run"), *TINY, *START]) == 0
    scene = load_scene(tiny_scene)
    refined = refine_calibration(scene, SensorThresholds.uniform(0.005, 0.005, scene.events.cfa),
                                 _tiny_cfg())
    full, alone = recorded_floor
    assert torch.equal(full["means"], alone["means"]) and torch.equal(full["colours"], alone["colours"])
    assert all(torch.equal(a, b) for a, b in zip(full["trajectory"], alone["trajectory"]))
    np.testing.assert_allclose(refined.theta_pos, [0.05], rtol=1e-6)  # raised to the floor
    np.testing.assert_allclose(refined.theta_neg, [0.005], rtol=1e-6)  # its floor is lower: kept
    assert refined.method.endswith("+ render floor")
    info = refined.details["refine"]
    assert info["raised"] == [[True], [False]] and info["iterations"] == 4
    from_run = read_calibration(tmp_path / "run" / REFINED_FILE)[0]
    np.testing.assert_allclose(from_run.as_array(), refined.as_array())


def test_a_resumed_finished_run_writes_the_same_refined_calibration(tiny_scene, tmp_path, recorded_floor):
    """The floor's θ travels in the checkpoint: a run resumed after its events started (the floor
    is not fitted again) still writes ``calibration_refined.json``."""
    from fusiongs.pipeline.refine import REFINED_FILE

    out = tmp_path / "run"
    assert main(["deblur", str(tiny_scene), "-o", str(out), *TINY, *START]) == 0
    first = (out / REFINED_FILE).read_text()
    (out / REFINED_FILE).unlink()
    assert main(["deblur", str(tiny_scene), "-o", str(out), "--resume", *TINY, *START]) == 0
    assert len(recorded_floor) == 1  # fitted once, in the first run
    assert json.loads((out / REFINED_FILE).read_text())["thresholds"] == json.loads(first)["thresholds"]


def test_no_refined_calibration_without_the_floor(tiny_scene, tmp_path, recorded_floor):
    """Not written, and an earlier run's in the same folder removed."""
    from fusiongs.pipeline.refine import REFINED_FILE

    out = tmp_path / "run"
    out.mkdir()
    (out / REFINED_FILE).write_text("{}")
    args = ["deblur", str(tiny_scene), "-o", str(out), *TINY, *START, "threshold.render_floor=false"]
    assert main(args) == 0
    assert not (out / REFINED_FILE).exists() and recorded_floor == []


def test_cli_refine_prints_one_json_object_and_writes_the_file(tiny_scene, tmp_path, capsys, recorded_floor):
    out = tmp_path / "c.json"
    assert main(["calibrate", str(tiny_scene), "-o", str(out), "--json", "--refine", *TINY]) == 0
    doc = json.loads(capsys.readouterr().out)  # stdout: the JSON object alone
    th = doc["thresholds"]
    assert th["method"].endswith("+ render floor") and th["details"]["refine"]["windows"] == 32
    assert th["theta_pos"] == [pytest.approx(max(0.05, th["details"]["refine"]["before"][0][0]))]
    assert read_calibration(out)[0].details["refine"]["iterations"] == 4
    assert main(["calibrate", str(tiny_scene), "-o", str(out), "--refine", *TINY]) == 0
    assert "refined: the frames-only warm-up (4 iterations)" in capsys.readouterr().out


@pytest.mark.parametrize("args, names", [
    (["events.warmup=10"], "events.warmup"),  # the warm-up never ends (10 iterations)
    (["threshold.render_floor=false"], "threshold.render_floor"),
    (["events.enabled=false"], "events.enabled"),
    (["no_such.key=1"], "no_such.key"),
])
def test_cli_refine_refuses_a_config_it_cannot_run_in_one_line(tiny_scene, tmp_path, capsys, args, names):
    code = main(["calibrate", str(tiny_scene), "-o", str(tmp_path / "c.json"), "--refine", *TINY, *args])
    err = capsys.readouterr().err.strip()
    assert code == 2 and names in err and len(err.splitlines()) == 1
    assert not (tmp_path / "c.json").exists()


def test_cli_overrides_without_refine_and_a_one_frame_scene_are_refused(tiny_scene, tmp_path, capsys):
    from fusiongs.frames.frameset import FrameSet
    from fusiongs.io.scene_io import load_scene
    from fusiongs.sim.write import write_simulated_scene

    code = main(["calibrate", str(tiny_scene), "-o", str(tmp_path / "c.json"), "events.warmup=3"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--refine" in err and len(err.splitlines()) == 1
    sc = load_scene(tiny_scene)
    fs = sc.frames
    one = dataclasses.replace(sc, frames=FrameSet(fs.images[:1], fs.t_start[:1], fs.t_end[:1], fs.names[:1],
                                                  fs.response), renders=())
    write_simulated_scene(one, {}, tmp_path / "one")
    code = main(["calibrate", str(tmp_path / "one"), "-o", str(tmp_path / "o.json"), "--refine", *TINY])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "frames" in err and "at least 2" in err and len(err.splitlines()) == 1


def test_refined_thresholds_widen_only_what_was_raised():
    cal = SensorThresholds(("R", "G", "B"), np.array([0.1, 0.2, 0.3]), np.array([0.2, 0.2, 0.2]),
                           np.array([0.01, 0.02, 0.03]), np.array([0.004, 0.004, 0.004]), True, "mEDI",
                           {"warnings": ["w"]})
    before = torch.tensor(cal.as_array())
    after = before.clone()
    after[0, 1], after[1, 2] = 0.25, 0.3
    out = refined_thresholds(cal, before, after, iterations=7)
    np.testing.assert_allclose(out.theta_pos, [0.1, 0.25, 0.3])
    np.testing.assert_allclose(out.theta_neg, [0.2, 0.2, 0.3])
    np.testing.assert_allclose(out.std_pos, [0.01, REFINED_SYSTEMATIC * 0.25, 0.03])
    np.testing.assert_allclose(out.std_neg, [0.004, 0.004, REFINED_SYSTEMATIC * 0.3])
    assert out.details["warnings"] == ["w"] and out.details["refine"]["iterations"] == 7
    assert out.details["refine"]["raised"] == [[False, True, False], [False, False, True]]
    assert out.method == "mEDI + render floor"
    with pytest.raises(ValueError, match="3-channel"):
        refined_thresholds(cal, before[:, :1], after[:, :1])


def test_a_checkpoint_whose_floor_has_another_shape_is_one_line(tiny_scene, tmp_path, capsys, recorded_floor):
    """An edited checkpoint's floor of the wrong shape is refused when the run resumes, in one line
    naming the file, not a traceback when the refined calibration is written."""
    from fusiongs.train.checkpoint import load_checkpoint, save_checkpoint

    out = tmp_path / "run"
    assert main(["deblur", str(tiny_scene), "-o", str(out), *TINY, *START]) == 0
    ckpt = load_checkpoint(out / "checkpoint.pt")
    ckpt["threshold_floor"] = [torch.zeros(3), torch.zeros(3)]
    save_checkpoint(out / "checkpoint.pt", ckpt)
    capsys.readouterr()
    assert main(["deblur", str(tiny_scene), "-o", str(out), "--resume", *TINY, *START]) == 2
    err = capsys.readouterr().err.strip()
    assert "checkpoint.pt" in err and "threshold_floor" in err and len(err.splitlines()) == 1
