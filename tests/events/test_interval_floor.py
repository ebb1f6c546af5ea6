"""The floor of a sensor's same-pixel intervals (:func:`fusiongs.events.dead_time.interval_floor`): a
step for a pixel whose level keeps every crossing, a rise without a step for a pixel held in reset."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.events.dead_time import IntervalFloor, dead_time_us, interval_floor
from fusiongs.events.stream import EventStream
from fusiongs.sim import dvs


def _edges_stream(dead_s: float, reset: bool, seed: int = 0, noise: int = 2000) -> EventStream:
    """800 pixels watching smooth edges go by (tanh of sines, 2-12 Hz, up to ~750 log units a
    second) for 1 s at 0.2 log units a threshold, plus ``noise`` background events."""
    rng = np.random.default_rng(seed)
    n_pix, times = 800, np.linspace(0.0, 1.0, 4001)
    f, ph, k = rng.uniform(2, 12, n_pix), rng.uniform(0, 2 * np.pi, n_pix), rng.uniform(1, 8, n_pix)
    logs = (1.5 * np.tanh(k * np.sin(2 * np.pi * f * times[:, None] + ph))).astype(np.float32)
    th = np.full(n_pix, 0.2)
    t, pix, p = (dvs.dvs_events_reset if reset else dvs.dvs_events)(logs, times, th, th, dead_s)
    t = np.concatenate([t, rng.integers(0, 1_000_000, noise)])
    pix = np.concatenate([pix, rng.integers(0, n_pix, noise)])
    p = np.concatenate([p, np.ones(noise, np.int8)])
    o = np.argsort(t, kind="stable")
    return EventStream.create(t[o], pix[o] % 40, pix[o] // 40, p[o], 40, 20)


@pytest.mark.parametrize("dead_us", [300, 900])
def test_the_default_pixel_steps_at_its_dead_time(dead_us):
    fl = interval_floor(_edges_stream(dead_us * 1e-6, reset=False))
    assert not fl.reset
    assert fl.step_us == fl.onset_us == fl.dead_us == dead_time_us(_edges_stream(dead_us * 1e-6, False))
    assert 0.85 * dead_us <= fl.dead_us <= dead_us  # the left edge of the bin holding it


@pytest.mark.parametrize("dead_us", [300, 900])
def test_a_reset_pixel_rises_from_its_dead_time_without_a_step(dead_us):
    fl = interval_floor(_edges_stream(dead_us * 1e-6, reset=True))
    assert fl.reset and fl.dead_us == fl.onset_us
    assert fl.step_us == 0 or fl.step_us > fl.onset_us
    # its intervals are the dead time plus the time to a threshold after the release: the onset is
    # at or above the dead time, by the fastest edge's time to a threshold (here up to 1.7x)
    assert 0.85 * dead_us <= fl.onset_us <= 1.7 * dead_us


def test_the_fastest_edge_of_a_scene_makes_an_onset_without_any_dead_time():
    """No refractory period, but no edge faster than ~750 log units a second: no interval under
    theta / r_max ~ 270 µs, a floor a reset pixel's would look like. The intervals alone cannot
    tell the two apart, which is why ``calibrate`` asks the frames (``pixel_model`` "auto")."""
    fl = interval_floor(_edges_stream(0.0, reset=False))
    assert fl.step_us == 0 and 150 <= fl.onset_us <= 300 and fl.reset
    assert interval_floor(EventStream.empty(4, 4)) == IntervalFloor(0.0, 0.0)


def test_poisson_noise_alone_has_no_floor():
    rng = np.random.default_rng(5)
    t = np.sort(rng.integers(0, 1_000_000, 20000))
    ev = EventStream.create(t, rng.integers(0, 20, t.size), rng.integers(0, 10, t.size), np.ones(t.size),
                            20, 10)
    assert interval_floor(ev).onset_us < 100 and not interval_floor(ev).reset
