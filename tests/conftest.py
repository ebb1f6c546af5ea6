"""Shared test helpers: locating the optional real recordings, seeding."""

from __future__ import annotations  # noqa: I001  (fusiongs first: it sets OMP_WAIT_POLICY before torch)

from pathlib import Path

import fusiongs  # noqa: F401  (first: sets OMP_WAIT_POLICY before torch is imported)
import numpy as np
import pytest
import torch

REPO_ROOT = Path(__file__).resolve().parents[1]


def real_data_dir() -> Path:
    """``../shared/data/real`` beside the repository (third-party recordings, never committed)."""
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
