"""Transfer curves: exact IEC 61966-2-1 sRGB (checked against colour-science), gamma, names."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.frames.response import (
    linear_to_gamma,
    linear_to_response,
    linear_to_srgb,
    parse_response,
    response_to_linear,
    srgb_to_linear,
)

V = np.concatenate([np.linspace(0, 1, 2001), [0.04045, 0.0031308, 0.04045 + 1e-9]])


def test_srgb_matches_colour_science():
    import colour

    # The two sRGB segments meet only to ~1e-9; at the exact break points the standard's "<="
    # picks the linear segment, where colour-science may pick the other one.
    off = ~np.isin(V, [0.04045, 0.0031308])
    np.testing.assert_allclose(srgb_to_linear(V)[off], colour.models.eotf_sRGB(V)[off], rtol=1e-12,
                               atol=1e-15)
    np.testing.assert_allclose(linear_to_srgb(V)[off], colour.models.eotf_inverse_sRGB(V)[off],
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(srgb_to_linear(V), colour.models.eotf_sRGB(V), atol=1e-8)
    np.testing.assert_allclose(linear_to_srgb(V), colour.models.eotf_inverse_sRGB(V), atol=1e-7)


def test_srgb_constants_and_round_trip():
    assert srgb_to_linear(np.float64(0.04045)) == pytest.approx(0.04045 / 12.92)
    assert linear_to_srgb(np.float64(1.0)) == pytest.approx(1.0)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(V)), V, atol=1e-7)  # break-point gap
    assert srgb_to_linear(np.zeros(3, np.float32)).dtype == np.float32


def test_torch_versions_match_numpy_and_have_finite_gradients():
    x = torch.tensor(V, requires_grad=True)
    y = srgb_to_linear(x)
    np.testing.assert_allclose(y.detach().numpy(), srgb_to_linear(V), rtol=1e-12)
    (y.sum() + linear_to_srgb(x).sum() + linear_to_gamma(x, 2.2).sum()).backward()
    assert torch.isfinite(x.grad).all()
    xs = torch.tensor([0.01, 0.3, 0.8], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(srgb_to_linear, (xs,))
    assert torch.autograd.gradcheck(linear_to_srgb, (xs,))


@pytest.mark.parametrize("response", ["srgb", "linear", "gamma:2.2", "gamma:1.8"])
def test_response_round_trip(response):
    np.testing.assert_allclose(linear_to_response(response_to_linear(V, response), response), V,
                               atol=1e-7)


def test_gamma_response_definition():
    np.testing.assert_allclose(response_to_linear(np.array([0.5]), "gamma:2.0"), [0.25])
    np.testing.assert_allclose(linear_to_response(np.array([0.25]), "gamma:2.0"), [0.5])


@pytest.mark.parametrize("bad", ["sRGB", "gamma", "gamma:", "gamma:-1", "gamma:abc", "log", None, 2.2])
def test_unknown_response_names_raise(bad):
    with pytest.raises(InputError, match="frame_response"):
        response_to_linear(V, bad)
    with pytest.raises(InputError):
        parse_response(bad)
