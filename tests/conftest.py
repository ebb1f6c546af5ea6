"""Shared test helpers: locating the optional real recordings, seeding, a tiny scene and a tiny run."""

from __future__ import annotations  # noqa: I001  (fusiongs first: it sets OMP_WAIT_POLICY before torch)

import os
from pathlib import Path

import fusiongs  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch is imported)
import numpy as np
import pytest
import torch

from fusiongs.cli import main
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene

REPO_ROOT = Path(__file__).resolve().parents[1]


def docs_script(name: str):
    """A script of docs/ (``gen_commands``, ``build_tutorials``) loaded as a module (docs/ is not a
    package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO_ROOT / "docs" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def real_data_dir() -> Path:
    """The real recordings (third-party, never committed): the folder shared/data/real beside the
    repository, or the FUSIONGS_REAL_DATA environment variable when it is set."""
    if os.environ.get("FUSIONGS_REAL_DATA"):
        return Path(os.environ["FUSIONGS_REAL_DATA"])
    return REPO_ROOT.parent / "shared" / "data" / "real"


def real_file(name: str) -> Path:
    """Path of a real recording, skipping the calling test when it is absent."""
    path = real_data_dir() / name
    if not path.is_file():
        pytest.skip(f"real recording {name} not found in {real_data_dir()}")
    return path


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


@pytest.fixture
def generator() -> torch.Generator:
    return torch.Generator().manual_seed(0)


def has_cuda() -> bool:
    return torch.cuda.is_available()


# A few iterations of every stage (warm-up, events, pose learning, densification) on a 32x24 scene.
TINY = ["init.n_points=300", "blur.n_samples=3", "events.warmup=4", "events.pixels=256",
        "optim.iterations=10", "optim.pose_start=5", "densify.start=4", "densify.every=4",
        "densify.stop=9", "output.progress=false", "output.checkpoint_every=0"]


def simulated_scene(root, **config):
    """Simulate a boxes scene (32x24, 2 frames of 0.12 s unless ``config`` says otherwise) and
    write it, with its truth, to the folder ``root``; returns ``root``."""
    base = {"preset": "boxes", "width": 32, "height": 24, "duration": 0.12, "frames": 2, "exposure": 0.03,
            "dvs_rate_hz": 500.0, "blur_samples": 6, "supersample": 1, "novel": 1, "seed": 1}
    res = run_simulation(SimConfig(**(base | config)))
    write_simulated_scene(res.scene, res.gt, root, stats=res.stats, overwrite=True)
    return root


@pytest.fixture(scope="module")
def tiny_scene(tmp_path_factory):
    """A 32x24 boxes scene with 2 frames, events, trajectory and truth (written to a folder)."""
    return simulated_scene(tmp_path_factory.mktemp("scene"))


@pytest.fixture(scope="module")
def tiny_run(tiny_scene, tmp_path_factory):
    """``fusiongs deblur`` with :data:`TINY` on :func:`tiny_scene`: the output folder."""
    out = tmp_path_factory.mktemp("run")
    assert main(["deblur", str(tiny_scene), "-o", str(out), *TINY]) == 0
    return out


# 200 iterations on a 64x48 scene: a small but real fit (its renders ~28 dB from the truth), ~15 s.
SMALL = ["init.n_points=1500", "blur.n_samples=3", "events.warmup=60", "events.pixels=256",
         "optim.iterations=200", "optim.pose_start=100", "densify.start=50", "densify.every=50",
         "densify.stop=150", "output.progress=false", "output.checkpoint_every=0"]
_SMALL_RUNS: dict[str, Path] = {}


def small_run(tmp_path_factory) -> Path:
    """``fusiongs deblur`` with :data:`SMALL` on a 64x48 boxes scene (2 frames): the output folder
    (its ``frames.json`` names the scene folder). Made once per test process and shared by the
    modules that ask for it (build module-scoped fixtures on it; never write into it)."""
    if "run" not in _SMALL_RUNS:
        scene = simulated_scene(tmp_path_factory.mktemp("small_scene"), width=64, height=48)
        out = tmp_path_factory.mktemp("small_run")
        assert main(["deblur", str(scene), "-o", str(out), *SMALL]) == 0
        _SMALL_RUNS["run"] = out
    return _SMALL_RUNS["run"]
