"""``fusiongs calibrate --refine``: the calibration raised to what a frames-only fit's renders say.

The estimator of :mod:`fusiongs.calibrate.estimate` reads the thresholds from the frames and events
alone; where its refractory gate leaves little to fit it can read far low (test scene 1312 at
half the truth). ``deblur`` mends such a start when its events start (``threshold.render_floor``,
:mod:`fusiongs.train.render_threshold`): the model fitted to the frames so far is rendered over
event windows and each θ raised to what the renders' log changes fit to the counts. This module
runs that same warm-up alone (the run's configuration, seed and schedules, stopped at
``events.warmup``) and returns the raised thresholds as a calibration, so that ``fusiongs edi
--calibration`` and other tools can use them. It costs the warm-up's minutes instead of the
estimator's seconds, and it can only raise a θ: a calibration that is too high stays so.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from fusiongs.errors import ConfigError, InputError
from fusiongs.events.thresholds import SensorThresholds
from fusiongs.io.scene import Scene
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.trained import Trained
from fusiongs.train.trainer import check_device, train

REFINED_FILE = "calibration_refined.json"  # deblur's OUT/ copy of the floor-raised θ


def check_refine(scene: Scene, cfg: DeblurConfig, where: str | Path = "scene") -> None:
    """Raise :class:`InputError` / :class:`ConfigError` (one line) where the refinement cannot run:
    fewer than 2 frames (the renders' scale is then not the frames'), no events, or a
    configuration whose warm-up never ends or that has the floor switched off."""
    n = 0 if scene.frames is None else len(scene.frames)
    if n < 2:
        raise InputError(where, "frames", "at least 2 frames (--refine fits the frames first)",
                         f"{n} frame(s)")
    if scene.events is None or len(scene.events) == 0:
        raise InputError(where, "events", "a scene with events (thresholds are measured from them)",
                         "no events")
    if not cfg.events.enabled:
        raise ConfigError("config", "events.enabled", "true for --refine", "false")
    if not cfg.threshold.render_floor:
        raise ConfigError("config", "threshold.render_floor", "true for --refine", "false")
    if not 0 < cfg.events.warmup < cfg.optim.iterations:
        raise ConfigError("config", "events.warmup", f"an iteration between 1 and optim.iterations - 1 "
                          f"({cfg.optim.iterations - 1}) for --refine", str(cfg.events.warmup))


def refine_calibration(scene: Scene, calibration: SensorThresholds, cfg: DeblurConfig,
                       where: str | Path = "scene", log=print) -> SensorThresholds:
    """Train ``cfg``'s warm-up from ``calibration`` and return θ raised to its renders' floor.

    Args:
        scene: the loaded scene (with frames and events; a scene without trajectory or intrinsics
            goes through ``deblur``'s pose stage first).
        calibration: the starting thresholds (:func:`~fusiongs.calibrate.estimate.estimate_thresholds`).
        cfg: the ``deblur`` configuration whose warm-up is run (its seed, schedules and floor).
        where: the scene's name in error messages.
        log: where the pose stage's summary line goes.

    Returns:
        :func:`~fusiongs.train.render_threshold.refined_thresholds` of the floor: the state is the
        one ``fusiongs deblur`` with this calibration and configuration has when its events start.
    """
    from fusiongs.pipeline.poses import needs_pose_stage, run_pose_stage

    check_refine(scene, cfg, where)
    check_device(cfg.device)
    calibration = calibration.for_sensor(scene.events.cfa, str(where))
    with tempfile.TemporaryDirectory(prefix="fusiongs-refine-") as tmp:
        if needs_pose_stage(scene):
            scene, _ = run_pose_stage(scene, cfg, tmp, calibration, log=log)
        tr = train(scene, cfg, Path(tmp), calibration=calibration, until=cfg.events.warmup)
    refined = floor_calibration(tr)
    if refined is None:  # every condition of apply_render_floor is checked above
        raise RuntimeError("the render floor did not run at events.warmup")
    return refined


def floor_calibration(tr: Trained) -> SensorThresholds | None:
    """A run's θ after ``threshold.render_floor`` as a calibration
    (:func:`~fusiongs.train.render_threshold.refined_thresholds`), or None where the floor did not
    run (no events, fewer than 2 frames, switched off, or the run stopped before its events)."""
    from fusiongs.train.render_threshold import refined_thresholds

    if tr.threshold_floor is None or tr.initial_thresholds is None:
        return None
    cfg = tr.config
    return refined_thresholds(tr.initial_thresholds, *tr.threshold_floor, iterations=cfg.events.warmup,
                              windows=cfg.threshold.render_floor_windows,
                              sigma_px=cfg.threshold.render_floor_sigma, seed=cfg.seed)
