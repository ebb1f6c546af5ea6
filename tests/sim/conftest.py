"""Tiny simulated scenes shared by the simulator tests (generated once per module)."""

from __future__ import annotations

import dataclasses

import pytest

from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.simulate import SimConfig, run_simulation


def tiny_config(**kw) -> SimConfig:
    """A scene small enough to simulate in about a second."""
    base = SimConfig(preset="boxes", width=32, height=24, duration=0.12, frames=2, exposure=0.03,
                     dvs_rate_hz=500.0, blur_samples=6, supersample=1, novel=1)
    return dataclasses.replace(base, **kw)


@pytest.fixture(scope="package")
def tiny_result():
    return run_simulation(tiny_config(seed=3, dvs=DVSParams(ba_rate_hz=5.0)))
