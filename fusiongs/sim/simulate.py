"""Simulate a complete scene: blurry frames, events, trajectory and sharp truth from a preset.

Pipeline: preset world + seeded trajectory -> dense linear renders (ray caster) at ``dvs_rate_hz``
-> DVS events (+ leak, background activity, hot pixels); renders at ``blur_samples`` instants per
exposure -> mean -> noise -> 8-bit sRGB frames (or linear 16-bit ones); sharp renders at every
frame's mid-exposure (``deblur_<stem>``) and at held-out instants between exposures
(``novel_<k>``) -> truth. Same config and seed -> identical output.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np
import torch

from fusiongs.camera.pinhole import PinholeCamera, world_to_pixels
from fusiongs.errors import InputError
from fusiongs.events.cfa import check_pattern
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet
from fusiongs.io.scene import RenderRequest, Scene
from fusiongs.sim import dvs
from fusiongs.sim.exposure import add_sensor_noise, blur_frame, encode_linear16, encode_srgb8
from fusiongs.sim.motion import Trajectory, make_trajectory, scale_motion
from fusiongs.sim.presets import Preset, get_preset
from fusiongs.sim.raycast import RayCaster, fov_focal


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a simulated scene (with ``seed``, the output is reproducible).

    Attributes:
        preset: scene preset name (``fusiongs.sim.presets.PRESETS``).
        width, height: sensor size in pixels (frames and events share it).
        duration: length of the recording (s); events and trajectory cover ``[0, duration]``.
        frames: number of blurry frames, centred evenly over the duration.
        exposure: exposure time of each frame (s).
        cfa: ``None`` for a grey event sensor, else the Bayer pattern of a colour event sensor.
        seed: seed of every random choice (shake, thresholds, noise, jitter).
        events_target: if set, the thresholds are scaled (ON/OFF ratio and mismatch kept) so that
            the stream has about this many events.
        novel: number of held-out instants between exposures for novel-view truth.
        dvs: event sensor parameters.
        dvs_rate_hz: render rate for the event model (log intensity is interpolated in between).
        blur_samples: sharp renders averaged per exposure.
        supersample: anti-aliasing samples per pixel along each axis.
        read_noise, shot_gain: frame noise (linear units, variance per unit radiance).
        pose_rate_hz: sampling rate of ``trajectory.txt``.
        device: torch device of the ray caster.
        frame_response: how frames are stored: ``"srgb"`` (8-bit sRGB) or ``"linear"`` (linear
            radiance clipped to [0, 1], 16-bit PNG; ``scene.json`` says ``frame_response: linear``).
        motion_scale: speed factor of the preset's camera path and hand shake, centred on the
            middle of the recording (image velocities and blur scale with it).
    """

    preset: str = "boxes"
    width: int = 173
    height: int = 130
    duration: float = 1.0
    frames: int = 12
    exposure: float = 0.06
    cfa: str | None = None
    seed: int = 0
    events_target: int | None = None
    novel: int = 4
    dvs: dvs.DVSParams = field(default_factory=dvs.DVSParams)
    dvs_rate_hz: float = 1000.0
    blur_samples: int = 48
    supersample: int = 2
    read_noise: float = 0.002
    shot_gain: float = 2e-4
    pose_rate_hz: float = 1000.0
    device: str = "cpu"
    frame_response: str = "srgb"
    motion_scale: float = 1.0

    def validate(self) -> SimConfig:
        """Return ``self`` or raise :class:`InputError` naming the bad field."""
        def need(ok: bool, name: str, expected: str) -> None:
            if not ok:
                raise InputError("simulate", name, expected, repr(getattr(self, name)))
        need(self.width >= 8 and self.height >= 8, "width", "a sensor of at least 8x8 pixels")
        need(self.duration > 0, "duration", "a positive duration in seconds")
        need(self.frames >= 0, "frames", "a non-negative number of frames")
        need(0 < self.exposure <= self.duration / max(self.frames, 1), "exposure",
             "a positive exposure no longer than the frame interval (duration / frames)")
        need(self.novel >= 0, "novel", "a non-negative number of novel views")
        need(self.events_target is None or self.events_target > 0, "events_target", "a positive count")
        need(self.dvs_rate_hz * self.duration >= 2, "dvs_rate_hz", "at least 2 render steps")
        need(self.blur_samples >= 1, "blur_samples", "at least 1")
        need(self.supersample >= 1, "supersample", "at least 1")
        need(self.frame_response in FRAME_RESPONSES, "frame_response", " or ".join(FRAME_RESPONSES))
        need(0 < self.motion_scale <= 10, "motion_scale", "a speed factor in (0, 10]")
        if self.cfa is not None:
            check_pattern(self.cfa, "simulate", "cfa")
        d = self.dvs
        for name, ok, expected in (
                ("theta_on", d.theta_on > 0, "a positive threshold"),
                ("theta_off", d.theta_off > 0, "a positive threshold"),
                ("theta_sigma", d.theta_sigma >= 0, "a non-negative spread"),
                ("theta_min", d.theta_min > 0, "a positive smallest threshold"),
                ("refractory_s", d.refractory_s >= 0, "a non-negative period in s"),
                ("ba_rate_hz", d.ba_rate_hz >= 0, "a non-negative rate"),
                ("hot_pixel_fraction", 0 <= d.hot_pixel_fraction <= 1, "a fraction in [0, 1]"),
                ("hot_pixel_rate_hz", d.hot_pixel_rate_hz >= 0, "a non-negative rate"),
                ("leak_rate_hz", d.leak_rate_hz >= 0, "a non-negative rate"),
                ("leak_spread_decades", d.leak_spread_decades >= 0, "a non-negative spread"),
                ("refractory_reset", isinstance(d.refractory_reset, bool), "true or false")):
            if not ok:
                raise InputError("simulate", f"dvs.{name}", expected, repr(getattr(d, name)))
        return self


