"""A closed-form scene of any size: a textured plane seen by a translating camera, with its events
written chunk by chunk (the memory benchmarks' 1e8-event scenes; tiny ones for tests).

The world is a plane at depth ``Z`` carrying the log texture ``c + a sin(kx X + ky Y)``; the camera
translates along x at a constant speed, so every pixel's log intensity is a sinusoid in time,
``L(t) = c + a sin(phi(x, y) + omega t)``, with the same period ``T`` everywhere. Events are the
crossings of the levels ``theta * m`` (an ON event when ``L`` crosses a level upward, OFF
downward; EDI's model: the signed count between two instants is the change of ``L`` in units of
``theta``, quantised). Their times within one period are solved in closed form (``asin``), sorted
once, and every later period is the same list shifted by ``n T``, so ``1e8`` events are written
with one period (about ``2 levels`` events per pixel) in memory. Blurry frames are the exposure
means of ``exp(L)`` (16 instants) as 8-bit sRGB; the trajectory is exact. The scene follows
``docs/scene-format.md``, so every verb reads it like any other scene.

    python -m fusiongs.sim.plane_wave OUT --events 1e8 [--size 1280x720] [--duration 10]
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from fusiongs.atomic import atomic_path, write_text
from fusiongs.errors import InputError
from fusiongs.frames.image_io import write_png
from fusiongs.frames.response import linear_to_srgb


@dataclass(frozen=True)
class PlaneWave:
    """Geometry and sensor of :func:`write_plane_wave_scene` (sizes in pixels, times in seconds).

    ``events`` sets the texture speed: one period of the sinusoid yields ``2 * levels`` events per
    pixel (``levels`` about ``2 a / theta``), and the recording holds ``duration / T`` periods.
    """

    events: int = 100_000_000
    width: int = 1280
    height: int = 720
    duration: float = 10.0
    frames: int = 10
    exposure: float = 0.04
    theta: float = 0.2
    c: float = math.log(0.2)
    a: float = 1.0
    amplitude_spread: float = 0.6
    wavelength_x: float = 48.0  # texture period along x, pixels
    wavelength_y: float = 96.0  # and along y
    depth: float = 2.0
    focal: float = 1000.0

    def __post_init__(self) -> None:
        for name in ("events", "width", "height", "frames"):
            if int(getattr(self, name)) < 1:
                raise InputError("plane_wave", name, "a positive integer", getattr(self, name))
        for name in ("duration", "exposure", "theta", "a", "depth", "focal"):
            if not getattr(self, name) > 0:
                raise InputError("plane_wave", name, "a positive number", getattr(self, name))
        if not 0 <= self.amplitude_spread < 1:
            raise InputError("plane_wave", "amplitude_spread", "a number in [0, 1)", self.amplitude_spread)


def amplitude(s: PlaneWave) -> np.ndarray:
    """``[H]`` texture amplitude of every row (log units): ``a (1 + spread sin(2 pi y / 67))``.

    It varies along y only, the axis the camera does not move along, so every pixel still sees a
    periodic signal; different amplitudes give different event rates and interval floors, as the
    pixels of a real scene have."""
    y = np.arange(s.height, dtype=np.float64)
    return s.a * (1.0 + s.amplitude_spread * np.sin(2 * np.pi * y / 67.0))


def _levels(s: PlaneWave) -> np.ndarray:
    """Level indices ``m`` with ``theta m`` strictly inside ``(c - a_max, c + a_max)``."""
    a = float(amplitude(s).max())
    lo = math.floor((s.c - a) / s.theta) + 1
    hi = math.ceil((s.c + a) / s.theta) - 1
    return np.arange(lo, hi + 1)


def _crossing(s: PlaneWave, m: int) -> np.ndarray:
    """``[H]`` sine value of level ``m`` per row (NaN where the row's amplitude does not reach it)."""
    v = (s.theta * m - s.c) / amplitude(s)
    return np.where(np.abs(v) < 1, v, np.nan)


@lru_cache(maxsize=4)
def period_s(s: PlaneWave) -> float:
    """Period ``T`` (s) that puts ``s.events`` events into ``s.duration``."""
    per_row = sum(np.isfinite(_crossing(s, m)).sum() for m in _levels(s))
    per_period = 2 * int(per_row) * s.width
    return s.duration * per_period / s.events


@lru_cache(maxsize=4)
def phase(s: PlaneWave) -> np.ndarray:
    """``[H, W]`` texture phase of every pixel at ``t = 0``."""
    y, x = np.mgrid[0:s.height, 0:s.width].astype(np.float64)
    ph = 2 * np.pi * (x / s.wavelength_x + y / s.wavelength_y)
    ph.flags.writeable = False  # cached: shared by every call
    return ph


def one_period(s: PlaneWave) -> tuple[np.ndarray, ...]:
    """Events of ``[0, T)``, time-sorted: ``(t seconds float64, x uint16, y uint16, p int8)``."""
    omega = 2 * np.pi / period_s(s)
    ph = phase(s)
    ys, xs = np.mgrid[0:s.height, 0:s.width]
    ts, xo, yo, po = [], [], [], []
    for m in _levels(s):
        row = _crossing(s, m)
        ok = np.isfinite(row)
        u = np.arcsin(row[ok])[:, None]
        for root, pol in ((u, 1), (np.pi - u, -1)):  # rising branch: ON; falling: OFF
            ts.append((np.mod(root - ph[ok], 2 * np.pi) / omega).reshape(-1))
            xo.append(xs[ok].reshape(-1))
            yo.append(ys[ok].reshape(-1))
            po.append(np.full(ts[-1].size, pol, np.int8))
    t = np.concatenate(ts)
    order = np.argsort(t, kind="stable")
    return (t[order], np.concatenate(xo)[order].astype(np.uint16),
            np.concatenate(yo)[order].astype(np.uint16), np.concatenate(po)[order])


def log_intensity(s: PlaneWave, t: float) -> np.ndarray:
    """``[H, W]`` log intensity at ``t`` (s)."""
    return s.c + amplitude(s)[:, None] * np.sin(phase(s) + 2 * np.pi * t / period_s(s))


def write_events(s: PlaneWave, path: Path) -> int:
    """Write ``events.h5`` period by period (chunked datasets); returns the number written."""
    import h5py

    t0, x0, y0, p0 = one_period(s)
    T = period_s(s)
    n_written = 0
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        g = f.create_group("events")
        dsets = {k: g.create_dataset(k, (0,), dtype=dt, maxshape=(None,), chunks=(1 << 20,))
                 for k, dt in (("t", np.int64), ("x", np.uint16), ("y", np.uint16), ("p", np.int8))}
        g.attrs["width"], g.attrs["height"] = np.int64(s.width), np.int64(s.height)
        n = 0
        while n * T < s.duration:
            t_us = np.round((t0 + n * T) * 1e6).astype(np.int64)
            keep = t_us < int(round(s.duration * 1e6))
            for k, v in (("t", t_us), ("x", x0), ("y", y0), ("p", p0)):
                d = dsets[k]
                d.resize((n_written + int(keep.sum()),))
                d[n_written:] = v[keep]
            n_written += int(keep.sum())
            n += 1
    return n_written


def write_plane_wave_scene(s: PlaneWave, out: Path) -> dict:
    """Write the scene folder ``out`` (scene.json, events.h5, frames/, trajectory.txt)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "frames").mkdir(exist_ok=True)
    n = write_events(s, out / "events.h5")
    mids = (np.arange(s.frames) + 0.5) * s.duration / s.frames
    frames = []
    for i, tm in enumerate(mids):
        ts, te = tm - s.exposure / 2, tm + s.exposure / 2
        lin = np.mean([np.exp(log_intensity(s, t)) for t in np.linspace(ts, te, 16)], axis=0)
        img = np.repeat(linear_to_srgb(np.clip(lin, 0, 1))[..., None], 3, axis=-1)
        write_png(out / "frames" / f"{i:06d}.png", img, bits=8)
        frames.append({"path": f"frames/{i:06d}.png", "t_start": float(ts), "t_end": float(te)})
    # Image shift omega / kx (pixels per second) from a camera moving by v = shift * Z / f.
    speed_px = s.wavelength_x / period_s(s)
    v = speed_px * s.depth / s.focal
    times = np.linspace(0.0, s.duration, int(s.duration * 100) + 1)
    lines = [f"{t:.6f} {v * t:.9f} 0 0 0 0 0 1" for t in times]
    write_text(out / "trajectory.txt", "# t tx ty tz qx qy qz qw\n" + "\n".join(lines) + "\n")
    doc = {"format": "fusiongs-scene", "version": 1,
           "camera": {"width": s.width, "height": s.height, "fx": s.focal, "fy": s.focal,
                      "cx": s.width / 2, "cy": s.height / 2},
           "events": {"path": "events.h5", "cfa": None}, "frames": frames,
           "trajectory": "trajectory.txt", "frame_response": "srgb"}
    write_text(out / "scene.json", json.dumps(doc, indent=1))
    return {"events": n, "period_s": period_s(s), "theta": s.theta}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--events", type=float, default=1e8)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--duration", type=float, default=10.0)
    a = ap.parse_args()
    try:
        w, h = (int(v) for v in a.size.lower().split("x"))
    except ValueError:
        ap.error(f"--size: expected WIDTHxHEIGHT in pixels, got {a.size!r}")
    if (a.out / "scene.json").exists():
        ap.error(f"{a.out}: a scene is already there (scene.json); choose a new folder")
    try:
        pw = PlaneWave(events=int(a.events), width=w, height=h, duration=a.duration)
    except InputError as e:
        ap.error(str(e))
    print(write_plane_wave_scene(pw, a.out))


if __name__ == "__main__":
    main()
