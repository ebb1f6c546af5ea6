"""Cameras: pinhole intrinsics, TUM pose files and trajectories in time."""

from fusiongs.camera.frusta import sample_in_frusta
from fusiongs.camera.pinhole import PinholeCamera, SceneCamera, UncalibratedCamera
from fusiongs.camera.trajectory import Trajectory
from fusiongs.camera.tum import PoseSamples, read_tum, write_tum

__all__ = ["PinholeCamera", "PoseSamples", "SceneCamera", "Trajectory", "UncalibratedCamera", "read_tum",
           "sample_in_frusta", "write_tum"]