FRAME_RESPONSES = ("srgb", "linear")


@dataclass(frozen=True, eq=False)
class SimResult:
    """A simulated scene, its sharp truth (``name -> [H, W, 3]`` float32 sRGB in [0, 1]) and stats."""

    scene: Scene
    gt: dict[str, np.ndarray]
    stats: dict


def frame_windows(cfg: SimConfig) -> tuple[np.ndarray, np.ndarray]:
    """Exposure windows ``t_start [F], t_end [F]`` (s), frames centred at ``(i + 0.5) duration / F``."""
    mid = (np.arange(cfg.frames) + 0.5) * cfg.duration / max(cfg.frames, 1)
    return mid - cfg.exposure / 2, mid + cfg.exposure / 2


def novel_instants(cfg: SimConfig) -> np.ndarray:
    """``[novel]`` held-out instants (s): midpoints of evenly chosen gaps between exposures."""
    if cfg.novel == 0:
        return np.zeros(0)
    if cfg.frames >= 2:
        s, e = frame_windows(cfg)
        gaps = (e[:-1] + s[1:]) / 2
        pick = np.unique(np.round(np.linspace(0, len(gaps) - 1, min(cfg.novel, len(gaps)))).astype(int))
        return gaps[pick]
    return (np.arange(cfg.novel) + 0.5) / cfg.novel * cfg.duration


@dataclass(frozen=True, eq=False)
class SceneRenderer:
    """The camera, the seeded trajectory and the ray caster of a config: ``render(t)`` is the sharp
    ``[H, W, 3]`` linear radiance at instant ``t`` (s)."""

    camera: PinholeCamera
    trajectory: Trajectory
    caster: RayCaster

    def render(self, t: float) -> torch.Tensor:
        return self.caster.render(self.trajectory.c2w(np.array([t]))[0])


def scene_renderer(cfg: SimConfig, preset: Preset | None = None) -> SceneRenderer:
    """The renderer :func:`run_simulation` uses for ``cfg`` (same seeds, so the same images)."""
    preset = preset if preset is not None else get_preset(cfg.preset)
    seeds = np.random.SeedSequence(cfg.seed).spawn(5)
    rng_shake, rng_jitter = np.random.default_rng(seeds[0]), np.random.default_rng(seeds[4])
    f = fov_focal(cfg.width, preset.hfov_deg)
    camera = PinholeCamera(cfg.width, cfg.height, f, f, cfg.width / 2, cfg.height / 2)
    traj = make_trajectory(scale_motion(preset.motion, cfg.motion_scale, cfg.duration), cfg.duration,
                           rng_shake)
    caster = RayCaster(preset.world, camera, cfg.supersample, int(rng_jitter.integers(2**31)), cfg.device)
    return SceneRenderer(camera, traj, caster)


