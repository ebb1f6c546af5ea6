"""The pose stage of ``fusiongs deblur``: a recording without trajectory or intrinsics."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from fusiongs.cli import main
from fusiongs.frames.image_io import write_png
from fusiongs.io import load_scene
from fusiongs.pipeline.poses import estimate_scene_poses, needs_pose_stage, read_pose_outputs
from tests.conftest import TINY, real_data_dir


def cut_recording(src, dst, n_frames: int):
    """The first ``n_frames`` frames of a scene folder and the events up to the last one's end."""
    from fusiongs.events.h5 import read_events_h5, write_events_h5

    doc = json.loads((src / "scene.json").read_text())
    doc["frames"] = doc["frames"][:n_frames]
    (dst / "frames").mkdir(parents=True)
    for f in doc["frames"]:
        shutil.copy(src / f["path"], dst / f["path"])
    cam, ev = doc["camera"], doc["events"]
    events = read_events_h5(src / ev["path"], cam["width"], cam["height"], ev["cfa"])
    end_us = round(doc["frames"][-1]["t_end"] * 1e6) + 1
    write_events_h5(events.slice_time(int(events.t[0]), end_us), dst / "events.h5")
    doc["events"]["path"] = "events.h5"
    doc.pop("trajectory", None)
    (dst / "scene.json").write_text(json.dumps(doc))
    return dst


def _strip_camera(scene_dir):
    """Remove the trajectory and the intrinsics from a scene folder (what a raw recording has)."""
    doc = json.loads((scene_dir / "scene.json").read_text())
    for k in ("fx", "fy", "cx", "cy"):
        doc["camera"].pop(k)
    (scene_dir / doc.pop("trajectory")).unlink()
    (scene_dir / "scene.json").write_text(json.dumps(doc))


@pytest.fixture(scope="module")
def raw_sim_scene(tmp_path_factory):
    """A small simulated recording (sharp enough views of the textured gallery) without trajectory
    and intrinsics."""
    from fusiongs.sim.simulate import SimConfig, run_simulation
    from fusiongs.sim.write import write_simulated_scene

    root = tmp_path_factory.mktemp("raw")
    res = run_simulation(SimConfig(preset="gallery", width=173, height=130, duration=0.6, frames=6,
                                   exposure=0.02, blur_samples=3, dvs_rate_hz=300.0, supersample=1,
                                   novel=0, seed=0))
    write_simulated_scene(res.scene, res.gt, root, stats=res.stats, overwrite=True)
    _strip_camera(root)
    return root


def test_deblur_estimates_camera_and_trajectory_first(raw_sim_scene, tmp_path, capsys):
    scene = load_scene(raw_sim_scene)
    assert needs_pose_stage(scene)
    out = tmp_path / "run"
    assert main(["deblur", str(raw_sim_scene), "-o", str(out), *TINY]) == 0
    assert "registered 6/6, failed: none" in capsys.readouterr().out
    doc = json.loads((out / "camera.json").read_text())
    assert doc["intrinsics"] == doc["trajectory"] == "estimated" and doc["report"]["registered"] == 6
    restored = read_pose_outputs(out, scene)  # what --resume uses
    assert restored.camera.fx == doc["camera"]["fx"] and not needs_pose_stage(restored)
    fs = scene.frames
    assert restored.poses.t[0] <= fs.t_start[0] and restored.poses.t[-1] >= fs.t_end[-1]
    assert (out / "deblurred" / f"{fs.names[0]}.png").is_file()


def test_calibrate_refine_poses_a_raw_recording_first_and_writes_nothing_beside_it(raw_sim_scene, tmp_path,
                                                                                   capsys):
    """``fusiongs calibrate --refine`` on a recording without trajectory or intrinsics goes through
    deblur's pose stage (in a temporary folder: the scene folder and the output's folder get
    nothing but the calibration)."""
    before = sorted(p.name for p in raw_sim_scene.rglob("*"))
    out = tmp_path / "cal"
    assert main(["calibrate", str(raw_sim_scene), "-o", str(out), "--refine", *TINY]) == 0
    captured = capsys.readouterr()
    assert "registered 6/6" in captured.err and "refined: the frames-only warm-up" in captured.out
    assert sorted(p.name for p in out.iterdir()) == ["calibration.json"]
    assert sorted(p.name for p in raw_sim_scene.rglob("*")) == before
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["thresholds"]["details"]["refine"]["iterations"] == 4


