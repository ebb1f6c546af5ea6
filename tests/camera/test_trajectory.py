import numpy as np
import pytest
import torch
from torch.func import functional_call

from fusiongs.camera.lie import rigid_inverse, se3_exp, se3_log, so3_log
from fusiongs.camera.trajectory import Trajectory
from fusiongs.camera.tum import PoseSamples, quat_xyzw_to_matrix, read_tum, write_tum
from fusiongs.errors import InputError

F64 = torch.float64


def _smooth_motion(t: torch.Tensor) -> torch.Tensor:
    xi = torch.stack([0.3 * torch.sin(t), 0.2 * t, 0.1 * torch.cos(2 * t),
                      0.5 * torch.sin(t), 0.3 * t, 0.2 * torch.cos(t)], -1)
    return se3_exp(xi)


def _samples(n=41, t1=2.0, t0=0.0) -> PoseSamples:
    t = np.linspace(t0, t1, n)
    return PoseSamples(t=t, c2w=_smooth_motion(torch.from_numpy(t)).numpy())


def _pose_error(a: torch.Tensor, b: torch.Tensor) -> float:
    return se3_log(rigid_inverse(a) @ b).abs().max().item()


def test_linear_reproduces_sample_poses_exactly():
    s = _samples()
    traj = Trajectory(s, "linear", out_dtype=F64)
    assert _pose_error(traj.c2w(torch.from_numpy(s.t)), torch.from_numpy(s.c2w)) < 1e-12


def test_linear_midpoint_of_screw_motion_halves_the_rotation():
    phi = torch.tensor([0.4, -1.1, 0.7], dtype=F64)
    T1 = se3_exp(torch.cat([torch.tensor([1.0, 2.0, 3.0], dtype=F64), phi]))
    s = PoseSamples(t=np.array([10.0, 11.0]), c2w=np.stack([np.eye(4), T1.numpy()]))
    traj = Trajectory(s, "linear", out_dtype=F64)
    mid = traj.c2w(torch.tensor([10.5, 10.25], dtype=F64))
    assert torch.allclose(so3_log(mid[:, :3, :3]), torch.stack([phi / 2, phi / 4]), atol=1e-12)
    assert torch.allclose(mid[0, :3, 3], T1[:3, 3] / 2, atol=1e-12)


@pytest.mark.parametrize("mode", ["linear", "spline"])
def test_view_matrix_is_inverse_of_c2w(mode):
    traj = Trajectory(_samples(), mode, out_dtype=F64, fit_iters=3)
    t = torch.linspace(0, 2, 17, dtype=F64)
    eye = torch.eye(4, dtype=F64).expand(17, 4, 4)
    assert torch.allclose(traj.w2c(t) @ traj.c2w(t), eye, atol=1e-12)
    assert traj.forward(t).shape == (17, 4, 4)


def test_spline_follows_smooth_motion_at_and_between_samples():
    s = _samples()
    traj = Trajectory(s, "spline", out_dtype=F64)
    assert torch.allclose(traj.knot_t[1:-1], torch.from_numpy(s.t))  # knots = uniform samples
    assert _pose_error(traj.c2w(torch.from_numpy(s.t)), torch.from_numpy(s.c2w)) < 1e-6
    dense = torch.linspace(0, 2, 401, dtype=F64)
    assert _pose_error(traj.c2w(dense), _smooth_motion(dense)) < 1e-5


def test_spline_with_coarser_knots_smooths_within_tolerance():
    traj = Trajectory(_samples(81), "spline", knot_spacing=0.2, out_dtype=F64, fit_iters=20)
    assert traj.knots.shape[0] == 10 + 3
    dense = torch.linspace(0, 2, 101, dtype=F64)
    assert _pose_error(traj.c2w(dense), _smooth_motion(dense)) < 1e-3


@pytest.mark.parametrize("mode", ["linear", "spline"])
def test_gradients_reach_refinement_deltas(mode):
    traj = Trajectory(_samples(6, t1=1.0), mode, refine=True, out_dtype=F64, fit_iters=10)
    assert torch.count_nonzero(traj.delta) == 0
    t = torch.tensor([0.05, 0.33, 0.5, 0.91], dtype=F64)
    delta = (0.01 * torch.randn(traj.delta.shape, dtype=F64,
                                generator=torch.Generator().manual_seed(1))).requires_grad_()
    assert torch.autograd.gradcheck(lambda d: functional_call(traj, {"delta": d}, (t,)), (delta,))
    traj.w2c(t).square().sum().backward()
    assert traj.delta.grad is not None and traj.delta.grad.abs().sum() > 0


def test_quaternion_sign_flips_between_samples_take_the_short_way(tmp_path):
    # Two nearly equal orientations written with opposite quaternion signs.
    q0 = np.array([0.0, 0.0, np.sin(0.05), np.cos(0.05)])
    q1 = -np.array([0.0, 0.0, np.sin(0.06), np.cos(0.06)])
    path = tmp_path / "traj.txt"
    path.write_text(f"0 0 0 0 {' '.join(map(str, q0))}\n1 0 0 0 {' '.join(map(str, q1))}\n")
    traj = Trajectory(read_tum(path), "linear", out_dtype=F64)
    angle = so3_log(traj.c2w(torch.tensor([0.5], dtype=F64))[:, :3, :3]).norm().item()
    assert angle == pytest.approx(0.11, abs=1e-9)  # halfway between 0.1 and 0.12 rad
    assert np.allclose(quat_xyzw_to_matrix(q1), traj.c2w(torch.tensor([1.0], dtype=F64))[0, :3, :3])


def test_instants_outside_range_raise_or_clamp():
    s = _samples(t0=5.0, t1=7.0)
    traj = Trajectory(s, "spline", fit_iters=5)
    assert (traj.t_min, traj.t_max) == (5.0, 7.0)
    with pytest.raises(InputError, match="within"):
        traj.w2c(torch.tensor([5.5, 7.01], dtype=F64))
    clamped = Trajectory(s, "linear", outside="clamp", out_dtype=F64)
    out = clamped.c2w(torch.tensor([4.0, 9.0], dtype=F64))
    assert torch.allclose(out, torch.from_numpy(s.c2w[[0, -1]]), atol=1e-12)


def test_bad_arguments_raise_input_error():
    s = _samples()
    with pytest.raises(InputError, match="mode"):
        Trajectory(s, "cubic")
    with pytest.raises(InputError, match="knot_spacing"):
        Trajectory(s, "spline", knot_spacing=-1.0)
    with pytest.raises(InputError, match="samples"):
        Trajectory(PoseSamples(s.t[:1], s.c2w[:1]), "spline")


def test_float32_output_and_pose_samples_round_trip(tmp_path):
    s = _samples(t0=1.7e9, t1=1.7e9 + 2.0)  # large unix times stay exact in float64
    traj = Trajectory(s, "linear")
    assert traj.w2c(torch.from_numpy(s.t[:3])).dtype == torch.float32
    write_tum(tmp_path / "out.txt", traj.as_pose_samples())
    back = read_tum(tmp_path / "out.txt")
    assert np.allclose(back.t, s.t) and np.allclose(back.c2w, s.c2w, atol=1e-8)
