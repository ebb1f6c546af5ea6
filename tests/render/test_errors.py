"""Bad rasterize input raises InputError naming the argument and the expected shape."""

from __future__ import annotations

import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.render import rasterize
from fusiongs.render.gsplat_backend import gsplat_available
from tests.render.scenes import make_scene

ARGS = ("means", "quats", "scales", "opacities", "colors", "viewmats", "Ks")


def _call(**over):
    scene = make_scene(n=6, n_cams=2)
    kw = {k: over.pop(k, scene[k]) for k in ARGS}
    w, h = over.pop("width", scene["width"]), over.pop("height", scene["height"])
    return rasterize(*[kw[k] for k in ARGS], w, h, **over)


@pytest.mark.parametrize(("over", "field", "expected"), [
    (dict(means=torch.zeros(6, 2, dtype=torch.float64)), "means", "[N, 3]"),
    (dict(quats=torch.ones(5, 4, dtype=torch.float64)), "quats", "[N, 4]"),
    (dict(scales=torch.ones(6, dtype=torch.float64)), "scales", "[N, 3]"),
    (dict(opacities=torch.ones(7, dtype=torch.float64)), "opacities", "[N]"),
    (dict(colors=torch.ones(5, 3, dtype=torch.float64)), "colors", "[N, D]"),
    (dict(viewmats=torch.eye(4, dtype=torch.float64)), "viewmats", "[C, 4, 4]"),
    (dict(Ks=torch.eye(3, dtype=torch.float64)[None]), "Ks", "[C, 3, 3]"),
    (dict(width=0), "width", "positive integer"),
    (dict(height=-3), "height", "positive integer"),
    (dict(backgrounds=torch.zeros(2, 4, dtype=torch.float64)), "backgrounds", "[C, D]"),
    (dict(sh_degree=4), "sh_degree", "0..3"),
    (dict(sh_degree=2), "colors", "K >= 9"),
    (dict(backend="opengl"), "backend", "one of"),
    (dict(opacities=torch.full((6,), 2.0, dtype=torch.float64)), "opacities", "[0, 1]"),
    (dict(quats=torch.zeros(6, 4, dtype=torch.float64)), "quats", "non-zero"),
    (dict(means=torch.zeros(6, 3, dtype=torch.float32)), "quats", "dtype torch.float32"),
    (dict(near_plane=2.0, far_plane=1.0), "near_plane/far_plane", "near_plane < far_plane"),
])
def test_bad_input_names_argument_and_expectation(over, field, expected):
    with pytest.raises(InputError) as err:
        _call(**over)
    assert err.value.where == "rasterize" and err.value.field == field
    assert expected in err.value.expected


@pytest.mark.parametrize("name", ["means", "scales", "colors", "viewmats", "Ks"])
def test_non_finite_values_are_rejected(name):
    scene = make_scene(n=6, n_cams=2)
    bad = scene[name].clone()
    bad.view(-1)[0] = float("nan")
    with pytest.raises(InputError, match=f"{name}: expected finite values"):
        _call(**{name: bad})


def test_gsplat_backend_refuses_cpu_tensors():
    with pytest.raises(InputError, match="backend"):
        _call(backend="gsplat")


def test_gsplat_is_not_needed_on_cpu():
    _, _, meta = _call()
    assert meta.backend == "cpu"
    assert isinstance(gsplat_available(), bool)
