"""How a 3DGS viewer draws a Gaussian PLY, written densely in NumPy (tests only; slow, plain).

Independent of fusiongs' rasteriser: it reads the file's stored values and composites them the
way the Inria 3DGS renderer and the viewers built on it do (Kerbl et al. 2023): display colour
``max(0.5 + SH_C0 f_dc, 0)``, opacity ``sigmoid``, scale ``exp``, rotation a wxyz quaternion;
EWA projection with a 0.3 px² low-pass, Gaussians sorted by camera depth and composited front to
back over a black background (alpha capped at 0.99, skipped under 1/255, stopped when the
transmittance would fall under 1e-4), the result clipped to [0, 1]. Every pixel meets every
Gaussian (in blocks of Gaussians, so memory stays bounded). Only the DC colour is drawn: the
file must hold no ``f_rest`` values other than zero.
"""

from __future__ import annotations

import numpy as np

SH_C0 = 0.28209479177387814


def read_vertices(path) -> dict[str, np.ndarray]:
    """The ``vertex`` properties of a binary little-endian PLY as float64 arrays, by name."""
    raw = open(path, "rb").read()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    names, n = [], 0
    for line in raw[:end].decode("ascii").splitlines():
        parts = line.split()
        if parts[:2] == ["element", "vertex"]:
            n = int(parts[2])
        elif parts[:1] == ["property"]:
            assert parts[1] == "float", line
            names.append(parts[2])
    rec = np.frombuffer(raw, dtype=[(nm, "<f4") for nm in names], count=n, offset=end)
    return {nm: rec[nm].astype(np.float64) for nm in names}


def _rotations(q: np.ndarray) -> np.ndarray:
    """``[N, 3, 3]`` rotation matrices of wxyz quaternions ``[N, 4]`` (any norm)."""
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)


def render_viewer(vertices: dict[str, np.ndarray], w2c: np.ndarray, K: np.ndarray, width: int, height: int,
                  block: int = 256) -> np.ndarray:
    """One view of a PLY's Gaussians as a viewer shows it.

    Args:
        vertices: :func:`read_vertices` of the file.
        w2c: ``[4, 4]`` world-to-camera transform (OpenCV axes: x right, y down, z forward).
        K: ``[3, 3]`` intrinsics in pixels (pixel centres at +0.5).
        width, height: image size (px).
        block: Gaussians composited at a time.

    Returns:
        ``[H, W, 3]`` float64 display values in [0, 1].
    """
    v = vertices
    rest = [k for k in v if k.startswith("f_rest_")]
    assert all(np.all(v[k] == 0) for k in rest), "the reference draws the DC colour only"
    mean = np.stack([v["x"], v["y"], v["z"]], 1)
    colour = np.maximum(0.5 + SH_C0 * np.stack([v[f"f_dc_{c}"] for c in range(3)], 1), 0.0)
    opacity = 1.0 / (1.0 + np.exp(-v["opacity"]))
    scale = np.exp(np.stack([v[f"scale_{c}"] for c in range(3)], 1))
    rot = _rotations(np.stack([v[f"rot_{c}"] for c in range(4)], 1))
    cov = rot @ (scale[:, :, None] ** 2 * np.transpose(rot, (0, 2, 1)))
    R, t = w2c[:3, :3], w2c[:3, 3]
    p = mean @ R.T + t
    keep = p[:, 2] > 0.01
    p, cov, colour, opacity = p[keep], cov[keep], colour[keep], opacity[keep]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    lim_x, lim_y = 1.3 * 0.5 * width / fx, 1.3 * 0.5 * height / fy
    z = p[:, 2]
    tx = np.clip(p[:, 0] / z, -lim_x, lim_x) * z
    ty = np.clip(p[:, 1] / z, -lim_y, lim_y) * z
    J = np.zeros((z.size, 2, 3))
    J[:, 0, 0], J[:, 0, 2] = fx / z, -fx * tx / z ** 2
    J[:, 1, 1], J[:, 1, 2] = fy / z, -fy * ty / z ** 2
    cov_cam = R @ cov @ R.T
    cov2 = J @ cov_cam @ np.transpose(J, (0, 2, 1)) + 0.3 * np.eye(2)
    det = cov2[:, 0, 0] * cov2[:, 1, 1] - cov2[:, 0, 1] ** 2
    conic = np.stack([cov2[:, 1, 1], -cov2[:, 0, 1], cov2[:, 0, 0]], 1) / det[:, None]
    centre = np.stack([fx * p[:, 0] / z + cx, fy * p[:, 1] / z + cy], 1)
    order = np.argsort(z, kind="stable")
    ys, xs = np.meshgrid(np.arange(height) + 0.5, np.arange(width) + 0.5, indexing="ij")
    px, py = xs.reshape(-1), ys.reshape(-1)
    image = np.zeros((px.size, 3))
    T = np.ones(px.size)
    done = np.zeros(px.size, bool)
    for lo in range(0, order.size, block):
        idx = order[lo:lo + block]
        dx, dy = px[None] - centre[idx, 0:1], py[None] - centre[idx, 1:2]
        a, b, c = (conic[idx, k:k + 1] for k in range(3))
        power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
        alpha = np.minimum(0.99, opacity[idx, None] * np.exp(np.minimum(power, 0.0)))
        alpha = np.where((power <= 0) & (alpha >= 1 / 255), alpha, 0.0)  # [G, P]
        before = T[None] * np.concatenate([np.ones((1, px.size)), np.cumprod(1 - alpha, 0)[:-1]], 0)
        stop = np.logical_or.accumulate(before * (1 - alpha) < 1e-4, axis=0) | done[None]
        w = np.where(stop, 0.0, alpha * before)
        image += w.T @ colour[idx]
        last = np.where(stop, 1.0, 1 - alpha).prod(0)
        T = T * last
        done = done | stop[-1]
    return np.clip(image.reshape(height, width, 3), 0.0, 1.0)
