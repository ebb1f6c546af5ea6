"""Event losses: log change, mse, band (Event-3DGS Eq. 15), pvc, mask mode, pixel sampling."""

from __future__ import annotations

import math

import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.losses.event import (
    band_penalty,
    delta_log,
    event_loss_band,
    event_loss_mse,
    event_loss_pvc,
    log_intensity,
    sample_event_pixels,
    select_channel,
)


def test_log_intensity_grey_uses_rec601_weights_and_eps():
    lin = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    out = log_intensity(lin, "grey", eps=1e-3)
    assert out.shape == (2, 1)
    torch.testing.assert_close(out[:, 0], torch.log(torch.tensor([0.299 + 1e-3, 0.114 + 1e-3])))


def test_log_intensity_rgb_keeps_channels_and_rejects_bad_mode():
    lin = torch.tensor([[0.5, 1.0, 2.0]])
    torch.testing.assert_close(log_intensity(lin, "rgb", eps=0.0), torch.log(lin))
    with pytest.raises(InputError, match="mode"):
        log_intensity(lin, "hsv")


def test_delta_log_is_log_ratio():
    a, b = torch.tensor([[0.2]]), torch.tensor([[0.4]])
    assert delta_log(a, b, "grey", eps=0.0).item() == pytest.approx(math.log(2.0))


def test_mse_hand_example_with_channel_weights():
    d = torch.tensor([[0.5, 0.0, -0.2]])
    n_pos = torch.tensor([[2.0, 0.0, 0.0]])
    n_neg = torch.tensor([[0.0, 1.0, 1.0]])
    th_p = torch.tensor([0.2, 0.2, 0.2])
    th_n = torch.tensor([0.3, 0.3, 0.3])
    # residuals: 0.5-0.4=0.1, 0+0.3=0.3, -0.2+0.3=0.1 -> sq 0.01, 0.09, 0.01
    w = torch.tensor([0.4, 0.2, 0.4])
    expected = (0.4 * 0.01 + 0.2 * 0.09 + 0.4 * 0.01) / 1.0
    assert event_loss_mse(d, n_pos, n_neg, th_p, th_n, w).item() == pytest.approx(expected)
    assert event_loss_mse(d, n_pos, n_neg, th_p, th_n).item() == pytest.approx(0.11 / 3)


def test_mse_weights_per_pixel_mean_over_pixels():
    d = torch.tensor([[1.0], [0.0]])
    z = torch.zeros(2, 1)
    w = torch.tensor([[0.4], [0.2]])
    assert event_loss_mse(d, z, z, torch.tensor([0.2]), torch.tensor([0.2]), w).item() == pytest.approx(
        0.4 / 0.6
    )


# (D_r, D_gt, beta) -> Event-3DGS Eq. 15 value
BAND_CASES = [
    (2.0, 2.0, 0.5, 0.0),  # lower edge of [D_gt, D_gt + 2 beta]
    (3.0, 2.0, 0.5, 0.0),  # upper edge
    (2.5, 2.0, 0.5, 0.0),  # inside
    (1.5, 2.0, 0.5, 0.5),  # below the band
    (4.0, 2.0, 0.5, 1.0),  # above the band
    (-2.0, -2.0, 0.5, 0.0),
    (-3.0, -2.0, 0.5, 0.0),  # lower edge of [D_gt - 2 beta, D_gt]
    (-1.0, -2.0, 0.5, 1.0),
    (-3.5, -2.0, 0.5, 0.5),
    (0.5, 0.0, 0.5, 0.0),  # zero target: free inside |D_r| <= 1
    (-1.0, 0.0, 0.5, 0.0),
    (1.75, 0.0, 0.5, 0.75),
    (-2.0, 0.0, 0.0, 1.0),
    (2.5, 2.0, 0.0, 0.5),  # beta 0: |D_r - D_gt|
    (1.5, 2.0, 0.0, 0.5),
    (-2.5, -2.0, 0.0, 0.5),
]


@pytest.mark.parametrize(("d_r", "d_gt", "beta", "expected"), BAND_CASES)
def test_band_penalty_table(d_r, d_gt, beta, expected):
    out = band_penalty(torch.tensor([d_r]), torch.tensor([d_gt]), beta)
    assert out.item() == pytest.approx(expected)


def test_band_loss_uses_theta_of_target_polarity():
    th_p, th_n = torch.tensor([0.2]), torch.tensor([0.4])
    # D_gt=+1 with theta_+: D_r = 0.2/0.2 = 1 -> in band; D_gt=-1 with theta_-: D_r = -0.4/0.4 = -1
    d = torch.tensor([[0.2], [-0.4]])
    gt = torch.tensor([[1.0], [-1.0]])
    assert event_loss_band(d, gt, th_p, th_n, beta=0.0).item() == pytest.approx(0.0)
    # swapping the thresholds gives D_r = 0.5 and -2 -> |0.5-1| and |-2+1| -> mean 0.75
    assert event_loss_band(d, gt, th_n, th_p, beta=0.0).item() == pytest.approx(0.75)


