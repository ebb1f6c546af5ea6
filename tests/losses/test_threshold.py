"""Learnable contrast threshold module."""

from __future__ import annotations

import math

import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.losses.threshold import ContrastThreshold


def test_scalar_init_per_polarity_and_channel():
    ct = ContrastThreshold(channels=3, init=(0.2, 0.25))
    tp, tn = ct.theta()
    torch.testing.assert_close(tp, torch.full((3,), 0.2))
    torch.testing.assert_close(tn, torch.full((3,), 0.25))


def test_gradients_reach_log_threshold():
    ct = ContrastThreshold(channels=1, init=0.2)
    tp, tn = ct.theta()
    (tp.sum() + 2 * tn.sum()).backward()
    torch.testing.assert_close(ct.log_theta.grad, torch.tensor([[0.2], [0.4]]))


def test_freeze_and_unfreeze_toggle_requires_grad():
    ct = ContrastThreshold(grid=(2, 3), image_size=(4, 6), time_knots=3)
    ct.freeze()
    assert not any(p.requires_grad for p in ct.parameters())
    ct.unfreeze()
    assert all(p.requires_grad for p in ct.parameters())


def test_regularisers_zero_at_init_and_positive_after_change():
    ct = ContrastThreshold(channels=3, grid=(3, 4), image_size=(30, 40), time_knots=4)
    assert ct.regularisation().item() == 0.0 and ct.smoothness().item() == 0.0
    with torch.no_grad():
        ct.log_theta.add_(0.1)
        ct.field[0, 0, 1, 1] = 0.5
    assert ct.regularisation().item() == pytest.approx(6 * 0.01)
    # 4 neighbours each (0.5)^2 = 1.0, plus the squared mean (0.5 / 12)^2 of that map
    assert ct.smoothness().item() == pytest.approx(1.0 + (0.5 / 12) ** 2)


def test_field_at_init_equals_scalar_for_flat_and_xy_pixels():
    ct = ContrastThreshold(channels=3, init=0.22, grid=(6, 8), image_size=(26, 34), time_knots=3,
                           time_range=(0.0, 2.0))
    flat = torch.tensor([0, 5, 26 * 34 - 1])
    tp, tn = ct.theta(flat, t=torch.tensor([0.0, 1.0, 3.0]))
    torch.testing.assert_close(tp, torch.full((3, 3), 0.22))
    xy = torch.tensor([[0, 0], [33, 25]])
    tp2, _ = ct.theta(xy, t=0.5)
    torch.testing.assert_close(tp2, torch.full((2, 3), 0.22))


def test_field_is_bilinear_between_cell_centres_and_gradients_reach_it():
    ct = ContrastThreshold(channels=1, init=0.25, grid=(1, 2), image_size=(1, 4))
    with torch.no_grad():
        ct.field[:, 0, 0, 1] = math.log(2.0)  # right cell doubles theta
    # cell centres at x = 1 and x = 3 (pixel centres x + 0.5 = 1 and 3 -> pixels 0.5 and 2.5)
    xy = torch.tensor([[0.5, 0.0], [2.5, 0.0], [1.5, 0.0]])
    tp, tn = ct.theta(xy)
    torch.testing.assert_close(tp[:, 0], torch.tensor([0.25, 0.5, 0.25 * math.sqrt(2.0)]))
    tp.sum().backward()
    assert ct.field.grad is not None and ct.field.grad[0].abs().sum() > 0
    assert ct.field.grad[1].abs().sum() == 0


def test_drift_interpolates_linearly_between_knots_and_clamps():
    ct = ContrastThreshold(channels=1, init=0.2, time_knots=2, time_range=(0.0, 1.0))
    with torch.no_grad():
        ct.drift[1] = math.log(2.0)
    for t, factor in [(0.0, 1.0), (0.5, math.sqrt(2.0)), (1.0, 2.0), (5.0, 2.0), (-1.0, 1.0)]:
        tp, _ = ct.theta(t=t)
        assert tp.item() == pytest.approx(0.2 * factor, rel=1e-6)


def test_mask_mode_channel_selection():
    ct = ContrastThreshold(channels=3, grid=(2, 2), image_size=(4, 4))
    with torch.no_grad():
        ct.log_theta[0] = torch.log(torch.tensor([0.1, 0.2, 0.3]))
    tp, _ = ct.theta(torch.tensor([0, 1, 5]), channel=torch.tensor([0, 1, 2]))
    torch.testing.assert_close(tp, torch.tensor([[0.1], [0.2], [0.3]]))


def test_bad_construction_and_missing_pixels_are_named_errors():
    with pytest.raises(InputError, match="init"):
        ContrastThreshold(init=-0.1)
    with pytest.raises(InputError, match="time_knots"):
        ContrastThreshold(time_knots=1)
    with pytest.raises(InputError, match="pixels"):
        ContrastThreshold(grid=(2, 2), image_size=(4, 4)).theta()
