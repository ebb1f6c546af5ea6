"""EDI and HPF intensity priors."""

from __future__ import annotations

import math

import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.losses.blur import apply_response
from fusiongs.losses.priors import edi_prior_loss, intensity_prior_loss


def test_edi_prior_is_l1_after_encoding():
    r = torch.full((2, 2, 3), 0.18)
    e = torch.full((2, 2, 3), 0.5)
    expected = (apply_response(torch.tensor(0.5)) - apply_response(torch.tensor(0.18))).item()
    assert edi_prior_loss(r, e).item() == pytest.approx(expected)
    assert edi_prior_loss(r, e, response="linear").item() == pytest.approx(0.32)


def test_edi_prior_valid_mask_ignores_pixels():
    r = torch.zeros(1, 2, 1)
    e = torch.tensor([[[0.5], [100.0]]])
    valid = torch.tensor([[[True], [False]]])
    assert edi_prior_loss(r, e, "linear", valid).item() == pytest.approx(0.5)


def test_intensity_prior_is_invariant_to_log_offset_per_channel():
    g = torch.Generator().manual_seed(0)
    render = torch.rand(5, 6, 3, generator=g) + 0.1
    hpf = torch.log(render + 1e-3) + torch.tensor([0.3, -2.0, 5.0])
    assert intensity_prior_loss(render, hpf).item() == pytest.approx(0.0, abs=1e-6)


def test_intensity_prior_hand_example_median_offset():
    render = torch.tensor([[[1.0], [1.0], [1.0]]]) - 1e-3  # log render = 0 everywhere
    hpf = torch.tensor([[[0.0], [1.0], [3.0]]])
    # median offset 1 -> |0+1-0| + |1-1| + |1-3| = 3 -> mean 1
    assert intensity_prior_loss(render, hpf).item() == pytest.approx(1.0, rel=1e-5)


def test_intensity_prior_gradient_finite_and_shape_check():
    render = torch.rand(2, 4, 4, 3, requires_grad=True)
    intensity_prior_loss(render, torch.randn(2, 4, 4, 3)).backward()
    assert torch.isfinite(render.grad).all()
    with pytest.raises(InputError, match="render/target"):
        intensity_prior_loss(render, torch.zeros(4, 4, 3))
    assert math.isfinite(edi_prior_loss(torch.zeros(2, 2, 3), torch.zeros(2, 2, 3)).item())
