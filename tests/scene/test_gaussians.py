import math

import pytest
import torch

from fusiongs.camera.lie import se3_exp
from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError
from fusiongs.scene.gaussians import PARAM_NAMES, SH_C0, GaussianModel
from fusiongs.scene.knn import knn_distances, knn_distances_reference


def _grid(n=5, spacing=0.1):
    r = torch.arange(n, dtype=torch.float32) * spacing
    return torch.stack(torch.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)


def test_from_points_sets_scales_from_neighbour_distances_and_defaults():
    xyz = _grid()
    rgb = torch.rand(xyz.shape, generator=torch.Generator().manual_seed(0))
    m = GaussianModel.from_points(xyz, rgb, sh_degree=2)
    assert m.n == 125 and m.max_sh_degree == 2 and m.active_sh_degree == 0
    assert torch.allclose(m.scales, torch.full((125, 3), 0.1), atol=1e-6)  # 6-connected grid
    assert torch.allclose(m.opacities, torch.full((125,), 0.1))
    assert torch.equal(m.rotations, torch.tensor([[1.0, 0, 0, 0]]).expand(125, 4))
    assert torch.allclose(m.base_colors(), rgb, atol=1e-6)
    assert m.sh_coeffs().shape == (125, 9, 3)
    assert torch.allclose(m.sh_coeffs()[:, 0], (rgb - 0.5) / SH_C0)
    assert list(m.parameter_groups()) == list(PARAM_NAMES)
    assert all(p.requires_grad for p in m.parameter_groups().values())


def test_grow_sh_degree_stops_at_maximum():
    m = GaussianModel.from_points(_grid(2), sh_degree=1)
    assert [m.grow_sh_degree() for _ in range(3)] == [1, 1, 1]


def test_lone_point_and_duplicates_get_finite_scales():
    m = GaussianModel.from_points(torch.zeros(1, 3))
    assert torch.allclose(m.scales, torch.ones(1, 3))
    m = GaussianModel.from_points(torch.zeros(4, 3))
    assert torch.isfinite(m.log_scales).all()
    assert torch.allclose(m.scales, torch.full((4, 3), math.sqrt(1e-7)))


def test_kdtree_neighbour_distances_match_brute_force_reference(generator):
    xyz = torch.randn(700, 3, generator=generator, dtype=torch.float64)
    xyz[10] = xyz[11]  # a duplicate pair
    fast = knn_distances(xyz, 3)
    ref = knn_distances_reference(xyz, 3, max_elements=5000)  # several chunks
    assert torch.allclose(fast, ref, atol=1e-12)
    assert fast[10, 0] == 0 and fast[11, 0] == 0


@pytest.mark.parametrize("kwargs, field", [
    (dict(xyz=torch.zeros(4, 2)), "xyz"),
    (dict(xyz=torch.tensor([[0.0, float("nan"), 0.0]])), "xyz"),
    (dict(xyz=torch.zeros(2, 3), rgb=torch.full((2, 3), 2.0)), "rgb"),
    (dict(xyz=torch.zeros(2, 3), rgb=torch.zeros(3, 3)), "rgb"),
    (dict(xyz=torch.zeros(2, 3), sh_degree=4), "sh_degree"),
])
def test_bad_points_raise_input_error_naming_the_field(kwargs, field):
    with pytest.raises(InputError, match=field):
        GaussianModel.from_points(**kwargs)


def test_constructor_rejects_inconsistent_shapes():
    m = GaussianModel.empty(3, sh_degree=1)
    params = {k: v.detach() for k, v in m.parameter_groups().items()}
    with pytest.raises(InputError, match="shN"):
        GaussianModel(**{**params, "shN": torch.zeros(3, 2, 3)})
    with pytest.raises(InputError, match="quats"):
        GaussianModel(**{**params, "quats": torch.zeros(3, 3)})


def test_state_dict_round_trip_keeps_active_degree():
    m = GaussianModel.from_points(_grid(3), sh_degree=3)
    m.grow_sh_degree()
    other = GaussianModel.empty(m.n, sh_degree=3)
    other.load_state_dict(m.state_dict())
    assert other.active_sh_degree == 1
    assert torch.equal(other.means, m.means)


def test_random_in_frusta_builds_seeded_float32_model():
    cam = PinholeCamera(32, 24, 30.0, 30.0, 16.0, 12.0)
    c2w = se3_exp(torch.tensor([[0.0] * 6, [0.5, 0, 0, 0, 0.3, 0]], dtype=torch.float64))
    a = GaussianModel.random_in_frusta(cam, c2w, 300, 1.0, 4.0, torch.Generator().manual_seed(0), sh_degree=1)
    b = GaussianModel.random_in_frusta(cam, c2w, 300, 1.0, 4.0, torch.Generator().manual_seed(0), sh_degree=1)
    assert a.n == 300 and a.means.dtype == torch.float32
    assert torch.equal(a.means, b.means)
    assert torch.allclose(a.base_colors(), torch.full((300, 3), 0.5))
