"""Loss helpers that avoid device constants give the same values as the tensor formulas."""

from __future__ import annotations

import pytest
import torch

from fusiongs.losses.colour import channel_weights_for
from fusiongs.losses.event import REC601, log_intensity, to_grey
from fusiongs.losses.threshold import ContrastThreshold


def test_grey_with_python_weights_equals_the_weighted_sum(generator):
    lin = torch.rand(4, 5, 3, generator=generator)
    want = (lin * torch.tensor(REC601)).sum(-1, keepdim=True)
    torch.testing.assert_close(to_grey(lin), want)
    torch.testing.assert_close(log_intensity(lin, "grey", eps=1e-3), torch.log(want + 1e-3))


def test_channel_weights_follow_the_channel_index():
    ch = torch.tensor([0, 1, 2, 2, 1])
    w = channel_weights_for(ch, (0.4, 0.2, 0.4))
    assert w.shape == (5, 1) and w.dtype == torch.float32
    torch.testing.assert_close(w[:, 0], torch.tensor([0.4, 0.2, 0.4, 0.4, 0.2]))


@pytest.mark.parametrize("t", [-1.0, 0.0, 0.1, 0.25, 0.5, 0.74, 1.0, 3.0])
def test_drift_at_a_python_time_equals_the_tensor_path(t, generator):
    ct = ContrastThreshold(channels=3, init=(0.2, 0.3), time_knots=4, time_range=(0.0, 1.0))
    with torch.no_grad():
        ct.drift.copy_(torch.randn(ct.drift.shape, generator=generator))
    at_float = ct.log_theta_at(t=t)  # [2, C]
    at_tensor = ct.log_theta_at(t=torch.tensor(t, dtype=torch.float64))
    torch.testing.assert_close(at_float, at_tensor)
