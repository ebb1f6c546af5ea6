"""Pixels carried between posed views through a depth map (fusiongs/camera/reproject.py)."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.reproject import identity_grid, pixel_rays, reference_grid

CAM = PinholeCamera(width=12, height=8, fx=10.0, fy=11.0, cx=6.3, cy=3.8)


def _pose(tx: float = 0.0, ty: float = 0.0) -> torch.Tensor:
    c2w = torch.eye(4, dtype=torch.float64)
    c2w[0, 3], c2w[1, 3] = tx, ty
    return c2w


def test_identity_grid_reads_every_pixel_at_its_centre():
    img = torch.arange(CAM.height * CAM.width, dtype=torch.float64).reshape(1, 1, CAM.height, CAM.width)
    read = F.grid_sample(img, identity_grid(CAM)[None], mode="bilinear", align_corners=False)
    torch.testing.assert_close(read, img)
    rays = pixel_rays(CAM)
    assert rays.shape == (8, 12, 3) and torch.allclose(rays[..., 2], torch.ones(8, 12, dtype=torch.float64))


def test_the_same_pose_maps_every_pixel_to_itself_at_any_depth():
    depth = torch.rand(2, CAM.height, CAM.width, dtype=torch.float64) * 5 + 0.5
    valid = torch.ones(2, CAM.height, CAM.width, dtype=torch.bool)
    grid = reference_grid(depth, valid, torch.stack([_pose(), _pose()]), torch.linalg.inv(_pose()), CAM)
    torch.testing.assert_close(grid, identity_grid(CAM).expand(2, -1, -1, -1))


def test_a_sideways_camera_shifts_a_plane_by_focal_times_baseline_over_depth():
    """A view whose camera is 0.2 to the right of the reference sees a plane at depth 2 shifted:
    its pixel u sees what the reference sees at u + fx * 0.2 / 2 (and v unchanged)."""
    depth = torch.full((1, CAM.height, CAM.width), 2.0, dtype=torch.float64)
    valid = torch.ones_like(depth, dtype=torch.bool)
    grid = reference_grid(depth, valid, _pose(tx=0.2)[None], torch.linalg.inv(_pose()), CAM)
    half = torch.tensor([CAM.width / 2, CAM.height / 2], dtype=torch.float64)
    shift_px = (grid - identity_grid(CAM))[0] * half
    np.testing.assert_allclose(shift_px[..., 0].numpy(), 10.0 * 0.2 / 2.0, atol=1e-12)
    np.testing.assert_allclose(shift_px[..., 1].numpy(), 0.0, atol=1e-12)


def test_pixels_without_a_surface_or_behind_the_reference_read_themselves():
    depth = torch.full((1, CAM.height, CAM.width), 2.0, dtype=torch.float64)
    valid = torch.ones_like(depth, dtype=torch.bool)
    valid[0, 0, 0] = False
    grid = reference_grid(depth, valid, _pose(tx=0.2)[None], torch.linalg.inv(_pose()), CAM)
    ident = identity_grid(CAM)
    torch.testing.assert_close(grid[0, 0, 0], ident[0, 0])
    assert not torch.allclose(grid[0, 0, 1], ident[0, 1])
    behind = _pose()
    behind[2, 3] = 5.0  # the reference camera is 5 in front of the view: the plane is behind it
    grid = reference_grid(depth, valid, _pose()[None], torch.linalg.inv(behind), CAM)
    torch.testing.assert_close(grid[0], ident)


def test_the_grid_is_on_the_depth_maps_device():
    depth = torch.full((1, CAM.height, CAM.width), 2.0, device="meta")
    grid = reference_grid(depth, torch.ones(1, CAM.height, CAM.width, dtype=torch.bool, device="meta"),
                          _pose()[None], torch.linalg.inv(_pose()), CAM)
    assert grid.device.type == "meta" and grid.shape == (1, CAM.height, CAM.width, 2)
