"""Distances to the k nearest neighbours of a point cloud (initial Gaussian scales)."""

from __future__ import annotations

import numpy as np
import torch


def knn_distances_reference(xyz: torch.Tensor, k: int = 3, max_elements: int = 1 << 24) -> torch.Tensor:
    """Brute-force distances to the ``k`` nearest other points (``torch.cdist`` in row chunks).

    Args:
        xyz: ``[N, 3]`` points.
        k: neighbours per point; at most ``N - 1`` are returned.
        max_elements: size of one ``[rows, N]`` distance block (memory bound).

    Returns:
        ``[N, min(k, N - 1)]`` distances, ascending, in ``xyz``'s units and dtype.
    """
    n = xyz.shape[0]
    kk = min(k, n - 1)
    rows = max(1, max_elements // max(n, 1))
    out = []
    for start in range(0, n, rows):  # chunks of rows, not a loop over points
        block = torch.cdist(xyz[start:start + rows], xyz)
        idx = torch.arange(start, min(start + rows, n), device=xyz.device)
        block[idx - start, idx] = float("inf")  # exclude the point itself (duplicates stay)
        out.append(torch.topk(block, kk, dim=1, largest=False).values)
    return torch.cat(out) if out else xyz.new_zeros(0, max(kk, 0))


def knn_distances(xyz: torch.Tensor, k: int = 3) -> torch.Tensor:
    """Distances ``[N, min(k, N - 1)]`` to the ``k`` nearest other points.

    Uses scipy's ``cKDTree`` (``O(N log N)``) when scipy is importable, else the brute-force
    :func:`knn_distances_reference`; both return the same values.
    """
    n = xyz.shape[0]
    kk = min(k, n - 1)
    if kk <= 0:
        return xyz.new_zeros(n, 0)
    try:
        from scipy.spatial import cKDTree
    except ImportError:  # pragma: no cover - scipy ships with scikit-image
        return knn_distances_reference(xyz, k)
    pts = xyz.detach().cpu().double().numpy()
    dist, _ = cKDTree(pts).query(pts, k=kk + 1)
    # Column 0 is normally the point itself; with duplicate points it may be a twin (also 0), so
    # drop exactly one zero per row rather than blindly the first column.
    d = np.sort(dist, axis=1)[:, 1:]
    return torch.as_tensor(d, dtype=xyz.dtype, device=xyz.device)
