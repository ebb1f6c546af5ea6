import numpy as np
import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.frames.response import linear_to_srgb
from fusiongs.render.sh import eval_sh
from fusiongs.scene.gaussians import PARAM_NAMES, SH_C0, GaussianModel
from fusiongs.scene.ply import display_sh, load_ply, save_ply

COLOURS = ("sh0", "shN")  # stored through the sRGB encoding (module docstring): equal up to rounding


def _random_model(n: int, degree: int, seed: int = 0) -> GaussianModel:
    g = torch.Generator().manual_seed(seed)
    k = (degree + 1) ** 2
    return GaussianModel(torch.randn(n, 3, generator=g), torch.randn(n, 3, generator=g),
                         torch.randn(n, 4, generator=g), torch.randn(n, generator=g),
                         torch.randn(n, 1, 3, generator=g), torch.randn(n, k - 1, 3, generator=g))


def _read_vertices(path):
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode().splitlines()
    names = [line.split()[2] for line in header if line.startswith("property")]
    return header, names, np.frombuffer(raw[end:], dtype=[(nm, "<f4") for nm in names])


@pytest.mark.parametrize("degree", [0, 1, 3])
def test_round_trip_preserves_every_parameter(tmp_path, degree):
    m = _random_model(50, degree)
    save_ply(m, tmp_path / "g.ply")
    back = load_ply(tmp_path / "g.ply")
    assert back.max_sh_degree == degree and back.active_sh_degree == degree
    for name in PARAM_NAMES:
        if name in COLOURS:  # float32 file values through S and S^-1: a few ulp, not bit-exact
            torch.testing.assert_close(getattr(back, name), getattr(m, name), atol=1e-6, rtol=1e-6)
        else:
            assert torch.equal(getattr(back, name), getattr(m, name)), name
    assert [p.name for p in tmp_path.iterdir()] == ["g.ply"]  # no temporary file left


def test_layout_is_inria_with_channel_major_f_rest(tmp_path):
    m = _random_model(7, 2)
    save_ply(m, tmp_path / "g.ply")
    header, names, rec = _read_vertices(tmp_path / "g.ply")
    assert header[1] == "format binary_little_endian 1.0" and "element vertex 7" in header
    rest = [f"f_rest_{i}" for i in range(24)]
    assert names == (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + rest
                     + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
    f_dc, f_rest = display_sh(m.sh0, m.shN)  # [N, 3], [N, 8, 3]: display-space coefficients
    sh = f_rest.float().numpy()
    for c in range(3):
        assert np.array_equal(rec[f"f_dc_{c}"], f_dc[:, c].float().numpy())
        for j in range(8):
            assert np.array_equal(rec[f"f_rest_{c * 8 + j}"], sh[:, j, c])
    assert np.array_equal(rec["rot_0"], m.quats.detach().numpy()[:, 0])  # w first
    assert np.array_equal(rec["opacity"], m.opacity_logits.detach().numpy())
    assert np.all(rec["nx"] == 0)


def test_overwrites_existing_file(tmp_path):
    save_ply(_random_model(5, 0, seed=1), tmp_path / "g.ply")
    m = _random_model(9, 1, seed=2)
    save_ply(m, tmp_path / "g.ply")
    assert load_ply(tmp_path / "g.ply").n == 9


def _write_custom(path, props, n=2, fmt="binary_little_endian 1.0"):
    header = f"ply\nformat {fmt}\nelement vertex {n}\n"
    header += "".join(f"property double {p}\n" for p in props) + "end_header\n"
    path.write_bytes(header.encode() + np.arange(n * len(props), dtype="<f8").tobytes())


def test_reads_other_order_and_types_without_normals(tmp_path):
    props = ["rot_0", "rot_1", "rot_2", "rot_3", "scale_0", "scale_1", "scale_2", "opacity",
             "f_dc_0", "f_dc_1", "f_dc_2", "z", "y", "x"]
    _write_custom(tmp_path / "o.ply", props)
    m = load_ply(tmp_path / "o.ply")
    assert m.max_sh_degree == 0 and m.n == 2
    assert torch.equal(m.means[0], torch.tensor([13.0, 12.0, 11.0]))


def test_missing_property_names_file_and_property(tmp_path):
    props = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
             "rot_0", "rot_1", "rot_2", "rot_3"]
    _write_custom(tmp_path / "bad.ply", props)
    with pytest.raises(InputError, match=r"bad\.ply: property scale_2"):
        load_ply(tmp_path / "bad.ply")


def test_bad_format_truncation_and_sh_count_raise(tmp_path):
    base = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
            "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    _write_custom(tmp_path / "a.ply", base, fmt="ascii 1.0")
    with pytest.raises(InputError, match="binary_little_endian"):
        load_ply(tmp_path / "a.ply")
    _write_custom(tmp_path / "s.ply", base + ["f_rest_0", "f_rest_1"])
    with pytest.raises(InputError, match="f_rest"):
        load_ply(tmp_path / "s.ply")
    save_ply(_random_model(4, 0), tmp_path / "t.ply")
    (tmp_path / "t.ply").write_bytes((tmp_path / "t.ply").read_bytes()[:-8])
    with pytest.raises(InputError, match="element vertex"):
        load_ply(tmp_path / "t.ply")
    (tmp_path / "n.ply").write_bytes(b"not a ply")
    with pytest.raises(InputError, match="header"):
        load_ply(tmp_path / "n.ply")


