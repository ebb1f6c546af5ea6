"""Censored event counts: a pixel that hit its refractory period only bounds the log change."""

import numpy as np
import torch

from fusiongs.events.stats import fast_event_mask
from fusiongs.events.stream import EventStream
from fusiongs.losses.event import band_penalty, censored_residual, event_loss_band, event_loss_mse
from fusiongs.sim.dvs import dvs_events


def test_censored_residual_keeps_only_the_shortfall():
    target = torch.tensor([[0.5], [0.5], [-0.5], [-0.5], [0.0], [0.5]])
    pred = torch.tensor([[0.7], [0.3], [-0.7], [-0.3], [0.2], [0.7]])
    cens = torch.tensor([[True], [True], [True], [True], [True], [False]])
    r = censored_residual(pred - target, target, cens)
    expect = torch.tensor([[0.0], [-0.2], [0.0], [0.2], [0.2], [0.2]])
    assert torch.allclose(r, expect, atol=1e-6)


def test_fast_event_mask_in_stream_order():
    # pixel (0, 0): 0, 100, 1000 µs; pixel (1, 0): 50, 60 µs
    t = np.array([0, 50, 60, 100, 1000], np.int64)
    x = np.array([0, 1, 1, 0, 0])
    ev = EventStream.create(t, x, np.zeros(5, np.int64), np.ones(5, np.int8), 2, 1, None)
    assert fast_event_mask(ev, 200.0).tolist() == [False, False, True, True, False]
    assert not fast_event_mask(ev, 0.0).any()


def test_refractory_edge_censored_loss_prefers_the_true_change():
    """A fast ramp of +1.2 log units at one pixel with θ = 0.1 and a 1 ms refractory period loses
    events; the plain mse is minimised at the (too small) count, the censored one accepts the truth
    and the fast events flag the pixel."""
    times = np.linspace(0.0, 0.01, 101)  # 10 ms, a sample every 0.1 ms
    logs = np.minimum(times / 0.005, 1.0)[:, None] * 1.2  # +1.2 in 5 ms
    th = np.full(1, 0.1)
    t_us, _, p = dvs_events(logs.astype(np.float32), times, th, th, 1e-3)
    n_pos = float((p > 0).sum())
    assert n_pos * 0.1 < 0.8  # refractory losses: the count says less than the change
    ev = EventStream.create(t_us, np.zeros_like(t_us), np.zeros_like(t_us), p, 1, 1, None)
    assert fast_event_mask(ev, 2e3).any()  # events at the dead time flag the pixel
    d_true = torch.tensor([[1.2]])
    args = (torch.tensor([[n_pos]]), torch.zeros(1, 1), torch.tensor(0.1), torch.tensor(0.1))
    plain = event_loss_mse(d_true, *args)
    cens = event_loss_mse(d_true, *args, censored=torch.tensor([[True]]))
    assert float(plain) > 0.1 and float(cens) == 0.0
    # a prediction short of the count is still penalised
    short = event_loss_mse(torch.tensor([[0.1]]), *args, censored=torch.tensor([[True]]))
    assert float(short) > 0.0


def test_censored_band_penalises_only_the_shortfall():
    """The band loss with censored counts (Event-3DGS Eq. 15, open on the far side): a rendered
    change beyond a censored count costs nothing and gets no gradient, a shortfall costs as much as
    uncensored, "no event" pixels and uncensored ones are unchanged (β = 0 and β = 0.5)."""
    d_gt = torch.tensor([3.0, 3.0, -2.0, -2.0, 0.0, 3.0])
    d_r = torch.tensor([4.5, 1.0, -3.5, -0.5, 1.7, 4.5], requires_grad=True)
    cens = torch.tensor([True, True, True, True, True, False])
    for beta in (0.0, 0.5):
        got = band_penalty(d_r, d_gt, beta, censored=cens)
        plain = band_penalty(d_r, d_gt, beta)
        expect = torch.tensor([0.0, 2.0, 0.0, 1.5, 0.7, float(plain[5].detach())])
        assert torch.allclose(got, expect, atol=1e-6), (beta, got)
        assert torch.allclose(got[[1, 3, 4, 5]], plain[[1, 3, 4, 5]])  # shortfalls, zeros, uncensored
        grad, = torch.autograd.grad(got.sum(), d_r)
        assert grad[0] == 0 and grad[2] == 0 and grad[1] < 0 and grad[3] > 0
    # the loss passes the mask through, in log units with per-polarity thresholds
    delta = torch.tensor([[0.9], [0.1]])
    counts = torch.tensor([[3.0], [3.0]])
    th = torch.tensor(0.2)
    one_sided = event_loss_band(delta, counts, th, th, 0.0, censored=torch.tensor([[True], [True]]))
    assert torch.isclose(one_sided, torch.tensor((0.0 + (3.0 - 0.5)) / 2))
    assert torch.isclose(event_loss_band(delta, counts, th, th, 0.0),
                         torch.tensor(((4.5 - 3.0) + (3.0 - 0.5)) / 2))
