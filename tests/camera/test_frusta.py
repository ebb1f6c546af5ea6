import numpy as np
import pytest
import torch

from fusiongs.camera.frusta import sample_in_frusta
from fusiongs.camera.lie import rigid_inverse, se3_exp
from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError


def _setup():
    cam = PinholeCamera(64, 48, 50.0, 50.0, 32.0, 24.0)
    c2w = se3_exp(torch.tensor([[0.0, 0, 0, 0, 0, 0], [1.0, 0.2, -0.3, 0.1, 0.5, -0.2]]))
    return cam, c2w


def test_points_lie_inside_some_frustum_between_near_and_far():
    cam, c2w = _setup()
    pts = sample_in_frusta(cam, c2w, 2000, 0.5, 3.0, torch.Generator().manual_seed(0))
    assert pts.shape == (2000, 3) and pts.dtype == torch.float32
    w2c = rigid_inverse(c2w)
    p = (w2c[:, None, :3, :3] @ pts[None, :, :, None])[..., 0] + w2c[:, None, :3, 3]
    z = p[..., 2]
    u = cam.fx * p[..., 0] / z + cam.cx
    v = cam.fy * p[..., 1] / z + cam.cy
    eps = 1e-3
    inside = ((z >= 0.5 - eps) & (z <= 3.0 + eps) & (u >= -eps) & (u <= 64 + eps)
              & (v >= -eps) & (v <= 48 + eps))
    assert bool(inside.any(0).all())


def test_depth_is_volume_uniform_and_sampling_is_seeded():
    cam, c2w = _setup()
    a = sample_in_frusta(cam, c2w[:1], 20000, 1.0, 2.0, torch.Generator().manual_seed(3))
    b = sample_in_frusta(cam, c2w[:1], 20000, 1.0, 2.0, torch.Generator().manual_seed(3))
    assert torch.equal(a, b)
    z_half = ((1.0 + 8.0) / 2) ** (1 / 3)  # half of the frustum volume lies below this depth
    assert float((a[:, 2] < z_half).float().mean()) == pytest.approx(0.5, abs=0.015)


def test_bad_depth_range_raises():
    cam, c2w = _setup()
    with pytest.raises(InputError, match="near/far"):
        sample_in_frusta(cam, c2w, 10, 2.0, 1.0, torch.Generator())
    with pytest.raises(InputError, match="c2w"):
        sample_in_frusta(cam, np.eye(4), 10, 1.0, 2.0, torch.Generator())


@pytest.mark.parametrize("mode, median", [("depth", 2.5), ("disparity", 1.0 / ((1.0 + 0.25) / 2))])
def test_depth_and_disparity_sampling_have_their_medians(mode, median):
    cam, c2w = _setup()
    p = sample_in_frusta(cam, c2w[:1], 20000, 1.0, 4.0, torch.Generator().manual_seed(5), mode)
    assert float((p[:, 2] < median).float().mean()) == pytest.approx(0.5, abs=0.015)
    assert float(p[:, 2].min()) >= 1.0 - 1e-5 and float(p[:, 2].max()) <= 4.0 + 1e-5


def test_unknown_depth_sampling_raises():
    cam, c2w = _setup()
    with pytest.raises(InputError, match="depth_sampling"):
        sample_in_frusta(cam, c2w, 10, 1.0, 2.0, torch.Generator(), "log")
    with pytest.raises(InputError, match="near"):
        sample_in_frusta(cam, c2w, 10, 0.0, 2.0, torch.Generator(), "disparity")
