"""Renders per exposure that follow the image motion (blur.sample_spacing)."""

from __future__ import annotations

import pytest
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import ConfigError
from fusiongs.train.exposure_samples import derived_samples, exposure_motion_px, samples_for_motion
from fusiongs.train.settings import BlurSettings

CAM = PinholeCamera(width=160, height=120, fx=100.0, fy=100.0, cx=80.0, cy=60.0)


def _slide(dx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Poses at exposure start (the origin) and end (moved by ``dx`` [F] along x), identity rotations."""
    start = torch.eye(4, dtype=torch.float64).repeat(len(dx), 1, 1)
    end = start.clone()
    end[:, 0, 3] = dx
    return start, end


def test_motion_of_a_sideways_slide_is_focal_times_shift_over_depth():
    """A camera sliding 0.1 along x in front of a plane at depth 2 moves every point by
    fx · 0.1 / 2 = 5 px; points behind the camera or outside the image are not counted."""
    g = torch.Generator().manual_seed(0)
    inside = torch.stack([torch.rand(50, generator=g) * 2 - 1, torch.rand(50, generator=g) - 0.5,
                          torch.full((50,), 2.0)], 1).double()
    behind = torch.tensor([[0.0, 0.0, -2.0]], dtype=torch.float64)
    outside = torch.tensor([[50.0, 0.0, 2.0]], dtype=torch.float64)  # projects at x = 2580 px
    start, end = _slide(torch.tensor([0.1, 0.0, -0.2], dtype=torch.float64))
    motion = exposure_motion_px(torch.cat([inside, behind, outside]), start, end, CAM)
    torch.testing.assert_close(motion, torch.tensor([5.0, 0.0, 10.0], dtype=torch.float64))


def test_no_point_seen_gives_no_motion():
    start, end = _slide(torch.tensor([0.1], dtype=torch.float64))
    motion = exposure_motion_px(torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64), start, end, CAM)
    assert float(motion[0]) == 0.0


@pytest.mark.parametrize("motion, want", [(0.0, 5), (3.6, 5), (4.0, 5), (4.01, 7), (5.9, 7), (6.0, 7),
                                          (6.5, 9), (8.0, 9), (11.7, 9), (40.0, 9)])
def test_fewest_odd_renders_within_the_spacing(motion, want):
    assert samples_for_motion(motion, 1.0, 9) == want


def test_spacing_and_bounds():
    assert samples_for_motion(5.9, 2.0, 9) == 5   # 3 px per gap needs 3 renders; at least 5
    assert samples_for_motion(9.0, 0.5, 99) == 19  # 18 gaps of 0.5 px
    assert samples_for_motion(20.0, 1.0, 5) == 5   # at most n_samples
    assert samples_for_motion(20.0, 1.0, 3) == 3   # n_samples under the least: n_samples


def test_derived_samples_use_the_ninetieth_percentile_of_the_exposures():
    """Nine still exposures and one that moves 20 px: the 90 % quantile (2 px) sets N = 5, not the
    one outlier; ten moving ones set N = 9."""
    pts = torch.tensor([[0.0, 0.0, 2.0], [0.3, 0.2, 2.0]], dtype=torch.float64)
    shift = torch.zeros(10, dtype=torch.float64)
    shift[3] = 0.4  # 20 px
    n, motion = derived_samples(pts, *_slide(shift), CAM, 1.0, 9)
    assert n == 5 and motion == pytest.approx(2.0)
    n, motion = derived_samples(pts, *_slide(torch.full((10,), 0.4, dtype=torch.float64)), CAM, 1.0, 9)
    assert n == 9 and motion == pytest.approx(20.0)


def test_negative_spacing_is_refused():
    with pytest.raises(ConfigError, match="blur.sample_spacing"):
        BlurSettings(sample_spacing=-1.0)
