"""Cameras: pinhole intrinsics, TUM pose files and trajectories in time."""

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.tum import PoseSamples, read_tum, write_tum

__all__ = ["PinholeCamera", "PoseSamples", "read_tum", "write_tum"]
