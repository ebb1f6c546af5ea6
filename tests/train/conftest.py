"""Shared fixtures of the training tests: a tiny simulated scene and a tiny finished run."""

from __future__ import annotations

import pytest

from fusiongs.cli import main
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene

# A few iterations of every stage (warm-up, events, pose learning, densification) on a 32x24 scene.
TINY = ["init.n_points=300", "blur.n_samples=3", "events.warmup=4", "events.pixels=256",
        "optim.iterations=10", "optim.pose_start=5", "densify.start=4", "densify.every=4",
        "densify.stop=9", "output.progress=false", "output.checkpoint_every=0"]


@pytest.fixture(scope="module")
def tiny_scene(tmp_path_factory):
    """A 32x24 boxes scene with 2 frames, events, trajectory and truth (written to a folder)."""
    root = tmp_path_factory.mktemp("scene")
    cfg = SimConfig(preset="boxes", width=32, height=24, duration=0.12, frames=2, exposure=0.03,
                    dvs_rate_hz=500.0, blur_samples=6, supersample=1, novel=1, seed=1)
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, root, stats=res.stats, overwrite=True)
    return root


@pytest.fixture(scope="module")
def tiny_run(tiny_scene, tmp_path_factory):
    """``fusiongs deblur`` with :data:`TINY` on :func:`tiny_scene`: the output folder."""
    out = tmp_path_factory.mktemp("run")
    assert main(["deblur", str(tiny_scene), "-o", str(out), *TINY]) == 0
    return out
