"""Camera and trajectory from sharp images (pycolmap) on a simulated scene with the truth withheld."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.camera.pinhole import UncalibratedCamera
from fusiongs.errors import InputError
from fusiongs.sfm.align import umeyama
from fusiongs.sfm.register import estimate_camera_and_trajectory, fill_poses


@pytest.fixture(scope="module")
def sharp_views():
    """Ten sharp mid-exposure views of the textured ``gallery`` preset and the true poses there."""
    from fusiongs.frames.response import srgb_to_linear
    from fusiongs.sim.simulate import SimConfig, run_simulation

    res = run_simulation(SimConfig(preset="gallery", width=173, height=130, duration=1.0, frames=10,
                                   exposure=0.02, blur_samples=1, dvs_rate_hz=4.0, supersample=1,
                                   novel=0, seed=0))
    fs, p = res.scene.frames, res.scene.poses
    images = np.stack([srgb_to_linear(res.gt[f"deblur_{n}"]) for n in fs.names]).astype(np.float32)
    true = np.stack([p.c2w[np.argmin(np.abs(p.t - t))] for t in fs.mid_times()])
    return res.scene.camera, images, fs.mid_times(), list(fs.names), true


def _angles_deg(R: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))


def _errors(est_c2w: np.ndarray, true: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Position errors after a similarity alignment, rotation errors relative to the first view
    (alignment-free), and the true path length."""
    s, R, t = umeyama(est_c2w[:, :3, 3], true[:, :3, 3])
    pos = np.linalg.norm(s * est_c2w[:, :3, 3] @ R.T + t - true[:, :3, 3], axis=1)
    rel_e = np.einsum("ji,njk->nik", est_c2w[0, :3, :3], est_c2w[:, :3, :3])
    rel_t = np.einsum("ji,njk->nik", true[0, :3, :3], true[:, :3, :3])
    rot = _angles_deg(np.einsum("nij,nkj->nik", rel_e, rel_t))
    return pos, rot, float(np.linalg.norm(np.diff(true[:, :3, 3], axis=0), axis=1).sum())


def test_unknown_camera_gives_the_path_the_rotations_and_the_focal_length(sharp_views):
    cam, images, times, names, true = sharp_views
    t_range = (times[0] - 0.01, times[-1] + 0.01)
    est = estimate_camera_and_trajectory(UncalibratedCamera(cam.width, cam.height), images, times, names,
                                         t_range=t_range)
    r = est.report
    assert r.registered == 10 and r.failed == () and r.focal_estimated and r.focal_observable
    assert est.camera.fx == pytest.approx(cam.fx, rel=0.1)
    assert (est.camera.cx, est.camera.cy) == (cam.width / 2, cam.height / 2)
    assert est.poses.t[0] == t_range[0] and est.poses.t[-1] == t_range[1]  # covers the exposures
    inner = est.poses.c2w[1:-1]
    np.testing.assert_allclose(inner[0], np.eye(4), atol=1e-9)  # first view at the origin
    pos, rot, path = _errors(inner, true)
    assert pos.max() < 0.02 * path, (est.camera.fx, pos.max() / path)
    assert rot.max() < 1.5, (est.camera.fx, rot)
    assert len(est.points) == r.n_points > 50


def test_given_camera_is_held_and_failed_images_are_interpolated(sharp_views):
    cam, images, times, names, true = sharp_views
    images = images.copy()
    images[4] = images[4].mean()  # a featureless view cannot register
    est = estimate_camera_and_trajectory(cam, images, times, names)
    r = est.report
    assert est.camera == cam and not r.focal_estimated and r.focal_observable is None
    assert r.failed == (names[4],) and r.registered == 9
    pos, rot, path = _errors(est.poses.c2w, true)  # view 4 interpolated between 3 and 5
    assert pos.max() < 0.03 * path
    assert rot.max() < 1.5


def test_images_without_parallax_raise_one_line_naming_the_alternatives(sharp_views):
    cam, images, times, names, _ = sharp_views
    noise = np.random.default_rng(0).normal(0.0, 1e-3, (4,) + images.shape[1:])
    static = (images[:1] + noise).astype(np.float32)  # a camera that does not move
    with pytest.raises(InputError) as e:
        estimate_camera_and_trajectory(UncalibratedCamera(cam.width, cam.height), static, times[:4])
    msg = str(e.value)
    assert "\n" not in msg and "trajectory" in msg and "intrinsics" in msg and "of 4 registered" in msg


def _turning(t: np.ndarray) -> np.ndarray:
    """Camera-to-world poses turning at 0.1 rad/s about y and moving at 0.5 m/s along x."""
    c2w = np.tile(np.eye(4), (len(t), 1, 1))
    c, s = np.cos(0.1 * t), np.sin(0.1 * t)
    c2w[:, 0, 0], c2w[:, 0, 2], c2w[:, 2, 0], c2w[:, 2, 2] = c, s, -s, c
    c2w[:, 0, 3] = 0.5 * t
    return c2w


def test_fill_poses_interpolates_gaps_and_extrapolates_the_ends():
    t = np.arange(6, dtype=np.float64)
    known = np.array([True, True, False, True, True, False])
    c2w = np.where(known[:, None, None], _turning(t), np.nan)
    t_out = np.array([-1.0, 2.0, 5.0, 6.0])
    np.testing.assert_allclose(fill_poses(t, known, c2w, t_out), _turning(t_out), atol=1e-9)


def test_wrong_image_shapes_are_named():
    with pytest.raises(InputError, match="images"):
        estimate_camera_and_trajectory(UncalibratedCamera(8, 6), np.zeros((3, 6, 9, 1)), np.arange(3.0))
    with pytest.raises(InputError, match="times"):
        estimate_camera_and_trajectory(UncalibratedCamera(8, 6), np.zeros((3, 6, 8, 1)), np.zeros(3))
