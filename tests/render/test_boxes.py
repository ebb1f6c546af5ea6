"""``sorted_visible``: visible entries grouped by camera, front to back, ties in index order."""

from __future__ import annotations

import torch

from fusiongs.render._boxes import sorted_visible


def _reference(depths, radii):
    """Python lists: per camera, the visible Gaussians sorted by (depth, index)."""
    cams, gids, offsets = [], [], [0]
    for c in range(depths.shape[0]):
        vis = [n for n in range(depths.shape[1]) if int(radii[c, n, 0]) > 0]
        vis.sort(key=lambda n: (float(depths[c, n]), n))
        cams += [c] * len(vis)
        gids += vis
        offsets.append(len(gids))
    return cams, gids, offsets


def test_sorted_visible_matches_a_per_camera_python_sort_with_ties_and_culled_entries():
    g = torch.Generator().manual_seed(5)
    C, N = 3, 400
    depths = torch.rand(C, N, generator=g) * 4
    depths[:, 10:60] = 1.5  # ties: index order
    depths[1, 100:110] = 0.0  # culled entries carry depth 0 in Projected
    radii = (torch.rand(C, N, 2, generator=g) > 0.2).to(torch.int32) * 2
    radii[1, 100:110] = 0
    radii[2] = 0  # a camera that sees nothing
    cam, gid, off = sorted_visible(depths, radii)
    ref = _reference(depths, radii)
    assert cam.tolist() == ref[0]
    assert gid.tolist() == ref[1]
    assert off.tolist() == ref[2]
    assert cam.dtype == gid.dtype == off.dtype == torch.int64
