"""Censored event counts: a pixel that hit its refractory period only bounds the log change."""

import numpy as np
import torch

from fusiongs.events.stats import fast_event_mask
from fusiongs.events.stream import EventStream
from fusiongs.losses.event import censored_residual, event_loss_mse
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
