"""A simulated scene whose trajectory is withheld gets it back from the pose stage
(within tolerances after a similarity alignment); the alignment and the no-parallax helpers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.sfm.align import align_sim3, chain_rotations, is_static, pair_rotation, pose_errors
from fusiongs.sfm.register import fill_poses

# The pose target of benchmarks/bench_poses.py, met by the tiny scene below too: measured position
# max 0.10 % of the extent and rotation max 0.28° (2-core CPU, 2026-11-23). Without enlarging the
# 173-pixel images for SIFT (PoseOptions.sfm_min_width=1, the stage before this test) the same
# scene gave 0.25 % and 0.57°, which fails here.
# Rotation: the registration's matches change with the EDI frames, so with the thresholds fixed at
# the truth the largest error is 0.43 deg and with thresholds 1-3 % off it ranged 0.30-0.74 deg
# (seed 4); the median over the frames stays near 0.4 deg. Bounds: median and largest.
POS_TOL_PCT, ROT_TOL_DEG, ROT_MAX_DEG = 1.0, 0.5, 0.8


def _rot(axis, deg: float) -> np.ndarray:
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(deg)
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k


def _arc(n: int = 8) -> np.ndarray:
    """Camera-to-world poses along a turning arc."""
    c2w = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        c2w[i, :3, :3] = _rot((0.1, 1, 0), -10 + 20 * i / (n - 1))
        c2w[i, :3, 3] = [np.sin(0.3 * i), 0.1 * np.cos(i), 0.05 * i * i]
    return c2w


def test_pose_errors_vanish_under_a_similarity_and_measure_a_perturbation():
    true = _arc()
    sim = np.eye(4)
    sim[:3, :3], sim[:3, 3] = _rot((1, 2, 3), 40.0), [5.0, -2.0, 1.0]
    est = sim @ true
    est[:, :3, 3] *= 0.3  # scale the path (a similarity: centres scale, orientations stay)
    pos, rot = pose_errors(est, true)
    assert pos.max() < 1e-9 and rot.max() < 1e-5
    bad = est.copy()
    bad[3, :3, :3] = bad[3, :3, :3] @ _rot((0, 0, 1), 2.0)  # one camera turned by 2° about its axis
    _, rot = pose_errors(bad, true)
    assert rot[3] == pytest.approx(2.0, abs=0.3) and np.delete(rot, 3).max() < 0.3


def test_alignment_rotation_is_determined_on_a_straight_path():
    true = _arc()
    true[:, :3, 3] = np.outer(np.arange(8.0), [1.0, 0.0, 0.0])  # collinear centres: a pan
    turn = _rot((1, 0, 0), 30.0)  # about the path itself: centres alone cannot see it
    est = true.copy()
    est[:, :3, :3] = turn.T @ true[:, :3, :3]
    est[:, :3, 3] = true[:, :3, 3] @ turn
    s, R, _ = align_sim3(est, true)
    np.testing.assert_allclose(R, turn, atol=1e-9)
    assert s == pytest.approx(1.0)
    with pytest.raises(InputError, match="poses"):
        align_sim3(est[:1], true[:1])


def test_pair_rotation_and_chain_recover_a_turning_camera_despite_a_moving_object(rng):
    K = np.array([[150.0, 0, 86.5], [0, 150.0, 65.0], [0, 0, 1]])
    rays = np.c_[rng.uniform(-0.5, 0.5, (200, 2)), np.ones(200)]
    c2w = [np.eye(3), _rot((0, 1, 0), 4.0), _rot((0.2, 1, 0.1), 9.0)]
    pix = [(rays @ R) @ K.T for R in c2w]  # camera i sees world ray d at R_i^T d
    pix = [p[:, :2] / p[:, 2:] for p in pix]
    moving = pix[1].copy()
    moving[:20] += 15.0  # a car crossing: 10 % of the matches move on their own
    links = {}
    for (i, j), pj in (((0, 1), moving), ((1, 2), pix[2])):
        R, res, kept = pair_rotation(pix[i] if i else pix[0], pj, K)
        links[(i, j)] = (R, float(kept))
        assert res < 1e-6 and kept >= 180
    linked, rots = chain_rotations(4, links)  # a fourth view without matches stays unlinked
    assert linked.tolist() == [True, True, True, False]
    for R_est, R_true in zip(rots[:3], c2w):
        assert np.degrees(np.arccos(np.clip((np.trace(R_est.T @ R_true) - 1) / 2, -1, 1))) < 1e-4


def test_pair_rotation_keeps_matches_whose_residuals_are_below_arccos_resolution(rng):
    """Residual angles of 6e-9 and 1.2e-8 rad: the median is measured and the trimmed pass keeps
    every match (3 x median covers them). An arccos of the rays' dot product has a floor of 1.5e-8
    near 1 and reads most of them as exactly 0: the median was 0, and which matches the 1e-9 floor
    kept turned on the rounding of each dot product (in CI: 141 of 200 exact matches kept
    in the test above)."""
    K = np.array([[150.0, 0, 86.5], [0, 150.0, 65.0], [0, 0, 1]])
    ri = np.c_[rng.uniform(-0.5, 0.5, (200, 2)), np.ones(200)]
    ri /= np.linalg.norm(ri, axis=1, keepdims=True)
    axis = np.cross(ri, rng.normal(size=(200, 3)))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = np.where(np.arange(200) < 120, 6e-9, 1.2e-8)[:, None]
    rj = ri * np.cos(angle) + np.cross(axis, ri) * np.sin(angle)  # each ray turned by its angle
    assert (np.clip(np.einsum("nk,nk->n", ri, rj), -1, 1)[:120] == 1.0).mean() > 0.5  # arccos: 0
    pix = [(r @ K.T)[:, :2] / (r @ K.T)[:, 2:] for r in (ri, rj)]
    _, res, kept = pair_rotation(pix[0], pix[1], K)
    assert kept == 200 and 1e-9 < res < 2e-8


def test_static_camera_is_told_from_the_match_shifts(rng):
    xy = rng.uniform(0, 100, (50, 2))
    still = {(0, 1): (xy, xy + 0.1), (1, 2): (xy, xy - 0.2), (0, 2): (xy[:3], xy[:3] + 9.0)}
    assert is_static(still, 0.5, 10)  # the 3-match pair is too small to count
    assert not is_static({**still, (0, 3): (xy, xy + 2.0)}, 0.5, 10)
    assert not is_static({}, 0.5, 10)


@pytest.fixture(scope="module")
def sim_scene(tmp_path_factory):
    """A small simulated recording (boxes, 173x130, 6 blurry frames and events) with its truth."""
    from fusiongs.sim.simulate import SimConfig, run_simulation
    from fusiongs.sim.write import write_simulated_scene

    root = tmp_path_factory.mktemp("withheld") / "scene"
    res = run_simulation(SimConfig(preset="boxes", width=173, height=130, duration=0.6, frames=6,
                                   exposure=0.03, blur_samples=4, dvs_rate_hz=300.0, supersample=1,
                                   novel=0, seed=4))
    write_simulated_scene(res.scene, res.gt, root, stats=res.stats, overwrite=True)
    return root, res.scene


def test_pose_stage_recovers_a_withheld_trajectory(sim_scene, tmp_path):
    from benchmarks.bench_poses import scene_extent, withheld_copy
    from fusiongs.camera.tum import read_tum
    from fusiongs.io import load_scene
    from fusiongs.pipeline.deblur import resolve_config
    from fusiongs.pipeline.poses import run_pose_stage

    src, truth = sim_scene
    held = withheld_copy(src, tmp_path / "held")
    assert "trajectory" not in json.loads((held / "scene.json").read_text())
    scene = load_scene(held)
    assert scene.poses is None
    out = tmp_path / "out"
    out.mkdir()
    run_pose_stage(scene, resolve_config("deblur_fast", []), out, log=lambda *_: None)
    report = json.loads((out / "camera.json").read_text())["report"]
    assert report["registered"] == 6 and report["motion"] == "general"
    mids = truth.frames.mid_times()
    every = np.ones(len(truth.poses.t), bool)
    true = fill_poses(truth.poses.t, every, truth.poses.c2w, mids)
    est_samples = read_tum(out / "trajectory_initial.txt")
    est = fill_poses(est_samples.t, np.ones(len(est_samples.t), bool), est_samples.c2w, mids)
    extent, how = scene_extent(src, true)
    assert how.startswith("bounding box") and extent > 5.0
    pos, rot = pose_errors(est, true)
    assert 100 * pos.max() / extent < POS_TOL_PCT, 100 * pos / extent
    assert np.median(rot) < ROT_TOL_DEG and rot.max() < ROT_MAX_DEG, rot


def test_a_camera_that_only_turns_gets_its_rotations_without_translation():
    """Pure rotation (views of a photo at infinity): structure from motion cannot start, the
    no-parallax fallback chains the pairwise rotations."""
    import cv2

    from fusiongs.camera.pinhole import PinholeCamera
    from fusiongs.sfm.options import PoseOptions
    from fusiongs.sfm.register import estimate_camera_and_trajectory
    from fusiongs.sim.textures import load_photo

    photo = load_photo("astronaut").mean(axis=-1)  # 512x512 linear
    cam = PinholeCamera(173, 130, 150.0, 150.0, 86.5, 65.0)
    K, K_photo = cam.K().double().numpy(), np.array([[400.0, 0, 256], [0, 400.0, 256], [0, 0, 1]])
    turns = [_rot((0.1, 1, 0.05), -6 + 2.4 * i) for i in range(6)]  # camera-to-world rotations
    images = np.stack([cv2.warpPerspective(photo, K_photo @ R @ np.linalg.inv(K), (173, 130),
                                           flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)[..., None]
                       for R in turns]).astype(np.float32)
    times = np.arange(6) * 0.1
    est = estimate_camera_and_trajectory(cam, images, times, options=PoseOptions(no_parallax=True))
    r = est.report
    assert r.motion == "rotation" and r.registered == 6 and r.n_points == 0
    assert np.abs(est.poses.c2w[:, :3, 3]).max() == 0.0
    rel = np.einsum("ji,njk->nik", turns[0], np.stack(turns))  # the truth relative to the first view
    err = np.einsum("nji,njk->nik", rel, est.poses.c2w[:, :3, :3])
    deg = np.degrees(np.arccos(np.clip((np.trace(err, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert deg.max() < 0.3, deg  # measured 0.10 (chained over 5 pairs)