def test_a_given_trajectory_is_kept_when_only_the_intrinsics_are_estimated(raw_sim_scene):
    import dataclasses

    from fusiongs.camera.tum import PoseSamples

    scene = load_scene(raw_sim_scene)
    given = PoseSamples(t=np.array([0.0, 0.6]), c2w=np.tile(np.eye(4), (2, 1, 1)))
    scene = dataclasses.replace(scene, poses=given)
    assert needs_pose_stage(scene)
    result = estimate_scene_poses(scene)
    assert result.scene.poses is given and result.scene.camera.intrinsics_known
    assert result.estimate.report.focal_estimated


def test_frames_that_share_nothing_stop_with_exit_2(tmp_path, capsys):
    # (a camera that never moves is no longer an error: the pose stage returns a static path)
    rng = np.random.default_rng(0)
    doc = {"format": "fusiongs-scene", "version": 1, "camera": {"width": 64, "height": 48},
           "frames": [{"path": f"frames/{i}.png", "t_start": 0.1 * i, "t_end": 0.1 * i + 0.05}
                      for i in range(4)]}
    for f in doc["frames"]:
        write_png(tmp_path / f["path"], rng.uniform(0.1, 0.9, (48, 64, 1)))  # unrelated views
    (tmp_path / "scene.json").write_text(json.dumps(doc))
    assert main(["deblur", str(tmp_path), "-o", str(tmp_path / "run"), *TINY]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "trajectory" in err[0] and "registered" in err[0]


def test_real_recording_cut_registers_every_frame(tmp_path):
    src = real_data_dir() / "eslnet_cups"
    if not (src / "scene.json").is_file():
        pytest.skip(f"real recording eslnet_cups not found in {real_data_dir()}")
    scene = load_scene(cut_recording(src, tmp_path / "cut", 8))
    assert not scene.camera.intrinsics_known and scene.poses is None
    result = estimate_scene_poses(scene)
    r = result.estimate.report
    assert r.registered == 8 and r.failed == (), r
    assert 0.25 * 346 < result.scene.camera.fx < 4 * 346
    fs = scene.frames
    assert result.scene.poses.t[0] <= fs.t_start[0] and result.scene.poses.t[-1] >= fs.t_end[-1]
    assert np.isfinite(result.scene.poses.c2w).all()


@pytest.fixture(scope="module")
def raw_event_only_scene(tmp_path_factory):
    """A simulated event camera (no frames) moving through the gallery, without trajectory and
    intrinsics; returns the folder and the true poses."""
    from fusiongs.sim.simulate import SimConfig, run_simulation
    from fusiongs.sim.write import write_simulated_scene

    root = tmp_path_factory.mktemp("raw_events")
    res = run_simulation(SimConfig(preset="gallery", width=173, height=130, duration=0.6, frames=0,
                                   blur_samples=3, dvs_rate_hz=300.0, supersample=1, novel=1, seed=0))
    write_simulated_scene(res.scene, res.gt, root, stats=res.stats, overwrite=True)
    _strip_camera(root)
    return root, res.scene.poses


def _aligned_path_error(est, truth) -> tuple[float, float, float]:
    """``(position RMS, the true path's extent (max distance from its mean), rotation RMS °)`` of
    the estimated poses against the true ones nearest in time (the simulator samples every ms),
    after :func:`fusiongs.sfm.align.align_sim3`."""
    from fusiongs.sfm.align import pose_errors

    sel = (est.t >= truth.t[0]) & (est.t <= truth.t[-1])
    nearest = np.clip(np.searchsorted(truth.t, est.t[sel]), 0, len(truth.t) - 1)
    true_c2w = truth.c2w[nearest]
    pos, rot = pose_errors(est.c2w[sel], true_c2w)
    centres = true_c2w[:, :3, 3]
    extent = float(np.linalg.norm(centres - centres.mean(0), axis=1).max())
    return float(np.sqrt((pos ** 2).mean())), extent, float(np.sqrt((rot ** 2).mean()))


def test_an_event_only_recording_is_posed_from_images_of_its_events(raw_event_only_scene):
    root, truth = raw_event_only_scene
    scene = load_scene(root)
    assert len(scene.frames) == 0 and needs_pose_stage(scene)
    result = estimate_scene_poses(scene)
    r = result.estimate.report
    assert r.n_images == 16 and r.registered >= 12, r
    assert result.source.startswith("event images at 16 instants")
    t0, t1 = scene.events.t[0] * 1e-6, scene.events.t[-1] * 1e-6
    poses = result.scene.poses
    assert poses.t[0] <= t0 and poses.t[-1] >= t1 and np.isfinite(poses.c2w).all()
    ate, extent, rot = _aligned_path_error(poses, truth)
    assert ate < 0.05 * extent and rot < 3.0, (ate, extent, rot)  # measured 1.1 % and 1.5°: RESULTS


def test_deblur_poses_an_event_only_recording_first(raw_event_only_scene, tmp_path, capsys):
    root, _ = raw_event_only_scene
    out = tmp_path / "run"
    assert main(["deblur", str(root), "-o", str(out), "--config", "event_only", *TINY]) == 0
    assert "poses from event images at 16 instants" in capsys.readouterr().out
    doc = json.loads((out / "camera.json").read_text())
    assert doc["trajectory"] == "estimated" and doc["source"].startswith("event images")


def test_a_scene_with_one_frame_and_no_events_cannot_be_posed(raw_sim_scene):
    import dataclasses

    from fusiongs.errors import InputError
    from fusiongs.eval.holdout import frame_subset

    scene = load_scene(raw_sim_scene)
    scene = dataclasses.replace(scene, frames=frame_subset(scene.frames, np.array([0])), events=None)
    with pytest.raises(InputError, match="two frames or events"):
        estimate_scene_poses(scene)


def test_a_single_frame_is_posed_from_the_events_and_covered(raw_sim_scene):
    import dataclasses

    from fusiongs.eval.holdout import frame_subset

    scene = load_scene(raw_sim_scene)
    one = dataclasses.replace(scene, frames=frame_subset(scene.frames, np.array([2])))
    result = estimate_scene_poses(one)
    assert result.source.startswith("event images") and result.estimate.report.registered >= 3
    poses, fs = result.scene.poses, one.frames
    assert poses.t[0] <= min(fs.t_start[0], one.events.t[0] * 1e-6)
    assert poses.t[-1] >= max(fs.t_end[-1], one.events.t[-1] * 1e-6)


def test_event_images_that_do_not_register_are_named_as_events(raw_event_only_scene, monkeypatch):
    import fusiongs.pipeline.poses as stage
    from fusiongs.errors import InputError

    def refuse(*args, **kwargs):
        raise InputError("pose estimation", "frames", "at least 3 images registered", "1 of 16 registered")

    monkeypatch.setattr(stage, "estimate_camera_and_trajectory", refuse)
    with pytest.raises(InputError, match=r"pose estimation: events: .*\(the event images at 16 instants"):
        estimate_scene_poses(load_scene(raw_event_only_scene[0]))


def test_the_real_cups_events_alone_are_refused_not_misplaced():
    """eslnet_cups' events alone register about 3 of 16 images, on a path far from the one its
    frames give (RESULTS.md): the stage must stop with its one-line error, not go on."""
    import dataclasses

    from fusiongs.errors import InputError
    from fusiongs.eval.holdout import frame_subset

    src = real_data_dir() / "eslnet_cups"
    if not (src / "scene.json").is_file():
        pytest.skip(f"real recording eslnet_cups not found in {real_data_dir()}")
    scene = load_scene(src)
    events_only = dataclasses.replace(scene, frames=frame_subset(scene.frames, np.array([], dtype=int)))
    with pytest.raises(InputError, match=r"events: expected at least 8 images registered"):
        estimate_scene_poses(events_only)
