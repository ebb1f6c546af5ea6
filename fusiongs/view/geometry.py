"""What ``fusiongs view`` draws, as arrays: the Gaussians of ``model.ply`` in the form viser's
splats take, and camera poses as positions, orientations and look-at points.

Everything is in the run's world frame; cameras have OpenCV axes (x right, y down, z forward), as
viser's cameras and frustums do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.tum import matrix_to_quat_xyzw, quat_xyzw_to_matrix
from fusiongs.scene.gaussians import SH_C0, GaussianModel


@dataclass(frozen=True)
class Splats:
    """Gaussians as a 3DGS viewer composites them (float32).

    Attributes:
        centers: ``[N, 3]`` means (scene units).
        covariances: ``[N, 3, 3]`` world covariances ``R diag(s^2) R^T`` (scene units squared).
        rgbs: ``[N, 3]`` display colours in [0, 1] (sRGB-encoded values, composited as stored).
        opacities: ``[N, 1]`` opacities in (0, 1).
    """

    centers: np.ndarray
    covariances: np.ndarray
    rgbs: np.ndarray
    opacities: np.ndarray


def splats_from_ply(model: GaussianModel) -> Splats:
    """The splats of a PLY read with ``load_ply(path, colours="display")``: colour
    ``clip(0.5 + SH_C0 f_dc, 0, 1)`` (the DC band: viser draws no view dependence), opacity
    ``sigmoid``, covariance from ``exp`` scales and the wxyz rotation."""
    with np.errstate(all="ignore"):
        means = model.means.detach().double().cpu().numpy()
        scales = model.scales.detach().double().cpu().numpy()
        wxyz = model.rotations.detach().double().cpu().numpy()
        R = quat_xyzw_to_matrix(np.concatenate([wxyz[:, 1:], wxyz[:, :1]], axis=1))
        cov = R @ (scales[:, :, None] ** 2 * np.transpose(R, (0, 2, 1)))
        rgb = np.clip(0.5 + SH_C0 * model.sh0[:, 0].detach().double().cpu().numpy(), 0.0, 1.0)
        alpha = model.opacities.detach().double().cpu().numpy()[:, None]
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)
    return Splats(f32(means), f32(cov), f32(rgb), f32(alpha))


def wxyz_of(c2w: np.ndarray) -> np.ndarray:
    """``[4]`` unit quaternion (w, x, y, z) of the rotation of a ``[4, 4]`` camera-to-world pose."""
    x, y, z, w = matrix_to_quat_xyzw(np.asarray(c2w, dtype=np.float64)[:3, :3])
    return np.array([w, x, y, z])


def fov_y(camera: PinholeCamera) -> float:
    """The camera's vertical field of view (radians): ``2 atan(H / (2 fy))``."""
    return 2.0 * math.atan(camera.height / (2.0 * camera.fy))


def scene_depth(centers: np.ndarray, c2w: np.ndarray, default: float = 1.0) -> float:
    """Median depth (scene units, along the optical axis) of the ``[N, 3]`` ``centers`` in front of
    the camera at ``c2w`` ``[4, 4]``; ``default`` when none is."""
    R, t = c2w[:3, :3], c2w[:3, 3]
    z = (np.asarray(centers, dtype=np.float64) - t) @ R[:, 2]
    z = z[np.isfinite(z) & (z > 0)]
    return float(np.median(z)) if z.size else default


@dataclass(frozen=True)
class ViewPose:
    """A camera as viser's controls take it.

    Attributes:
        position: ``[3]`` the camera centre.
        look_at: ``[3]`` the point it orbits, on the optical axis.
        up: ``[3]`` the image's up direction (the camera's -y axis).
        wxyz: ``[4]`` its orientation (camera-to-world rotation, OpenCV axes).
    """

    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    wxyz: np.ndarray


def view_pose(c2w: np.ndarray, distance: float) -> ViewPose:
    """The viewer's camera at the pose ``c2w`` ``[4, 4]``, orbiting the point ``distance`` (scene
    units) ahead of it."""
    c2w = np.asarray(c2w, dtype=np.float64)
    position = c2w[:3, 3].copy()
    return ViewPose(position, position + distance * c2w[:3, 2], -c2w[:3, 1].copy(), wxyz_of(c2w))
