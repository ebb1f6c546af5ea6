"""Precomputed photovoltage read-outs for the pvc loss equal the filter run per window."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.events.hpf import high_pass_filter
from fusiongs.events.stream import EventStream
from fusiongs.train.data import pvc_readouts
from fusiongs.train.step import nearest_readout, snap_windows


@pytest.fixture
def events(rng):
    n = 5000
    t = np.sort(rng.integers(0, 200_000, n))
    return EventStream.create(t, rng.integers(0, 7, n), rng.integers(0, 5, n),
                              rng.choice([-1, 1], n), width=7, height=5)


def test_readout_differences_equal_the_filter_over_the_window(events):
    instants = np.array([0.0123456, 0.0871])
    times, maps = pvc_readouts(events, instants, (0.0, 0.2), 0.01, 0.05, 0.2, torch.device("cpu"))
    assert torch.all(torch.diff(times) > 0) and maps.shape == (len(times), 5, 7)
    assert set(instants.tolist()) <= set(times.tolist())  # the instants are read-outs exactly
    a, b = int(torch.nonzero(times == instants[0])), int(torch.nonzero(times == instants[1]))
    v = high_pass_filter(events, [instants[0] * 1e6, instants[1] * 1e6], tau=0.05, contrast=0.2)
    np.testing.assert_allclose((maps[b] - maps[a]).numpy(), (v[1] - v[0]) / 0.2, atol=1e-5)


def test_snapped_windows_end_on_nearest_readouts_and_keep_their_order():
    readouts = torch.linspace(0.0, 1.0, 11, dtype=torch.float64)
    w = torch.tensor([[0.12, 0.38], [0.51, 0.52], [0.0, 0.01], [0.96, 0.99]], dtype=torch.float64)
    s = snap_windows(w, readouts)
    want = torch.tensor([[0.1, 0.4], [0.4, 0.5], [0.0, 0.1], [0.9, 1.0]], dtype=torch.float64)
    torch.testing.assert_close(s, want)
    assert torch.all(s[:, 0] < s[:, 1])
    assert nearest_readout(readouts, torch.tensor([0.149, 0.151], dtype=torch.float64)).tolist() == [1, 2]
