"""Outputs of ``fusiongs deblur`` beyond the images: the refined camera path (``trajectory.txt``),
the pose stage's initial path on ``--resume``, and the progress bar only on a terminal."""

from __future__ import annotations

import dataclasses
import io
import json
import shutil
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from fusiongs.camera.trajectory import Trajectory
from fusiongs.camera.tum import PoseSamples, quat_xyzw_to_matrix, read_tum
from fusiongs.cli import main
from fusiongs.io import load_scene
from fusiongs.outputs.write import TRAJECTORY_RATE_HZ, trajectory_times, write_trajectory
from tests.conftest import TINY

F64 = torch.float64


def _random_samples(n: int, span: float, seed: int = 0) -> PoseSamples:
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, span, n)
    q = rng.normal(size=(n, 4)) * 0.1 + np.array([0, 0, 0, 1.0])
    c2w = np.tile(np.eye(4), (n, 1, 1))
    c2w[:, :3, :3] = quat_xyzw_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))
    c2w[:, :3, 3] = np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)
    return PoseSamples(t=t, c2w=c2w)


def _refined(mode: str) -> Trajectory:
    traj = Trajectory(_random_samples(11, 1.0), mode=mode, refine=True, out_dtype=F64, outside="clamp")
    with torch.no_grad():
        traj.delta.copy_(torch.randn(traj.delta.shape, generator=torch.Generator().manual_seed(1),
                                     dtype=F64) * 0.05)
    return traj


def test_trajectory_times_are_dense_increasing_and_hold_the_kept_instants():
    t = trajectory_times(np.array([0.0, 0.012, 0.013, 0.05]), keep_t=[0.0125, 0.0120000004, 0.2])
    assert np.all(np.diff(t) >= 1e-6) and t[0] == 0.0 and t[-1] == 0.05
    assert np.diff(t).max() <= 1 / TRAJECTORY_RATE_HZ + 1e-12
    assert {0.0125, 0.0120000004, 0.05} <= set(t.tolist())  # 0.2 is clamped to the end
    assert 0.012 not in t.tolist()  # within 1 µs of a kept instant: dropped


@pytest.mark.parametrize("mode", ["spline", "linear"])
def test_written_path_is_the_refined_one_at_the_frame_mid_times(tmp_path, mode):
    traj = _refined(mode)
    mids = np.array([0.0333, 0.41, 0.777])
    frames = type("Frames", (), {"mid_times": lambda self: mids, "__len__": lambda self: 3})()
    scene = SimpleNamespace(frames=frames)
    tr = SimpleNamespace(state=SimpleNamespace(trajectory=traj), iteration=7)
    write_trajectory(tr, scene, tmp_path / "trajectory.txt")
    text = (tmp_path / "trajectory.txt").read_text()
    assert text.startswith("#") and "7 iterations" in text
    back = read_tum(tmp_path / "trajectory.txt")
    assert np.diff(back.t).max() <= 1 / TRAJECTORY_RATE_HZ + 1e-9
    assert set(mids.tolist()) <= set(np.round(back.t, 9).tolist())
    reread = Trajectory(back, mode="linear", out_dtype=F64)
    want = traj.c2w(torch.from_numpy(mids))
    assert torch.allclose(reread.c2w(torch.from_numpy(mids)), want, atol=1e-5, rtol=0)
    unrefined = Trajectory(_random_samples(11, 1.0), mode=mode, out_dtype=F64)
    assert (unrefined.c2w(torch.from_numpy(mids)) - want).abs().max() > 1e-3  # not the initial path
    if mode == "linear":  # knots and mid-times are all in the file: the same path everywhere
        t = torch.linspace(0.0, 1.0, 997, dtype=F64)
        assert torch.allclose(reread.c2w(t), traj.c2w(t), atol=1e-6, rtol=0)


