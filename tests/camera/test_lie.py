import numpy as np
import pytest
import torch

from fusiongs.camera.lie import (
    matrix_to_quat,
    quat_to_matrix,
    rigid_inverse,
    se3_exp,
    se3_log,
    so3_exp,
    so3_log,
)
from fusiongs.camera.tum import matrix_to_quat_xyzw, quat_xyzw_to_matrix

F64 = torch.float64


def _twists(generator, n=64, max_angle=3.0):
    rho = torch.randn(n, 3, dtype=F64, generator=generator)
    axis = torch.nn.functional.normalize(torch.randn(n, 3, dtype=F64, generator=generator), dim=-1)
    angle = torch.rand(n, 1, dtype=F64, generator=generator) * max_angle
    return torch.cat([rho, axis * angle], -1)


def test_se3_log_inverts_exp_for_angles_below_pi(generator):
    xi = _twists(generator)
    xi[:3, 3:] *= torch.tensor([0.0, 1e-5, 1e-9], dtype=F64)[:, None]  # identity and tiny angles
    assert torch.allclose(se3_log(se3_exp(xi)), xi, atol=1e-12)


def test_so3_log_is_accurate_near_180_degrees():
    axis = torch.nn.functional.normalize(torch.tensor([[1.0, 2.0, -0.5]], dtype=F64), dim=-1)
    for angle in (np.pi - 1e-3, np.pi - 1e-7):
        phi = so3_log(so3_exp(axis * angle))
        assert phi.norm().item() == pytest.approx(angle, abs=1e-7)
        assert torch.allclose(torch.nn.functional.normalize(phi, dim=-1).abs(), axis.abs(), atol=1e-6)


def test_exp_gives_rotation_and_rigid_inverse_is_inverse(generator):
    T = se3_exp(_twists(generator))
    R = T[:, :3, :3]
    eye = torch.eye(3, dtype=F64)
    assert torch.allclose(R @ R.transpose(-1, -2), eye.expand_as(R), atol=1e-12)
    assert torch.allclose(torch.linalg.det(R), torch.ones(R.shape[0], dtype=F64))
    assert torch.allclose(rigid_inverse(T) @ T, torch.eye(4, dtype=F64).expand_as(T), atol=1e-12)


def test_matrix_to_quat_matches_numpy_tum_helper_and_round_trips(rng):
    q_xyzw = rng.standard_normal((200, 4))
    q_xyzw /= np.linalg.norm(q_xyzw, axis=1, keepdims=True)
    R = quat_xyzw_to_matrix(q_xyzw)
    q_t = matrix_to_quat(torch.from_numpy(R)).numpy()  # wxyz, w >= 0
    q_np = matrix_to_quat_xyzw(R)
    assert np.allclose(q_t, q_np[:, [3, 0, 1, 2]], atol=1e-12)
    assert np.allclose(quat_to_matrix(torch.from_numpy(q_t)).numpy(), R, atol=1e-12)


@pytest.mark.parametrize("fn", [se3_exp, lambda x: se3_log(se3_exp(x)), so3_exp])
def test_lie_functions_pass_gradcheck_including_identity(fn, generator):
    xi = _twists(generator, n=4, max_angle=2.0)
    xi[0] = 0.0
    if fn is so3_exp:
        xi = xi[:, 3:]
    assert torch.autograd.gradcheck(fn, (xi.clone().requires_grad_(),), atol=1e-7)
