"""Camera motion for the simulator: a smooth arc/dolly toward a look-at point plus hand shake.

The smooth part moves the eye along an arc around ``target`` (azimuth and radius change linearly
in time, height follows a half sine) and always looks at ``target``. Hand shake is a sum of a few
seeded sinusoids (2-14 Hz) on the position and on a small rotation vector applied in the camera
frame. Poses are camera-to-world, OpenCV axes (x right, y down, z forward).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fusiongs.camera.tum import PoseSamples
from fusiongs.sim.raycast import look_at


@dataclass(frozen=True)
class Motion:
    """Parameters of a camera path (its smooth part runs from start to end values in ``period`` s).

    Attributes:
        target: look-at point (m).
        radius: distance eye-target at the start and the end (m): a dolly when they differ.
        azimuth_deg: arc angle around the vertical axis at start and end (0 = eye on the -z side).
        height: eye height offset relative to the target (m, y down) at start and end.
        bob: amplitude (m) of a half-sine vertical bob over the path.
        target_shift: displacement (m) of the look-at point, and with it the whole arc, from
            start to end.
        look_shift: displacement (m) of the look-at point alone (the eye does not follow): turns
            the camera while it moves.
        shake_pos: hand-shake translation amplitude (m, per axis, sum of the sinusoids).
        shake_rot_deg: hand-shake rotation amplitude (degrees, per axis).
        shake_hz: frequency range of the shake sinusoids.
        period: seconds the path from start to end values takes (speed does not depend on the
            recording's duration; longer recordings continue along the same arc).
        start: path position at ``t = 0`` in units of the path (0 = start values, 1 = end values).
    """

    target: tuple[float, float, float] = (0.0, 0.0, 4.0)
    radius: tuple[float, float] = (4.0, 4.0)
    azimuth_deg: tuple[float, float] = (-10.0, 10.0)
    height: tuple[float, float] = (-0.3, -0.3)
    bob: float = 0.0
    target_shift: tuple[float, float, float] = (0.0, 0.0, 0.0)
    look_shift: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shake_pos: float = 0.004
    shake_rot_deg: float = 0.3
    shake_hz: tuple[float, float] = (2.0, 14.0)
    period: float = 1.0
    start: float = 0.0


def scale_motion(motion: Motion, factor: float, duration: float) -> Motion:
    """The same path travelled ``factor`` times as fast, centred on the middle of the recording,
    with the hand shake ``factor`` times as strong: every image velocity (and so the blur of a
    fixed exposure) scales by ``factor``.

    Args:
        motion: the preset's motion. factor: speed factor (> 0; 1 returns ``motion`` unchanged).
        duration: recording length (s); the path position at ``duration / 2`` does not change.
    """
    if factor == 1.0:
        return motion
    start = motion.start + (1.0 - factor) * duration / (2.0 * motion.period)
    return replace(motion, period=motion.period / factor, start=start,
                   shake_pos=motion.shake_pos * factor, shake_rot_deg=motion.shake_rot_deg * factor)


@dataclass(frozen=True)
class Trajectory:
    """A ``Motion`` over a duration with its seeded shake: evaluates poses at any instant.

    Build with :func:`make_trajectory`.
    """

    motion: Motion
    duration: float
    shake_freq: np.ndarray  # [6, K] Hz (3 translation axes, 3 rotation axes)
    shake_phase: np.ndarray  # [6, K] rad
    shake_amp: np.ndarray  # [6, K] weights summing to 1 per axis

    def c2w(self, t: np.ndarray) -> np.ndarray:
        """Camera-to-world poses ``[M, 4, 4]`` float64 at times ``t [M]`` (s)."""
        m, t = self.motion, np.atleast_1d(np.asarray(t, dtype=np.float64))
        s = t / m.period + m.start
        az = np.radians(m.azimuth_deg[0] + (m.azimuth_deg[1] - m.azimuth_deg[0]) * s)
        r = m.radius[0] + (m.radius[1] - m.radius[0]) * s
        h = m.height[0] + (m.height[1] - m.height[0]) * s - m.bob * np.sin(np.pi * s)
        target = np.asarray(m.target) + np.outer(s, m.target_shift)
        eye = target + np.stack([r * np.sin(az), h, -r * np.cos(az)], axis=1)
        wave = (self.shake_amp[None] * np.sin(2 * np.pi * self.shake_freq[None] * t[:, None, None]
                                              + self.shake_phase[None])).sum(-1)  # [M, 6]
        eye = eye + m.shake_pos * wave[:, :3]
        shake_R = rotvec_to_matrix(np.radians(m.shake_rot_deg) * wave[:, 3:])
        R = look_at(eye, target + np.outer(s, m.look_shift)) @ shake_R
        out = np.tile(np.eye(4), (t.shape[0], 1, 1))
        out[:, :3, :3], out[:, :3, 3] = R, eye
        return out

    def samples(self, rate_hz: float = 1000.0) -> PoseSamples:
        """Dense poses over ``[0, duration]`` for ``trajectory.txt`` (``rate_hz`` samples per second)."""
        n = max(2, int(round(self.duration * rate_hz)) + 1)
        t = np.linspace(0.0, self.duration, n)
        return PoseSamples(t=t, c2w=self.c2w(t))


def make_trajectory(motion: Motion, duration: float, rng: np.random.Generator,
                    n_waves: int = 3) -> Trajectory:
    """Draw the hand-shake sinusoids of a ``Motion`` from ``rng`` (seeded) for a ``duration`` (s)."""
    lo, hi = motion.shake_hz
    freq = rng.uniform(lo, hi, size=(6, n_waves))
    phase = rng.uniform(0, 2 * np.pi, size=(6, n_waves))
    amp = rng.uniform(0.5, 1.0, size=(6, n_waves))
    return Trajectory(motion, float(duration), freq, phase, amp / amp.sum(1, keepdims=True))


def rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: rotation vectors ``[..., 3]`` (rad) to matrices ``[..., 3, 3]``."""
    w = np.asarray(w, dtype=np.float64)
    th = np.linalg.norm(w, axis=-1, keepdims=True)
    k = w / np.where(th > 1e-12, th, 1.0)
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K = K - np.swapaxes(K, -1, -2)
    th = th[..., None]
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * (K @ K)
