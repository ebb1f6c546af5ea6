"""Gaussian scene: parameters and activations, initialisation, densification, PLY io."""

from fusiongs.scene.densify import (
    DensifyConfig,
    DensifyReport,
    DensifyStrategy,
    should_refine,
    should_reset_opacity,
)
from fusiongs.scene.gaussians import PARAM_NAMES, GaussianModel
from fusiongs.scene.optim import GaussianLR, edit_gaussians, make_optimizer, reset_opacity
from fusiongs.scene.ply import load_ply, save_ply

__all__ = ["PARAM_NAMES", "DensifyConfig", "DensifyReport", "DensifyStrategy", "GaussianLR",
           "GaussianModel", "edit_gaussians", "load_ply", "make_optimizer", "reset_opacity",
           "save_ply", "should_refine", "should_reset_opacity"]