def _toy_model(linear_rgb, opacity, shN=None) -> GaussianModel:
    """Gaussians of the given linear colours ``[N, 3]`` and opacities ``[N]``."""
    rgb = torch.as_tensor(linear_rgb, dtype=torch.float32)
    n = rgb.shape[0]
    op = torch.as_tensor(opacity, dtype=torch.float32)
    shN = torch.zeros(n, 0, 3) if shN is None else shN
    return GaussianModel(torch.randn(n, 3), torch.zeros(n, 3), torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                         torch.log(op / (1 - op)), ((rgb - 0.5) / SH_C0)[:, None, :], shN)


def _viewer_colours(path):
    """What a 3DGS viewer shows as base colour, ``clip(SH_C0 f_dc + 0.5, 0, 1)``, and opacities."""
    _, _, rec = _read_vertices(path)
    f_dc = np.stack([rec[f"f_dc_{c}"] for c in range(3)], 1).astype(np.float64)
    return np.clip(SH_C0 * f_dc + 0.5, 0, 1), 1 / (1 + np.exp(-rec["opacity"].astype(np.float64)))


def test_viewer_mean_colour_is_the_srgb_of_the_mean_linear_colour(tmp_path):
    """A uniformly coloured toy scene (mid grey 0.18 linear is 0.46 displayed) with varied
    opacities: the opacity-weighted mean display colour a viewer shows is sRGB(mean linear)."""
    n = 40
    linear = np.tile([0.02, 0.18, 0.75], (n, 1))
    opacity = np.linspace(0.05, 0.95, n)
    save_ply(_toy_model(linear, opacity), tmp_path / "g.ply")
    shown, alpha = _viewer_colours(tmp_path / "g.ply")
    mean_shown = (alpha[:, None] * shown).sum(0) / alpha.sum()
    mean_linear = (opacity[:, None] * linear).sum(0) / opacity.sum()
    np.testing.assert_allclose(mean_shown, linear_to_srgb(mean_linear), atol=2e-6)
    assert mean_shown[1] > 0.45  # not the linear 0.18 the old convention showed (too dark)


def test_every_gaussian_shows_its_rendered_display_colour_also_out_of_range(tmp_path):
    linear = np.array([[0.0, 0.001, 0.0031308], [0.01, 0.5, 1.0], [-0.3, 1.7, 0.2], [0.9, 0.04, 5.0]])
    save_ply(_toy_model(linear, np.full(4, 0.5)), tmp_path / "g.ply")
    shown, _ = _viewer_colours(tmp_path / "g.ply")
    np.testing.assert_allclose(shown, linear_to_srgb(np.clip(linear, 0, 1)), atol=2e-6)
    back = load_ply(tmp_path / "g.ply").base_colors().detach().double().numpy()
    np.testing.assert_allclose(back, linear, atol=2e-6)  # out-of-range colours come back too


def test_view_dependent_display_colour_matches_to_first_order(tmp_path):
    """A viewer adds the f_rest terms in display space: scaled by the sRGB slope at the base colour
    they give the sRGB of the linear colour fusiongs renders, up to second-order terms; unscaled
    they would be off by (slope - 1) times the view-dependent part."""
    g = torch.Generator().manual_seed(3)
    n, eps = 200, 1e-3
    linear = torch.rand(n, 3, generator=g) * 0.8 + 0.05
    m = _toy_model(linear, torch.full((n,), 0.5), eps * torch.randn(n, 15, 3, generator=g))
    save_ply(m, tmp_path / "g.ply")
    _, _, rec = _read_vertices(tmp_path / "g.ply")
    f_dc = torch.from_numpy(np.stack([rec[f"f_dc_{c}"] for c in range(3)], 1)).double()
    f_rest = torch.from_numpy(np.stack([rec[f"f_rest_{i}"] for i in range(45)], 1)).double()
    f_rest = f_rest.reshape(n, 3, 15).transpose(1, 2)  # channel-major in the file
    dirs = torch.randn(n, 3, generator=g).double()
    shown = eval_sh(3, dirs, torch.cat([f_dc[:, None], f_rest], 1)) + 0.5  # what a viewer shows
    expected = linear_to_srgb(eval_sh(3, dirs, m.sh_coeffs().double()) + 0.5)
    view = eval_sh(3, dirs, torch.cat([torch.zeros(n, 1, 3).double(), m.shN.double()], 1))
    unscaled = linear_to_srgb(linear.double()) + view  # f_rest written as the linear bands
    err, err_unscaled = (shown - expected).abs().max(), (unscaled - expected).abs().max()
    assert err < 1e-4 and err < 0.05 * err_unscaled, (err, err_unscaled)
