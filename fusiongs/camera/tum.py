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
    m00, m01, m02 = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    m10, m11, m12 = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
    m20, m21, m22 = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
    # Shepperd's method, loop-free: evaluate the four candidates (dividing by 4|w|, 4|x|, 4|y|,
    # 4|z|) and keep the one whose divisor is largest.
    diag = np.stack([m00 + m11 + m22, m00 - m11 - m22, m11 - m00 - m22, m22 - m00 - m11], axis=1)
    s = 2.0 * np.sqrt(np.maximum(1.0 + diag, 1e-300))
    s0, s1, s2, s3 = s.T
    cands = np.stack([
        np.stack([(m21 - m12) / s0, (m02 - m20) / s0, (m10 - m01) / s0, s0 / 4], axis=1),
        np.stack([s1 / 4, (m01 + m10) / s1, (m02 + m20) / s1, (m21 - m12) / s1], axis=1),
        np.stack([(m01 + m10) / s2, s2 / 4, (m12 + m21) / s2, (m02 - m20) / s2], axis=1),
        np.stack([(m02 + m20) / s3, (m12 + m21) / s3, s3 / 4, (m10 - m01) / s3], axis=1),
    ], axis=1)  # [n, 4 candidates, 4]
    out = cands[np.arange(m.shape[0]), np.argmax(diag, axis=1)]
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
            raise InputError(path, f"line {lineno}", "8 numbers 't tx ty tz qx qy qz qw'",
                             repr(line)) from None
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


def write_tum(path: str | Path, poses: PoseSamples, comment: str | None = None) -> None:
    """Write poses as a TUM file (times and values with 9 decimals), atomically.

    Args:
        path: the file; replaced only once it is completely written.
        poses: the samples to write.
        comment: optional text for ``#`` lines above the column header (one per line of text).
    """
    from fusiongs.atomic import write_text

    q = matrix_to_quat_xyzw(poses.c2w[:, :3, :3])
    tr = poses.c2w[:, :3, 3]
    lines = [f"# {c}".rstrip() for c in (comment.splitlines() if comment else [])]
    lines.append("# t tx ty tz qx qy qz qw (camera-to-world, OpenCV axes)")
    for t, p, qq in zip(poses.t, tr, q):
        lines.append(" ".join(f"{v:.9f}" for v in (t, *p, *qq)))
    write_text(path, "\n".join(lines) + "\n")
