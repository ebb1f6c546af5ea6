"""High-pass filter photovoltage (Scheerlinck et al. 2018; Event-3DGS) against a per-event loop."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.events.hpf import high_pass_filter, hpf_contrast
from fusiongs.events.stream import EventStream


def _reference(ev: EventStream, times, tau, c_pos, c_neg):
    """Per-event loop of the filter definition (slow, obviously correct)."""
    v = np.zeros((ev.height, ev.width))
    last = np.zeros((ev.height, ev.width))
    out, i = [], 0
    for tr in times:
        while i < len(ev) and ev.t[i] < tr:
            y, x = ev.y[i], ev.x[i]
            step = c_pos if ev.p[i] > 0 else -c_neg
            v[y, x] = np.exp(-(ev.t[i] - last[y, x]) * 1e-6 / tau) * v[y, x] + step
            last[y, x] = ev.t[i]
            i += 1
        out.append(np.exp(-(tr - last) * 1e-6 / tau) * v)
    return np.stack(out)


def _stream(n=4000, w=9, h=7, seed=0):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, 300_000, n))
    return EventStream.create(t, rng.integers(0, w, n), rng.integers(0, h, n), rng.choice([-1, 1], n), w, h)


@pytest.mark.parametrize("tau", [0.005, 0.05, 1.0])
def test_hpf_matches_the_per_event_reference(tau):
    ev = _stream()
    times = np.array([0, 1, 20_000.5, 150_000, 150_000, 299_999, 400_000])
    got = high_pass_filter(ev, times, tau=tau, contrast_pos=0.2, contrast_neg=0.3)
    ref = _reference(ev, times, tau, 0.2, 0.3)
    assert got.shape == (7, 7, 9) and got.dtype == np.float32
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-6)


def test_hpf_read_out_counts_events_strictly_before_it():
    ev = EventStream.create([100, 200], [0, 0], [0, 0], [1, 1], 1, 1)
    v = high_pass_filter(ev, [100, 101, 200, 201], tau=1e9, contrast=1.0)[:, 0, 0]
    np.testing.assert_allclose(v, [0, 1, 1, 2], atol=1e-6)


def test_hpf_decays_with_time_constant():
    ev = EventStream.create([0], [0], [0], [-1], 1, 1)
    v = high_pass_filter(ev, [1, 50_001], tau=0.05, contrast=0.2)[:, 0, 0]
    np.testing.assert_allclose(v[1] / v[0], np.exp(-1.0), rtol=1e-5)
    assert v[0] < 0


def test_hpf_contrast_equals_signed_counts_for_long_tau():
    ev = _stream(seed=1)
    d = hpf_contrast(ev, 50_000, 120_000, tau=1e6, theta0=0.25)
    np.testing.assert_allclose(d, ev.signed_count_map(50_000, 120_000), atol=1e-3)


def test_hpf_contrast_removes_old_activity():
    ev = _stream(seed=2)
    d = hpf_contrast(ev, 250_000, 260_000, tau=0.002, theta0=0.2)
    full = high_pass_filter(ev, [250_000, 260_000], tau=0.002, contrast=0.2)
    np.testing.assert_allclose(d, (full[1] - full[0]) / 0.2, rtol=1e-5, atol=1e-5)


def test_hpf_rejects_bad_arguments():
    ev = _stream(n=10)
    with pytest.raises(InputError, match="times_us"):
        high_pass_filter(ev, [5, 3])
    with pytest.raises(InputError, match="tau"):
        high_pass_filter(ev, [5], tau=0)
    with pytest.raises(InputError, match="contrast_neg"):
        high_pass_filter(ev, [5], contrast_neg=-1)
    with pytest.raises(InputError, match="t_a_us"):
        hpf_contrast(ev, 10, 5)


def test_hpf_of_empty_stream_is_zero():
    out = high_pass_filter(EventStream.empty(4, 3), [0, 10])
    assert out.shape == (2, 3, 4) and not out.any()
