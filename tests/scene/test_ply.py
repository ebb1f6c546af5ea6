import numpy as np
import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.scene.gaussians import PARAM_NAMES, GaussianModel
from fusiongs.scene.ply import load_ply, save_ply


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
    sh = m.shN.detach().numpy()  # [N, 8, 3]
    for c in range(3):
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