def test_deblur_writes_the_refined_path_that_loads_as_a_scene_trajectory(tiny_scene, tiny_run, tmp_path):
    from fusiongs.train.restore import restore_state

    path = tiny_run / "trajectory.txt"
    assert path.read_text().startswith("#")
    poses = read_tum(path)
    state, _, _ = restore_state(tiny_run / "checkpoint.pt")
    traj = state.trajectory
    assert traj.delta is not None and float(traj.delta.detach().abs().max()) > 0
    assert poses.t[0] == pytest.approx(traj.t_min, abs=1e-9)
    assert poses.t[-1] == pytest.approx(traj.t_max, abs=1e-9)
    scene_dir = tmp_path / "scene"
    shutil.copytree(tiny_scene, scene_dir)
    spec = json.loads((scene_dir / "scene.json").read_text())
    shutil.copy(path, scene_dir / spec["trajectory"])
    scene = load_scene(scene_dir)
    mids = torch.from_numpy(scene.frames.mid_times())
    written = Trajectory(scene.poses, mode="linear", out_dtype=F64).c2w(mids)
    trained = traj.c2w(mids).to(F64)  # float32 out of the checkpoint's trajectory
    assert torch.allclose(written, trained, atol=1e-5, rtol=0)
    assert not list(tiny_run.glob(".trajectory*")), "no temporary file is left behind"


def test_resume_after_the_pose_stage_starts_from_the_initial_path(tiny_scene, tmp_path, monkeypatch):
    """The pose stage's path is trajectory_initial.txt; the refined trajectory.txt written after
    training must not replace it as the starting point of a resumed run."""
    from fusiongs.pipeline import poses as poses_stage
    from fusiongs.sfm.register import PoseEstimate, PoseReport
    from fusiongs.train.checkpoint import load_checkpoint

    scene_dir = tmp_path / "scene"
    shutil.copytree(tiny_scene, scene_dir)
    spec = json.loads((scene_dir / "scene.json").read_text())
    full = read_tum(scene_dir / spec.pop("trajectory"))
    every = np.r_[0:len(full) - 1:20, len(full) - 1]  # sparse, as registered frames are
    given = PoseSamples(t=full.t[every], c2w=full.c2w[every])
    (scene_dir / "scene.json").write_text(json.dumps(spec))
    calls = []

    def fake_estimate(scene, **_):
        calls.append(1)
        report = PoseReport(len(scene.frames), len(scene.frames), (), (scene.camera.fx, scene.camera.fy),
                            False, None, (), 0.1, 0, 1, 1.0, 0.0)
        est = PoseEstimate(scene.camera, given, report, np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
        return poses_stage.PoseStageResult(dataclasses.replace(scene, poses=given), est, None, "stub")

    monkeypatch.setattr(poses_stage, "estimate_scene_poses", fake_estimate)
    out = tmp_path / "run"
    args = ["deblur", str(scene_dir), "-o", str(out), *TINY]
    assert main(args[:-1] + ["optim.iterations=6"] + args[-1:]) == 0
    initial = read_tum(out / "trajectory_initial.txt")
    np.testing.assert_allclose(initial.t, given.t, atol=1e-9)
    assert len(read_tum(out / "trajectory.txt")) > len(given)  # the dense refined path
    assert main(args + ["--resume"]) == 0
    assert calls == [1], "the resumed run reads the earlier poses instead of estimating again"
    assert load_checkpoint(out / "checkpoint.pt")["iteration"] == 10
    restored = poses_stage.read_pose_outputs(out, load_scene(scene_dir))
    np.testing.assert_allclose(restored.poses.t, given.t, atol=1e-9)


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _train_three_iterations(scene_dir, out):
    from fusiongs.pipeline.deblur import resolve_config
    from fusiongs.train.trainer import train

    overrides = [o for o in TINY if not o.startswith(("output.progress", "optim.iterations"))]
    cfg = resolve_config(None, overrides + ["output.progress=true", "optim.iterations=3"])
    return train(load_scene(scene_dir), cfg, out)


@pytest.mark.parametrize("terminal", [False, True])
def test_progress_bar_only_on_a_terminal(tiny_scene, tmp_path, monkeypatch, terminal):
    stream = _Terminal() if terminal else io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream)
    tr = _train_three_iterations(tiny_scene, tmp_path)
    assert tr.iteration == 3
    bar = [line for line in stream.getvalue().replace("\r", "\n").splitlines() if "3/3" in line]
    assert bool(bar) == terminal, stream.getvalue()
