"""TUM-style trajectory files: ``t tx ty tz qx qy qz qw`` per line, camera-to-world, OpenCV axes."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusiongs.errors import InputError


@dataclass(frozen=True)
class PoseSamples:
    """Timestamped camera-to-world poses.

    Attributes:
        t: ``[M]`` float64 times in seconds, strictly increasing.
        c2w: ``[M, 4, 4]`` float64 camera-to-world rigid transforms (OpenCV axes: x right, y down,
            z forward).
    """

    t: np.ndarray
    c2w: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])


def quat_xyzw_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``[..., 4]`` (x, y, z, w) to rotation matrices ``[..., 3, 3]``."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    ], axis=-1).reshape(q.shape[:-1] + (3, 3))


def matrix_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` to unit quaternions ``[..., 4]`` (x, y, z, w), w ≥ 0."""
    R = np.asarray(R, dtype=np.float64)
    m = R.reshape(-1, 3, 3)
    out = np.empty((m.shape[0], 4))
    tr = np.trace(m, axis1=1, axis2=2)
    # Shepperd's method: choose the largest of w, x, y, z to divide by.
    cands = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    k = np.argmax(cands, axis=1)
    for i in range(m.shape[0]):
        a = m[i]
        if k[i] == 0:
            s = 2.0 * np.sqrt(max(1.0 + tr[i], 1e-300))
            out[i] = [(a[2, 1] - a[1, 2]) / s, (a[0, 2] - a[2, 0]) / s, (a[1, 0] - a[0, 1]) / s, s / 4]
        elif k[i] == 1:
            s = 2.0 * np.sqrt(max(1.0 + a[0, 0] - a[1, 1] - a[2, 2], 1e-300))
            out[i] = [s / 4, (a[0, 1] + a[1, 0]) / s, (a[0, 2] + a[2, 0]) / s, (a[2, 1] - a[1, 2]) / s]
        elif k[i] == 2:
            s = 2.0 * np.sqrt(max(1.0 + a[1, 1] - a[0, 0] - a[2, 2], 1e-300))
            out[i] = [(a[0, 1] + a[1, 0]) / s, s / 4, (a[1, 2] + a[2, 1]) / s, (a[0, 2] - a[2, 0]) / s]
        else:
            s = 2.0 * np.sqrt(max(1.0 + a[2, 2] - a[0, 0] - a[1, 1], 1e-300))
            out[i] = [(a[0, 2] + a[2, 0]) / s, (a[1, 2] + a[2, 1]) / s, s / 4, (a[1, 0] - a[0, 1]) / s]
    out *= np.where(out[:, 3:4] < 0, -1.0, 1.0)
    return out.reshape(R.shape[:-2] + (4,))


def read_tum(path: str | Path) -> PoseSamples:
    """Read a TUM trajectory file (``#`` comments and blank lines allowed).

    Raises:
        InputError: naming the file and line when a line does not hold 8 finite numbers, a
            quaternion is not of unit norm (tolerance 1e-3), or times are not strictly increasing.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise InputError(path, "trajectory", "a readable TUM text file", e.strerror) from None
    rows, lines = [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        parts = s.replace(",", " ").split()
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            raise InputError(path, f"line {lineno}", "8 numbers 't tx ty tz qx qy qz qw'", repr(line)) from None
        if len(vals) != 8 or not np.all(np.isfinite(vals)):
            raise InputError(path, f"line {lineno}", "8 finite numbers 't tx ty tz qx qy qz qw'", repr(line))
        rows.append(vals)
        lines.append(lineno)
    if not rows:
        raise InputError(path, "trajectory", "at least one pose line", "none")
    a = np.asarray(rows, dtype=np.float64)
    norms = np.linalg.norm(a[:, 4:8], axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
    if bad.size:
        raise InputError(path, f"line {lines[bad[0]]}", "a unit quaternion (qx qy qz qw)",
                         f"norm {norms[bad[0]]:.6g}")
    dec = np.flatnonzero(np.diff(a[:, 0]) <= 0)
    if dec.size:
        raise InputError(path, f"line {lines[dec[0] + 1]}", "strictly increasing times",
                         f"{a[dec[0] + 1, 0]} after {a[dec[0], 0]}")
    c2w = np.tile(np.eye(4), (a.shape[0], 1, 1))
    c2w[:, :3, :3] = quat_xyzw_to_matrix(a[:, 4:8])
    c2w[:, :3, 3] = a[:, 1:4]
    return PoseSamples(t=a[:, 0].copy(), c2w=c2w)


def write_tum(path: str | Path, poses: PoseSamples) -> None:
    """Write poses as a TUM file (times with microsecond precision or better)."""
    q = matrix_to_quat_xyzw(poses.c2w[:, :3, :3])
    tr = poses.c2w[:, :3, 3]
    lines = ["# t tx ty tz qx qy qz qw (camera-to-world, OpenCV axes)"]
    for t, p, qq in zip(poses.t, tr, q):
        lines.append(" ".join(f"{v:.9f}" for v in (t, *p, *qq)))
    Path(path).write_text("\n".join(lines) + "\n")
