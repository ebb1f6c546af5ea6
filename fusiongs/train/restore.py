"""Rebuild the optimised state of a finished run from its ``checkpoint.pt``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.trajectory import Trajectory
from fusiongs.camera.tum import PoseSamples
from fusiongs.losses.threshold import ContrastThreshold
from fusiongs.scene.gaussians import GaussianModel
from fusiongs.train.checkpoint import checkpoint_errors, load_checkpoint
from fusiongs.train.state import FusionState


def restore_state(path: str | Path) -> tuple[FusionState, PinholeCamera, dict]:
    """``(state, camera, config dict)`` of the run saved at ``path`` (on the CPU)."""
    ckpt = load_checkpoint(path)
    with checkpoint_errors(path):
        cam = ckpt["camera"]
        dist = tuple(cam["distortion"]) if cam.get("distortion") else None
        camera = PinholeCamera(**{**cam, "distortion": dist})
        model = GaussianModel.empty(int(ckpt["n_gaussians"]), int(ckpt["sh_degree"]))
        model.load_state_dict(ckpt["model"])
        tj = ckpt["trajectory"]
        poses = PoseSamples(t=np.asarray(tj["t"]), c2w=np.asarray(tj["c2w"]))
        refine = tj["state"].get("delta") is not None
        trajectory = Trajectory(poses, mode=tj["mode"], refine=refine, outside="clamp",
                                knot_spacing=tj["spacing"] or None, fit_iters=0)
        trajectory.load_state_dict(tj["state"])
        h, w = camera.height, camera.width
        th = ckpt["config"]["threshold"]
        threshold = ContrastThreshold(channels=int(ckpt["threshold_channels"]), image_size=(h, w),
                                      grid=tuple(th["grid"]) if th.get("grid") else None,
                                      time_knots=int(th.get("time_knots", 0)),
                                      time_range=tuple(ckpt.get("threshold_time_range", (0.0, 1.0))))
        threshold.load_state_dict(ckpt["threshold"])
        state = FusionState(model, trajectory, threshold, int(ckpt["log_gain"].numel()), False)
        with torch.no_grad():
            state.log_gain.copy_(ckpt["log_gain"])
    return state, camera, ckpt["config"]
