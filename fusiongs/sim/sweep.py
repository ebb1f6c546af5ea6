"""A seeded sweep over event sensors and scenes, for testing a threshold estimator on sensors it
was not tuned on.

``draw_sensor(seed)`` draws a :class:`DVSParams` from :data:`SENSOR_RANGE`;
``sweep_scene_config(seed, split)`` draws a whole :class:`SimConfig` (preset, CFA, frame
response, exposure, camera speed and sensor) from the seed. Tuning and test scenes come from
disjoint seed ranges (:data:`TUNING_SEEDS`, :data:`TEST_SEEDS`), and a seed used with the wrong
split is refused, so an estimator tuned on the first can be scored on the second honestly.

The thresholds are the drawn ones (``events_target`` stays unset), so the truth is known: the
scene's ``gt/sim.json`` holds them as ``theta_on`` / ``theta_off`` (nominal values), next to the
means of the per-pixel draws and every other drawn parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusiongs.errors import InputError
from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.simulate import SimConfig


@dataclass(frozen=True)
class SensorRange:
    """Ranges of the event sensors of the sweep (each drawn independently per seed).

    Attributes:
        theta: nominal ON and OFF thresholds (log units); ``theta_on`` log-uniform.
        ratio: ``theta_off / theta_on``, log-uniform over the part of this range that keeps
            ``theta_off`` inside ``theta`` (so asymmetric both ways, at most 2x, both in range).
        theta_sigma: per-pixel threshold spread (std, log units), uniform.
        refractory_s: refractory period (s), uniform.
        ba_rate_hz: background activity per pixel (Hz), log-uniform.
        hot_pixel_fraction: fraction of hot pixels, uniform.
        hot_pixel_rate_hz: event rate of a hot pixel (Hz), log-uniform.
        leak_rate_hz: leak-event rate per pixel (Hz), uniform.
    """

    theta: tuple[float, float] = (0.1, 0.6)
    ratio: tuple[float, float] = (0.5, 2.0)
    theta_sigma: tuple[float, float] = (0.0, 0.05)
    refractory_s: tuple[float, float] = (0.0, 1e-3)
    ba_rate_hz: tuple[float, float] = (0.01, 5.0)
    hot_pixel_fraction: tuple[float, float] = (0.0, 1e-3)
    hot_pixel_rate_hz: tuple[float, float] = (50.0, 500.0)
    leak_rate_hz: tuple[float, float] = (0.0, 0.5)


@dataclass(frozen=True)
class SceneRange:
    """Scene choices of the sweep: a 1 s, 12-frame recording at the default sensor size.

    Attributes:
        presets: scene presets, drawn with equal odds.
        cfa: ``None`` (grey sensor) or a Bayer pattern, equal odds.
        frame_response: ``"srgb"`` (8-bit) or ``"linear"`` (16-bit), equal odds.
        exposure: exposure time (s), uniform: with ``motion_scale`` sets the blur.
        motion_scale: camera speed factor, log-uniform (blur from about 1 px to 15 px).
        duration, frames: length (s) and number of frames of every recording.
    """

    presets: tuple[str, ...] = ("boxes", "wall", "corridor", "gallery", "dark", "depth")
    cfa: tuple[str | None, ...] = (None, "RGGB")
    frame_response: tuple[str, ...] = ("srgb", "linear")
    exposure: tuple[float, float] = (0.02, 0.08)
    motion_scale: tuple[float, float] = (0.6, 1.3)
    duration: float = 1.0
    frames: int = 12


SENSOR_RANGE = SensorRange()
SCENE_RANGE = SceneRange()
TUNING_SEEDS = range(0, 1000)
TEST_SEEDS = range(1000, 2000)
SPLITS: dict[str, range] = {"tuning": TUNING_SEEDS, "test": TEST_SEEDS}

_SENSOR_STREAM, _SCENE_STREAM = 1, 2  # independent random streams drawn from one seed


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_sensor(seed: int, ranges: SensorRange = SENSOR_RANGE) -> DVSParams:
    """An event sensor drawn from ``ranges`` (same seed, same sensor).

    ``theta_on`` is log-uniform in ``ranges.theta``; the ratio ``theta_off / theta_on`` is
    log-uniform in ``ranges.ratio`` narrowed to ``[theta_lo / theta_on, theta_hi / theta_on]`` so
    that ``theta_off`` also lies in ``ranges.theta``. Everything else as :class:`SensorRange` says;
    other fields keep their :class:`DVSParams` defaults (``theta_min`` 0.05, no threshold
    gradient).
    """
    rng = np.random.default_rng([int(seed), _SENSOR_STREAM])
    lo, hi = ranges.theta
    theta_on = _log_uniform(rng, lo, hi)
    r_lo, r_hi = max(ranges.ratio[0], lo / theta_on), min(ranges.ratio[1], hi / theta_on)
    theta_off = float(np.clip(theta_on * _log_uniform(rng, r_lo, r_hi), lo, hi))
    return DVSParams(
        theta_on=theta_on, theta_off=theta_off,
        theta_sigma=float(rng.uniform(*ranges.theta_sigma)),
        refractory_s=float(rng.uniform(*ranges.refractory_s)),
        ba_rate_hz=_log_uniform(rng, *ranges.ba_rate_hz),
        hot_pixel_fraction=float(rng.uniform(*ranges.hot_pixel_fraction)),
        hot_pixel_rate_hz=_log_uniform(rng, *ranges.hot_pixel_rate_hz),
        leak_rate_hz=float(rng.uniform(*ranges.leak_rate_hz)),
    )


def check_sweep_seed(seed: int, split: str) -> int:
    """Return ``seed`` if it belongs to ``split`` (``"tuning"`` or ``"test"``), else raise
    :class:`InputError`."""
    if split not in SPLITS:
        raise InputError("sweep", "split", " or ".join(SPLITS), repr(split))
    seeds = SPLITS[split]
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or int(seed) not in seeds:
        raise InputError("sweep", "seed", f"a {split} seed, {seeds.start} to {seeds.stop - 1}", repr(seed))
    return int(seed)


def sweep_scene_config(seed: int, split: str, scenes: SceneRange = SCENE_RANGE,
                       sensors: SensorRange = SENSOR_RANGE) -> SimConfig:
    """The sweep's scene number ``seed``: preset, CFA, frame response, exposure, camera speed and
    sensor (:func:`draw_sensor`), all drawn from ``seed``; the simulation itself is seeded with
    ``seed`` too.

    Args:
        seed: a seed of ``split``.
        split: ``"tuning"`` (:data:`TUNING_SEEDS`) or ``"test"`` (:data:`TEST_SEEDS`).
        scenes, sensors: the ranges (defaults: :data:`SCENE_RANGE`, :data:`SENSOR_RANGE`).

    Returns:
        a validated :class:`SimConfig` (default size, 1 s, 12 frames; ``events_target`` unset).

    Raises:
        InputError: ``split`` unknown or ``seed`` not one of its seeds.
    """
    seed = check_sweep_seed(seed, split)
    rng = np.random.default_rng([seed, _SCENE_STREAM])
    cfg = SimConfig(
        preset=scenes.presets[int(rng.integers(len(scenes.presets)))],
        cfa=scenes.cfa[int(rng.integers(len(scenes.cfa)))],
        frame_response=scenes.frame_response[int(rng.integers(len(scenes.frame_response)))],
        exposure=float(rng.uniform(*scenes.exposure)),
        motion_scale=_log_uniform(rng, *scenes.motion_scale),
        duration=scenes.duration, frames=scenes.frames, seed=seed, dvs=draw_sensor(seed, sensors))
    return cfg.validate()
