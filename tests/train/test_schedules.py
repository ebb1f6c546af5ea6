"""Schedules and event-window sampling, at their boundaries."""

from __future__ import annotations

import math

import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.train.schedules import (
    event_only_alpha,
    event_weight,
    log_linear_lr,
    sample_exposure_pairs,
    sample_free_windows,
    sample_windows,
)


def test_event_weight_zero_in_warmup_then_lambda():
    assert event_weight(0, 1000, 0.1) == 0.0
    assert event_weight(999, 1000, 0.1) == 0.0
    assert event_weight(1000, 1000, 0.1) == 0.1
    assert event_weight(10**6, 1000, 0.1) == 0.1


def test_event_weight_linear_ramp_boundaries():
    assert event_weight(1000, 1000, 0.1, ramp=100) == 0.0
    assert event_weight(1050, 1000, 0.1, ramp=100) == pytest.approx(0.05)
    assert event_weight(1100, 1000, 0.1, ramp=100) == pytest.approx(0.1)
    assert event_weight(2000, 1000, 0.1, ramp=100) == pytest.approx(0.1)


def test_event_only_alpha_boundaries_and_range_check():
    assert event_only_alpha(499, 500, 0.95) == 0.0
    assert event_only_alpha(500, 500, 0.95) == 0.95
    assert event_only_alpha(550, 500, 0.95, ramp=100) == pytest.approx(0.475)
    with pytest.raises(InputError, match="alpha_final"):
        event_only_alpha(0, 0, 1.5)


def test_log_linear_lr_endpoints_midpoint_and_after_end():
    assert log_linear_lr(0, 1e-3, 1e-5, 1000) == pytest.approx(1e-3)
    assert log_linear_lr(500, 1e-3, 1e-5, 1000) == pytest.approx(1e-4)
    assert log_linear_lr(1000, 1e-3, 1e-5, 1000) == pytest.approx(1e-5)
    assert log_linear_lr(5000, 1e-3, 1e-5, 1000) == pytest.approx(1e-5)
    with pytest.raises(InputError):
        log_linear_lr(0, 0.0, 1e-5, 1000)


def test_exposure_pairs_distinct_ordered_and_with_replacement_beyond_all_pairs():
    g = torch.Generator().manual_seed(0)
    p = sample_exposure_pairs(9, 36, g)
    assert len({tuple(r) for r in p.tolist()}) == 36 and (p[:, 0] < p[:, 1]).all()
    p2 = sample_exposure_pairs(3, 10, g)
    assert p2.shape == (10, 2) and (p2[:, 0] < p2[:, 1]).all() and p2.max() <= 2
    with pytest.raises(InputError, match="n_instants"):
        sample_exposure_pairs(1, 1, g)


def test_free_windows_log_uniform_durations_inside_range():
    g = torch.Generator().manual_seed(1)
    w = sample_free_windows(4000, (0.0, 10.0), 0.05, g)
    dur = w[:, 1] - w[:, 0]
    assert (w[:, 0] >= 0).all() and (w[:, 1] <= 10.0).all()
    assert dur.min() >= 1e-3 - 1e-12 and dur.max() <= 0.05 + 1e-12
    # log-uniform: median duration is the geometric mean of the bounds
    assert dur.median().item() == pytest.approx(math.sqrt(1e-3 * 0.05), rel=0.1)


def test_free_windows_clamped_to_short_event_range():
    w = sample_free_windows(50, (1.0, 1.002), 0.05, torch.Generator().manual_seed(2))
    assert (w[:, 0] >= 1.0).all() and (w[:, 1] <= 1.002 + 1e-12).all()


def test_sample_windows_inside_rows_are_blur_instant_pairs():
    exposures = torch.tensor([[0.0, 0.09], [0.1, 0.19]], dtype=torch.float64)
    w = sample_windows(exposures, 1, 4, 3, (0.0, 0.3), 0.1, n_instants=9,
                       generator=torch.Generator().manual_seed(3))
    assert w.shape == (7, 2) and w.dtype == torch.float64
    instants = 0.1 + (torch.arange(9, dtype=torch.float64) + 0.5) * 0.01
    for a, b in w[:4].tolist():
        assert a < b
        assert torch.isclose(instants, torch.tensor(a, dtype=torch.float64)).any()
        assert torch.isclose(instants, torch.tensor(b, dtype=torch.float64)).any()
    assert (w[4:, 1] - w[4:, 0] <= 0.1 + 1e-12).all()


def test_sample_windows_deterministic_and_clamps_inside_to_event_range():
    exposures = torch.tensor([[0.0, 0.09]], dtype=torch.float64)
    a = sample_windows(exposures, 0, 36, 2, (0.02, 0.5), 0.1, generator=torch.Generator().manual_seed(4))
    b = sample_windows(exposures, 0, 36, 2, (0.02, 0.5), 0.1, generator=torch.Generator().manual_seed(4))
    assert torch.equal(a, b) and a[:36].min() >= 0.02
    with pytest.raises(InputError, match="frame"):
        sample_windows(exposures, 1, 1, 1, (0.0, 1.0), 0.1)


def _window_data(n_events: int, frame_interval: float, span: float = 2.0):
    from types import SimpleNamespace

    return SimpleNamespace(t_range=(1.0, 1.0 + span), frame_interval=frame_interval, events=[0] * n_events,
                           camera=SimpleNamespace(width=40, height=25))


@pytest.mark.parametrize("overrides, n_events, frame_interval, want", [
    ([], 1000, 0.05, 0.05),                                     # one frame interval
    ([], 1000, 2.0, 2.0),                                       # no frames: the recording
    (["events.max_window=0.1"], 1000, 2.0, 0.1),
    # 40x25 pixels, 2 s: 1000 events is 0.5 per pixel per second, so 4 events take 8 s (> the span)
    (["events.window_events=4"], 1000, 2.0, 2.0),
    (["events.window_events=4"], 100_000, 2.0, 0.08),           # 50 per pixel per second: 4 in 80 ms
    (["events.window_events=4", "events.max_window=0.05"], 100_000, 2.0, 0.05),
    (["events.window_events=4"], 100_000, 0.05, 0.05),          # frames closer than that
    (["events.window_events=4"], 0, 2.0, 2.0),                  # no events: no rate to cap by
])
def test_the_longest_free_window(overrides, n_events, frame_interval, want):
    from fusiongs.pipeline.deblur import resolve_config
    from fusiongs.train.step import longest_free_window

    got = longest_free_window(resolve_config(None, overrides), _window_data(n_events, frame_interval))
    assert isinstance(got, float) and got == pytest.approx(want)
