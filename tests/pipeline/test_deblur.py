"""End to end: ``fusiongs deblur`` on a tiny simulated scene writes every output; resume; errors."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from fusiongs.cli import main
from fusiongs.configs.load import load_config
from fusiongs.frames.image_io import read_image
from fusiongs.io import load_scene
from fusiongs.scene.ply import load_ply
from fusiongs.train.checkpoint import load_checkpoint
from fusiongs.train.settings import DeblurConfig
from tests.conftest import TINY, simulated_scene


def test_deblur_writes_every_output(tiny_scene, tiny_run):
    scene = load_scene(tiny_scene)
    h, w = scene.camera.height, scene.camera.width
    for r in scene.renders:
        img = read_image(tiny_run / "renders" / f"{r.name}.png")
        assert img.shape == (h, w, 3)
    for name in scene.frames.names:
        assert read_image(tiny_run / "deblurred" / f"{name}.png").shape == (h, w, 3)
    assert (tiny_run / "deblurred.mp4").stat().st_size > 0
    model = load_ply(tiny_run / "model.ply")
    assert model.n > 0 and torch.isfinite(model.means).all()
    assert load_checkpoint(tiny_run / "checkpoint.pt")["iteration"] == 10
    cfg = load_config(DeblurConfig, tiny_run / "config.yaml")
    assert cfg.optim.iterations == 10 and cfg.init.n_points == 300
    # the renders per exposure were derived from the motion: config.yaml holds the N used, spacing 0
    assert cfg.blur.n_samples == 3 and cfg.blur.sample_spacing == 0.0
    theta = json.loads((tiny_run / "thresholds.json").read_text())
    assert len(theta["theta_pos"]) == 1 and theta["theta_pos"][0] > 0
    metrics = json.loads((tiny_run / "metrics.json").read_text())
    # a simulated scene knows its true thresholds: EDI with them is printed beside EDI estimated
    expected = {"fusiongs", "fusiongs_render", "blurry", "edi", "edi_true_theta"}
    assert set(metrics["mean"]["deblur"]) == expected
    # ten iterations explain little of the frames: the exposure-ratio correction takes the rest from
    # them (deblurred frames and the requested renders at their mid-exposure; novel ones stay renders)
    deb = metrics["mean"]["deblur"]
    assert deb["fusiongs"]["psnr"] > deb["fusiongs_render"]["psnr"] + 8
    # frames.json places the frames in time for `fusiongs view`; model.ply's display fit is scored
    frames = json.loads((tiny_run / "frames.json").read_text())
    assert [f["name"] for f in frames["frames"]] == list(scene.frames.names)
    assert [f["t_mid"] for f in frames["frames"]] == pytest.approx(list(scene.frames.mid_times()))
    assert frames["scene"] == str(Path(tiny_scene).resolve()) and all(f["trained"] for f in frames["frames"])
    assert metrics["model_ply"]["psnr_after"] >= metrics["model_ply"]["psnr_before"]
    rows = [json.loads(line) for line in (tiny_run / "history.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == list(range(10))
    assert all(r["loss"] is not None and r["n_gaussians"] > 0 and len(r["theta_pos"]) == 1 for r in rows)
    assert {"blur", "event", "event_weight", "psnr_input"} <= set(rows[0])
    # the truth probe scores the renders after the last iteration (10 < output.truth_every)
    assert [r["iteration"] for r in rows if r["psnr_truth"] is not None] == [9]
    assert 5.0 < rows[-1]["psnr_truth"] < 60.0 and rows[-1]["psnr_truth_fit"] >= rows[-1]["psnr_truth"] - 0.5
    calib = json.loads((tiny_run / "calibration.json").read_text())
    assert calib["format"] == "fusiongs-calibration" and calib["thresholds"]["channels"] == ["grey"]
    assert "novel" in metrics["mean"]
    # θ where it started, when the events started (iteration 4) and at the end, per polarity
    th = metrics["thresholds"]
    assert th["calibration"] == [calib["thresholds"]["theta_pos"], calib["thresholds"]["theta_neg"]]
    assert th["events_start"] == [rows[4]["theta_pos"], rows[4]["theta_neg"]]
    assert th["final"] == [theta["theta_pos"], theta["theta_neg"]]
    assert read_image(tiny_run / "report.png").shape[1] > 100
    assert not list(tiny_run.rglob("*.tmp*")), "no temporary files are left behind"


def test_resume_continues_from_the_checkpoint(tiny_scene, tiny_run, tmp_path):
    out = tmp_path / "run"
    args = ["deblur", str(tiny_scene), "-o", str(out), *TINY]
    assert main(args[:-1] + ["optim.iterations=6"] + args[-1:]) == 0
    first = load_checkpoint(out / "checkpoint.pt")
    assert first["iteration"] == 6
    assert main(args + ["--resume"]) == 0
    second = load_checkpoint(out / "checkpoint.pt")
    assert second["iteration"] == 10
    assert len(second["history"]["iteration"]) == 10  # 6 recorded before, 4 after resuming


def test_render_command_renders_requested_instants(tiny_run, tmp_path):
    assert main(["render", str(tiny_run), "--t", "0.03", "0.06", "-o", str(tmp_path)]) == 0
    files = sorted(tmp_path.glob("t_*.png"))
    assert len(files) == 2
    a, b = read_image(files[0]), read_image(files[1])
    assert a.shape == b.shape and not np.array_equal(a, b)


def test_render_outside_the_recording_is_one_line_and_exit_2(tiny_run, tmp_path, capsys):
    assert main(["render", str(tiny_run), "--t", "0.03", "5", "-o", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--t" in err[0] and "got 5" in err[0] and "recording's range [" in err[0]
    assert not list(tmp_path.glob("t_*.png"))


def test_eval_command_reads_run_and_truth(tiny_scene, tiny_run, capsys):
    assert main(["eval", str(tiny_run), "--gt", str(tiny_scene / "gt")]) == 0
    out = capsys.readouterr().out
    assert "fusiongs" in out and "deblur" in out


@pytest.mark.parametrize("bad, expected", [
    (["events.nope=1"], "events.nope"),
    (["events.loss=huber"], "events.loss"),
    (["optim.iterations=many"], "optim.iterations"),
    (["densify.max_gaussians=-1"], "densify.max_gaussians"),
    (["threshold.lr=-1"], "threshold.lr"),
    (["threshold.lr=0"], "threshold.lr"),
    (["threshold.init=0"], "threshold.init"),
    (["threshold.regularise=-0.5"], "threshold.regularise"),
    (["optim.lr_pose=-1e-3"], "optim.lr_pose"),
])
def test_bad_config_is_one_line_and_exit_2(tiny_scene, tmp_path, capsys, bad, expected):
    assert main(["deblur", str(tiny_scene), "-o", str(tmp_path), *bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0]


def test_missing_scene_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["deblur", str(tmp_path / "absent"), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene.json" in err[0]


def test_shipped_default_config_equals_builtin_defaults():
    from fusiongs.configs import config_file

    assert load_config(DeblurConfig, config_file("deblur.yaml")) == DeblurConfig()
    fast = load_config(DeblurConfig, config_file("deblur_fast.yaml"))
    assert dataclasses.replace(fast) != DeblurConfig()


def test_render_and_eval_on_missing_run_are_one_line_and_exit_2(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope"), "--t", "0.1"]) == 2
    assert main(["eval", str(tmp_path / "nope"), "--gt", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "checkpoint" in err[0] and "run folder" in err[1]


def test_corrupt_checkpoint_is_named(tmp_path, capsys):
    (tmp_path / "checkpoint.pt").write_bytes(b"not a checkpoint")
    assert main(["render", str(tmp_path), "--t", "0.1"]) == 2
    assert "checkpoint.pt" in capsys.readouterr().err


@pytest.fixture(scope="module")
def three_frames_no_truth(tmp_path_factory):
    """Three blurry frames with events and a trajectory, but no gt/ (as a real recording)."""
    import shutil

    root = simulated_scene(tmp_path_factory.mktemp("scene3"), duration=0.15, frames=3)
    shutil.rmtree(root / "gt")
    return root


def test_holdout_without_truth_scores_held_out_frames_and_writes_report(three_frames_no_truth, tmp_path,
                                                                        capsys):
    out = tmp_path / "run"
    assert main(["deblur", str(three_frames_no_truth), "-o", str(out), "--holdout", "2", *TINY]) == 0
    log = capsys.readouterr().out
    assert "held-out frames" in log and "edi_carried" in log and "Tenengrad" in log
    doc = json.loads((out / "heldout.json").read_text())
    assert doc["holdout"] == 2 and list(doc["frames"]) == ["000001"]  # frame 1 of 0..2: i % 2 == 1
    row = doc["frames"]["000001"]
    assert row["nearest_frame"] == "000000" and row["neighbours"] == ["000000", "000002"]
    for m in ("fusiongs", "fusiongs_ratio", "nearest", "edi_carried"):
        assert np.isfinite(row[m]) and row[m] > 5 and doc["mean"][m] == {"psnr": row[m], "n": 1}
    assert row["edi_carried"] > row["nearest"]  # events carry the neighbours across the motion
    # trained on the two kept frames; outputs still cover every frame
    assert load_checkpoint(out / "checkpoint.pt")["log_gain"].numel() == 2
    assert sorted(p.stem for p in (out / "deblurred").glob("*.png")) == ["000000", "000001", "000002"]
    frames = json.loads((out / "frames.json").read_text())["frames"]
    assert [(f["name"], f["trained"]) for f in frames] == [("000000", True), ("000001", False),
                                                           ("000002", True)]
    metrics = json.loads((out / "metrics.json").read_text())
    assert "mean" not in metrics and "gt/" in metrics["note"]
    assert metrics["heldout"]["mean"] == doc["mean"]
    assert set(metrics["sharpness"]) == {"fusiongs", "fusiongs_render", "blurry", "edi"}
    assert all(v["n"] == 3 and v["tenengrad"] > 0 for v in metrics["sharpness"].values())
    assert read_image(out / "report.png").shape[1] > 100


@pytest.mark.parametrize("k, expected", [("1", "integer >= 2"), ("x", "integer >= 2"),
                                         ("3", "first and last are always kept")])
def test_bad_holdout_is_one_line_and_exit_2(three_frames_no_truth, tmp_path, capsys, k, expected):
    assert main(["deblur", str(three_frames_no_truth), "-o", str(tmp_path), "--holdout", k, *TINY]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--holdout" in err[0] and expected in err[0]
    assert not (tmp_path / "checkpoint.pt").exists()
