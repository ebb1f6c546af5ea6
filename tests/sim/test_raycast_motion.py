"""Ray caster (geometry, texture lookup, occlusion) and camera motion."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.tum import read_tum, write_tum
from fusiongs.sim.motion import Motion, make_trajectory, rotvec_to_matrix, scale_motion
from fusiongs.sim.raycast import Quad, RayCaster, World, box_quads
from fusiongs.sim.textures import solid_texture


def _camera(w=40, h=30, f=40.0):
    return PinholeCamera(w, h, f, f, w / 2, h / 2)


def test_fronto_parallel_plane_maps_texture_columns_linearly():
    # A horizontal ramp texture filling a plane at depth 2 that exactly covers the view.
    ramp = np.repeat(np.linspace(0, 1, 256, dtype=np.float32)[None, :, None], 8, 0).repeat(3, 2)
    cam = _camera()
    half_w, half_h = 2.0 * cam.cx / cam.fx, 2.0 * cam.cy / cam.fy
    quad = Quad((-half_w, -half_h, 2.0), (2 * half_w, 0, 0), (0, 2 * half_h, 0), 0)
    img = RayCaster(World((quad,), (ramp,)), cam, ss=1).render(np.eye(4))
    expected = (np.arange(cam.width) + 0.5) / cam.width  # pixel centre -> texture u
    assert torch.allclose(img[cam.height // 2, :, 0], torch.tensor(expected, dtype=torch.float32), atol=0.01)


def test_nearest_surface_occludes_and_misses_show_background():
    red, blue = solid_texture((1.0, 0.0, 0.0)), solid_texture((0.0, 0.0, 1.0))
    far = Quad((-10, -10, 5.0), (20, 0, 0), (0, 20, 0), 0)
    near = Quad((-0.2, -0.2, 1.0), (0.4, 0, 0), (0, 0.4, 0), 1, gain=0.5)
    cam = _camera()
    img = RayCaster(World((far, near), (red, blue)), cam, ss=2).render(np.eye(4))
    assert torch.allclose(img[15, 20], torch.tensor([0.0, 0.0, 0.5]))
    assert torch.allclose(img[2, 2], torch.tensor([1.0, 0.0, 0.0]))
    c2w = np.eye(4)
    c2w[:3, :3] = rotvec_to_matrix(np.array([0.0, np.pi, 0.0]))  # look backwards: nothing there
    back = RayCaster(World((far,), (red,), background=(0.1, 0.2, 0.3)), cam, ss=1).render(c2w)
    assert torch.allclose(back, torch.tensor([0.1, 0.2, 0.3]).expand_as(back))


def test_back_face_culling_of_boxes_does_not_change_the_image():
    tex = np.random.default_rng(0).random((16, 16, 3)).astype(np.float32)
    quads = tuple(box_quads((0.3, 0.2, 3.0), (1.0, 1.2, 0.8), 0))
    two_sided = tuple(Quad(q.origin, q.edge_u, q.edge_v, q.texture, q.crop, q.gain, False) for q in quads)
    c2w = np.eye(4)
    c2w[:3, :3] = rotvec_to_matrix(np.array([0.1, -0.2, 0.05]))
    a = RayCaster(World(quads, (tex,)), _camera(), ss=2).render(c2w)
    b = RayCaster(World(two_sided, (tex,)), _camera(), ss=2).render(c2w)
    assert torch.allclose(a, b, atol=1e-5)
    assert (a != 0.02).any()


def test_trajectory_poses_are_rigid_smooth_and_survive_tum_round_trip(tmp_path):
    traj = make_trajectory(Motion(), 0.5, np.random.default_rng(1))
    poses = traj.samples(1000.0)
    R = poses.c2w[:, :3, :3]
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(R), 1.0)
    step = np.linalg.norm(np.diff(poses.c2w[:, :3, 3], axis=0), axis=1)
    assert step.max() < 5e-3  # < 5 m/s at 1 kHz: no jumps
    write_tum(tmp_path / "t.txt", poses)
    back = read_tum(tmp_path / "t.txt")
    assert np.allclose(back.c2w, poses.c2w, atol=1e-7)


def test_shake_depends_on_the_seed():
    a = make_trajectory(Motion(), 1.0, np.random.default_rng(1)).c2w(np.array([0.3]))
    b = make_trajectory(Motion(), 1.0, np.random.default_rng(2)).c2w(np.array([0.3]))
    c = make_trajectory(Motion(), 1.0, np.random.default_rng(1)).c2w(np.array([0.3]))
    assert not np.allclose(a, b) and np.array_equal(a, c)


def test_scaled_motion_keeps_the_middle_pose_and_scales_the_velocity():
    m = Motion(target=(0.0, 0.0, 5.0), radius=(5.0, 4.0), azimuth_deg=(-10.0, 12.0), shake_pos=0.0,
               shake_rot_deg=0.0)
    assert scale_motion(m, 1.0, 1.0) is m
    base = make_trajectory(m, 1.0, np.random.default_rng(0))
    fast = make_trajectory(scale_motion(m, 1.5, 1.0), 1.0, np.random.default_rng(0))
    assert np.allclose(base.c2w(np.array([0.5])), fast.c2w(np.array([0.5])))
    v = lambda tr: np.linalg.norm(np.diff(tr.c2w(np.array([0.5, 0.5001]))[:, :3, 3], axis=0))
    assert v(fast) / v(base) == pytest.approx(1.5, rel=1e-3)
    shaky = scale_motion(Motion(), 0.5, 1.0)
    assert shaky.shake_pos == pytest.approx(0.002) and shaky.shake_rot_deg == pytest.approx(0.15)