def run_simulation(cfg: SimConfig, preset=None) -> SimResult:
    """Simulate a scene.

    Args:
        cfg: configuration (validated here).
        preset: optional ``fusiongs.sim.presets.Preset`` overriding ``cfg.preset`` (custom worlds).

    Returns:
        a :class:`SimResult`; ``stats`` holds the event counts, the sensor's true parameters
        (``theta_on`` / ``theta_off``: nominal thresholds after any ``events_target`` scaling;
        ``theta_*_pixel_mean``: means of the per-pixel draws; refractory, noise, hot pixels, leak),
        the scene choices (preset, CFA, frame response, exposure, motion scale), timings, the mean
        blur extent in pixels and the whole config.
    """
    cfg.validate()
    t_begin = time.perf_counter()
    scene_r = scene_renderer(cfg, preset)
    camera, traj, caster, render = scene_r.camera, scene_r.trajectory, scene_r.caster, scene_r.render
    # Children 0 and 4 drive shake and jitter (scene_renderer); 5 and 6 were added for hot pixels
    # and leak, so the first five streams, and with them every default scene, are unchanged.
    seeds = np.random.SeedSequence(cfg.seed).spawn(7)
    rng_noise = np.random.default_rng(seeds[3])

    # Events: dense renders -> sensor log intensity -> DVS model.
    n_steps = int(round(cfg.duration * cfg.dvs_rate_hz))
    times = np.linspace(0.0, cfg.duration, n_steps + 1)
    logs = np.empty((n_steps + 1, cfg.width * cfg.height), dtype=np.float32)
    for k, t in enumerate(times):
        logs[k] = dvs.sensor_log(render(float(t)), cfg.cfa, cfg.dvs.eps)
    t_events = time.perf_counter()
    th_on, th_off, drift, phase = sensor_draws(cfg.dvs, logs.shape[1], cfg.width, seeds)
    scale = 1.0
    if cfg.events_target is not None:
        scale = tune_threshold_scale(logs, th_on, th_off, cfg.events_target)

    def events_at(s: float):
        return _pixel_events(logs, times, th_on * s, th_off * s, cfg.dvs.refractory_s, drift, phase, s,
                             cfg.dvs.refractory_reset)

    ev = events_at(scale)
    for _ in range(2 if cfg.events_target is not None else 0):
        # The fast count ignores refractory losses: correct with the real count (~ 1 / scale).
        n = ev[0].size
        if n == 0 or abs(n - cfg.events_target) <= 0.02 * cfg.events_target:
            break
        scale = float(np.clip(scale * n / cfg.events_target, 0.05, 20.0))
        ev = events_at(scale)
    noise, hot = noise_events(cfg.dvs, logs.shape[1], cfg.duration, seeds)
    t_us, pix, pol = dvs.merge_sorted(ev, noise, hot)
    n_pixels = logs.shape[1]
    logs = None  # free the dense log intensities before the frames
    events = EventStream.create(t_us, pix % cfg.width, pix // cfg.width, pol, cfg.width, cfg.height,
                                cfg.cfa, source="simulator")
    t_frames = time.perf_counter()

    # Frames and truth.
    t_start, t_end = frame_windows(cfg)
    imgs, gt, renders = [], {}, []
    names = tuple(f"{i:06d}" for i in range(cfg.frames))
    encode = encode_linear16 if cfg.frame_response == "linear" else encode_srgb8
    for i in range(cfg.frames):
        mean = blur_frame(render, float(t_start[i]), float(t_end[i]), cfg.blur_samples).cpu().numpy()
        imgs.append(encode(add_sensor_noise(mean, cfg.read_noise, cfg.shot_gain, rng_noise)))
        t_mid = float((t_start[i] + t_end[i]) / 2)
        renders.append(RenderRequest(f"deblur_{names[i]}", t_mid))
    for k, t in enumerate(novel_instants(cfg)):
        renders.append(RenderRequest(f"novel_{k:03d}", float(t)))
    for r in renders:
        gt[r.name] = encode_srgb8(render(r.t).cpu().numpy())
    images = np.stack(imgs) if imgs else np.zeros((0, cfg.height, cfg.width, 3), np.float32)
    frames = FrameSet(images, t_start.astype(np.float64), t_end.astype(np.float64), names,
                      cfg.frame_response)
    scene = Scene(camera, events, frames, traj.samples(cfg.pose_rate_hz), tuple(renders), None)
    t_done = time.perf_counter()
    stats = {
        "events": len(events), "events_per_pixel": len(events) / (cfg.width * cfg.height),
        "on_fraction": events.polarity_balance,
        "theta_on": cfg.dvs.theta_on * scale, "theta_off": cfg.dvs.theta_off * scale,
        "theta_sigma": cfg.dvs.theta_sigma * scale, "threshold_scale": scale,
        "theta_on_pixel_mean": float(th_on.mean() * scale),
        "theta_off_pixel_mean": float(th_off.mean() * scale),
        "refractory_s": cfg.dvs.refractory_s, "refractory_reset": cfg.dvs.refractory_reset,
        "ba_rate_hz": cfg.dvs.ba_rate_hz, "hot_pixel_fraction": cfg.dvs.hot_pixel_fraction,
        "hot_pixel_rate_hz": cfg.dvs.hot_pixel_rate_hz,
        "hot_pixels": dvs.hot_pixel_count(cfg.dvs.hot_pixel_fraction, n_pixels),
        "events_hot": int(hot[0].size),
        "events_background": int(noise[0].size), "leak_rate_hz": cfg.dvs.leak_rate_hz,
        "preset": cfg.preset, "cfa": cfg.cfa, "frame_response": cfg.frame_response,
        "exposure": cfg.exposure, "motion_scale": cfg.motion_scale,
        "blur_px": mean_blur_px(caster, traj, camera, t_start, t_end),
        "seconds_event_renders": t_events - t_begin, "seconds_dvs": t_frames - t_events,
        "seconds_frames_truth": t_done - t_frames, "seconds_total": t_done - t_begin,
        "config": {k: v for k, v in asdict(cfg).items()},
    }
    return SimResult(scene, gt, stats)


