"""What training hands on: the optimised state with its data, settings and history."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from fusiongs.camera.tum import PoseSamples
from fusiongs.events.thresholds import SensorThresholds
from fusiongs.train.data import TrainData
from fusiongs.train.history import History
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.state import FusionState


@dataclass
class Trained:
    """A finished (or interrupted) run."""

    state: FusionState
    data: TrainData
    config: DeblurConfig
    history: History
    iteration: int
    poses: PoseSamples
    initial_thresholds: SensorThresholds | None = None  # where θ started (calibration)
    # ``threshold.render_floor``'s ``(θ before, θ after)``, ``[2, C]`` host float64, when it ran
    threshold_floor: tuple[torch.Tensor, torch.Tensor] | None = None
    # the image motion (px, 90 % of the exposures) that set ``config.blur.n_samples``, if it did
    exposure_motion_px: float | None = None
