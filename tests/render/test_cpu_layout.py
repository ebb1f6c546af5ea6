"""``visible_layout`` (the CPU backend's depth order and boxes) against the torch reference."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.render._boxes import pixel_boxes, sorted_visible
from fusiongs.render._cpu_layout import depth_keys, visible_layout


def _case(dtype, seed=0, C=4, N=3000, W=61, H=37):
    g = torch.Generator().manual_seed(seed)
    depths = (torch.rand(C, N, generator=g, dtype=torch.float64) * 20 - 2).to(dtype)  # some negative
    depths[:, 5:80] = 1.25  # ties: index order
    depths[0, 80:90] = 0.0
    depths[0, 90:100] = -0.0  # equals +0: after the +0 entries above, in index order
    depths[1, :50] = torch.tensor([1e-30, 3e38, -3e38, 1e-45, 7.0] * 10, dtype=torch.float64).to(dtype)
    radii = torch.randint(0, 9, (C, N, 2), generator=g, dtype=torch.int32)
    radii[..., 0][radii[..., 0] < 2] = 0  # culled (radius 0 in x)
    radii[3] = 0  # a camera that sees nothing
    means2d = ((torch.rand(C, N, 2, generator=g, dtype=torch.float64) * 1.4 - 0.2)
               * torch.tensor([W, H])).to(dtype)
    means2d[0, :20] = torch.tensor([[0.5, 0.5], [W - 0.5, H - 0.5]] * 10, dtype=dtype)  # on centres
    return depths, radii, means2d, W, H


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("seed", [0, 1])
def test_visible_layout_equals_sorted_visible_and_pixel_boxes(dtype, seed):
    depths, radii, means2d, W, H = _case(dtype, seed)
    cam, gid, off = sorted_visible(depths, radii)
    box = pixel_boxes(means2d[cam, gid], radii[cam, gid], W, H)
    keys, bits = depth_keys(depths.numpy())
    g2, b2, o2 = visible_layout(keys, bits, radii.numpy(), means2d.numpy(), W, H)
    assert np.array_equal(g2, gid.numpy())
    assert np.array_equal(b2, box.numpy())
    assert np.array_equal(o2, off.numpy())
    assert o2[-1] > 0 and o2[4] == o2[3]  # entries exist; the last camera has none


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_depth_keys_sort_like_the_floats(dtype):
    rng = np.random.default_rng(3)
    vals = np.concatenate([rng.normal(0, 10, 500), [0.0, -0.0, np.inf, -np.inf, 1e-300, -1e-300,
                                                     np.finfo(dtype).max, -np.finfo(dtype).max]])
    d = vals.astype(dtype)[None]
    keys, _ = depth_keys(d)
    order = np.argsort(keys[0], kind="stable")
    ref = np.argsort(d[0] + dtype(0.0), kind="stable")  # numpy: -0 == +0, ties in index order
    assert np.array_equal(order, ref)