def sensor_draws(params: dvs.DVSParams, n_pixels: int, width: int, seeds: list[np.random.SeedSequence]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The sensor's per-pixel draws as :func:`run_simulation` makes them: ``(theta_on [P],
    theta_off [P], drift [P] | None, phase [P] | None)`` from the spawned ``seeds`` (children 1:
    thresholds, 6: leak; ``drift`` and ``phase`` of :func:`dvs.leak_drift`, None without leak)."""
    th_on, th_off = dvs.pixel_thresholds(params, n_pixels, np.random.default_rng(seeds[1]), width=width)
    drift = phase = None
    if params.leak_rate_hz > 0:
        drift, phase = dvs.leak_drift(params, th_on, np.random.default_rng(seeds[6]))
    return th_on, th_off, drift, phase


def noise_events(params: dvs.DVSParams, n_pixels: int, duration: float, seeds: list[np.random.SeedSequence]):
    """``(background activity, hot-pixel events)``, each ``(t µs, pixel, p)`` over ``[0, duration]``
    s, as :func:`run_simulation` draws them (seed children 2 and 5)."""
    noise = dvs.background_activity(params.ba_rate_hz, n_pixels, 0.0, duration,
                                    np.random.default_rng(seeds[2]))
    hot = dvs.hot_pixel_events(params.hot_pixel_fraction, params.hot_pixel_rate_hz, n_pixels, 0.0,
                               duration, np.random.default_rng(seeds[5]))
    return noise, hot


def _pixel_events(logs, times, th_on, th_off, refractory_s, drift, phase, scale, reset=False):
    """:func:`dvs.dvs_events` (or :func:`dvs.dvs_events_reset` when ``reset``) with the leak
    (``drift``, ``phase`` of :func:`dvs.leak_drift`, or ``None``) at thresholds scaled by ``scale``."""
    model = dvs.dvs_events_reset if reset else dvs.dvs_events
    if drift is None:
        return model(logs, times, th_on, th_off, refractory_s)
    return model(logs, times, th_on, th_off, refractory_s, drift=drift * scale,
                 ref0=logs[0] - phase * th_on)


def simulate_scene(cfg: SimConfig) -> tuple[Scene, dict[str, np.ndarray]]:
    """Simulate a scene: ``(Scene, gt)`` with ``gt[name]`` a ``[H, W, 3]`` float32 sRGB truth per render."""
    res = run_simulation(cfg)
    return res.scene, res.gt


def tune_threshold_scale(logs: np.ndarray, th_on: np.ndarray, th_off: np.ndarray, target: int,
                         iters: int = 4, tol: float = 0.02) -> float:
    """Factor on the thresholds that gives about ``target`` threshold crossings (count ~ 1/factor).

    Args:
        logs: ``[K + 1, P]`` log intensities. th_on, th_off: ``[P]`` thresholds before scaling.
        target: desired number of events. iters: secant-free fixed-point steps. tol: relative tolerance.

    Returns:
        the scale factor (clamped to [0.05, 20]).
    """
    scale = 1.0
    for _ in range(iters):
        n = dvs.count_events(logs, th_on * scale, th_off * scale)
        if n == 0 or abs(n - target) <= tol * target:
            break
        scale = float(np.clip(scale * n / target, 0.05, 20.0))
    return scale


def mean_blur_px(caster: RayCaster, traj, camera: PinholeCamera, t_start: np.ndarray,
                 t_end: np.ndarray) -> float:
    """Mean image displacement (px) of the scene points seen at mid-exposure, from start to end."""
    if len(t_start) == 0:
        return 0.0
    # Scene points: intersect the pixel-centre rays with the world at mid-exposure.
    vals = []
    for s, e in zip(t_start, t_end):
        P = torch.as_tensor(traj.c2w(np.array([s, (s + e) / 2, e])), dtype=torch.float32)
        pts = caster.surface_points(P[1])
        moved = [world_to_pixels(pts, P[i], camera)[0] for i in (0, 2)]
        d = (moved[0] - moved[1]).norm(dim=1)
        vals.append(float(d[torch.isfinite(d)].mean()))
    return float(np.mean(vals))