def test_band_loss_zero_target_uses_sign_of_render():
    th_p, th_n = torch.tensor([0.2]), torch.tensor([0.5])
    d = torch.tensor([[0.4], [-0.75]])  # D_r = 2 (theta_+) and -1.5 (theta_-)
    gt = torch.zeros(2, 1)
    assert event_loss_band(d, gt, th_p, th_n).item() == pytest.approx((1.0 + 0.5) / 2)


def test_band_zero_tol_treats_tiny_hpf_as_no_event():
    d = torch.tensor([[0.1]])
    gt = torch.tensor([[1e-4]])
    th = torch.tensor([0.2])
    assert event_loss_band(d, gt, th, beta=0.0).item() == pytest.approx(0.5 - 1e-4)
    assert event_loss_band(d, gt, th, beta=0.0, zero_tol=1e-3).item() == pytest.approx(0.0)


def test_pvc_mse_and_band_dispatch():
    d = torch.tensor([[0.3], [-0.3]])
    gt = torch.tensor([[1.0], [-0.5]])
    th_p, th_n = torch.tensor([0.2]), torch.tensor([0.4])
    # targets 0.2 and -0.2 -> residuals 0.1, -0.1
    assert event_loss_pvc(d, gt, th_p, th_n, kind="mse").item() == pytest.approx(0.01)
    assert event_loss_pvc(d, gt, th_p, th_n, kind="band", beta=0.25).item() == pytest.approx(
        event_loss_band(d, gt, th_p, th_n, beta=0.25).item()
    )
    with pytest.raises(InputError, match="kind"):
        event_loss_pvc(d, gt, th_p, kind="l1")


def test_select_channel_picks_each_pixels_cfa_channel():
    vals = torch.tensor([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
    idx = torch.tensor([2, 0, 1])
    torch.testing.assert_close(select_channel(vals, idx), torch.tensor([[3.0], [4.0], [8.0]]))


def test_event_losses_gradients_finite_and_reach_inputs_and_thresholds():
    g = torch.Generator().manual_seed(0)
    a = torch.rand(64, 3, generator=g, requires_grad=True)
    b = torch.rand(64, 3, generator=g)
    s = torch.tensor([math.log(0.25)] * 2, requires_grad=True)
    d = delta_log(a, b, "rgb")
    counts = torch.randint(0, 3, (2, 64, 3), generator=g).float()
    loss = event_loss_mse(d, counts[0], counts[1], s[0].exp(), s[1].exp(), torch.tensor([0.4, 0.2, 0.4]))
    loss = loss + event_loss_band(d, counts[0] - counts[1], s[0].exp(), s[1].exp())
    loss.backward()
    assert torch.isfinite(a.grad).all() and torch.isfinite(s.grad).all()
    assert a.grad.abs().sum() > 0 and (s.grad != 0).all()


def _maps(h=10, w=12, n_active=30, seed=0):
    g = torch.Generator().manual_seed(seed)
    m = torch.zeros(2, h * w)
    idx = torch.randperm(h * w, generator=g)[:n_active]
    m[0, idx[::2]] = 1
    m[1, idx[1::2]] = 2
    return m.reshape(2, h, w)


def test_sampling_fraction_distinct_and_deterministic():
    m = _maps()
    active = set((m.sum(0) > 0).reshape(-1).nonzero()[:, 0].tolist())
    idx = sample_event_pixels(m, 20, 0.9, torch.Generator().manual_seed(3))
    assert idx.shape == (20,) and len(set(idx.tolist())) == 20
    assert sum(i in active for i in idx.tolist()) == 18
    again = sample_event_pixels(m, 20, 0.9, torch.Generator().manual_seed(3))
    assert torch.equal(idx, again)


def test_sampling_fills_with_inactive_when_few_events_and_batched():
    maps = torch.stack([_maps(n_active=5), _maps(n_active=0, seed=1), _maps(n_active=120)])
    idx = sample_event_pixels(maps, 40, 0.9, torch.Generator().manual_seed(0))
    assert idx.shape == (3, 40)
    act = maps.sum(1).reshape(3, -1) > 0
    n_act = act.gather(1, idx).sum(1).tolist()
    assert n_act == [5, 0, 40]
    assert all(len(set(r.tolist())) == 40 for r in idx)


def test_sampling_rejects_too_many_pixels():
    with pytest.raises(InputError, match="n_pixels"):
        sample_event_pixels(_maps(), 10 * 12 + 1)
