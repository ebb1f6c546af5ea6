"""The pose stage of ``fusiongs deblur`` (docs/method.md §6): when a scene has no trajectory or no
intrinsics, EDI-deblur its frames and register them with pycolmap
(:func:`fusiongs.sfm.register.estimate_camera_and_trajectory`); a scene with fewer than
two frames registers images made from its events instead (:func:`event_instants`).

Outputs beside the run: ``trajectory_initial.txt`` (TUM, docs/scene-format.md: the poses training starts
from) and ``camera.json`` (the intrinsics, which of camera and trajectory were estimated, and the
registration report). ``--resume`` reads them back instead of estimating again; the refined path
that training ends with is ``trajectory.txt`` (:mod:`fusiongs.outputs.write`), which a resumed run
must not start from (its checkpoint corrects the initial poses).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError
from fusiongs.io.scene import Scene
from fusiongs.sfm.options import PoseOptions
from fusiongs.sfm.register import PoseEstimate, estimate_camera_and_trajectory
from fusiongs.train.state import EVENT_ONLY_VIEWS

if TYPE_CHECKING:
    from fusiongs.events.thresholds import SensorThresholds
    from fusiongs.train.settings import DeblurConfig

CAMERA_FILE = "camera.json"
TRAJECTORY_FILE = "trajectory_initial.txt"  # not trajectory.txt: that is the refined path
PAD_S = 1e-6  # poses reach 1 µs beyond the exposures, so rounding in trajectory.txt keeps them inside


@dataclass(frozen=True)
class PoseStageResult:
    """What :func:`estimate_scene_poses` gives the trainer.

    Attributes:
        scene: the input scene with the estimated camera and/or poses (given ones are kept).
        estimate: the pose estimate (camera, poses, report, sparse points).
        thresholds: the event thresholds the EDI images were made with (``None`` without events).
        source: what was registered, for the log (``"EDI at mid-exposure"``, ...).
    """

    scene: Scene
    estimate: PoseEstimate
    thresholds: SensorThresholds | None
    source: str


def needs_pose_stage(scene: Scene) -> bool:
    """Whether the scene lacks its trajectory or its intrinsics."""
    return scene.poses is None or not scene.camera.intrinsics_known


def stage_thresholds(scene: Scene, calibration: SensorThresholds | None = None, estimate: bool = True,
                     init: float = 0.2) -> SensorThresholds | None:
    """Starting thresholds as the trainer picks them (``calibration``, else the estimate of
    ``fusiongs calibrate`` when ``estimate``, else ``init``); ``None`` without events."""
    from fusiongs.events.thresholds import SensorThresholds

    if scene.events is None or not len(scene.events):
        return None
    cfa = scene.events.cfa
    if calibration is not None:
        return calibration.for_sensor(cfa)
    if estimate and len(scene.frames):
        from fusiongs.calibrate.estimate import estimate_thresholds
        from fusiongs.calibrate.options import CalibrateOptions

        try:
            return estimate_thresholds(scene.frames, scene.events,
                                       CalibrateOptions(unknown_scale=init)).for_sensor(cfa)
        except InputError:  # too little data to measure them: the trainer says so later
            pass
    return SensorThresholds.uniform(init, init, cfa, "threshold.init")


def edi_instants(scene: Scene, theta, per_exposure: int = 1
                 ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Sharp linear images at ``per_exposure`` evenly spaced instants of every exposure.

    EDI (Pan et al., CVPR 2019) gives the mid-exposure image ``L(t_mid)``; the other instants follow
    from the events, ``L(t) = L(t_mid) exp(theta E(t))``. Without events, the blurry frames
    themselves at mid-exposure.

    Returns:
        ``(images [F K, H, W, C] float32, times [F K] s, names)``; names are the frame names, with
        ``@k`` appended when ``per_exposure > 1``.
    """
    from fusiongs.edi import edi_deblur, edi_ratio, event_count_samples

    fs = scene.frames
    lin = fs.to_linear()
    if scene.events is None or not len(scene.events) or theta is None:
        return lin.astype(np.float32), fs.mid_times(), list(fs.names)
    k = max(int(per_exposure), 1)
    images, times, names = [], [], []
    for i, name in enumerate(fs.names):
        t0, t1 = float(fs.t_start[i]), float(fs.t_end[i])
        mid = edi_deblur(lin[i], scene.events, t0, t1, theta)
        if k == 1:
            images.append(mid)
            times.append(0.5 * (t0 + t1))
            names.append(name)
            continue
        counts = event_count_samples(scene.events, t0, t1, k)
        for j in range(k):
            images.append((mid * edi_ratio(counts[j:j + 1], theta, scene.events.cfa)).astype(np.float32))
            times.append(t0 + (j + 0.5) / k * (t1 - t0))
            names.append(f"{name}@{j}")
    return np.stack(images), np.asarray(times), names


def event_instants(scene: Scene, n: int, tau: float, theta0: float
                   ) -> tuple[np.ndarray, np.ndarray, list[str], tuple[float, float]]:
    """Images made from the events alone, for a scene without two frames to register.

    ``0.5 · exp(V)`` of the leaky-integrator (high-pass) image ``V`` of the events (Scheerlinck et
    al., ACCV 2018; :func:`fusiongs.train.data.event_stereo_images`) at ``n`` instants spread over
    the recording: the last at its end, the first ``min(2 tau, span / 2n)`` after its start (where
    nothing has fired yet). Moving edges leave the same trail in nearby views, which is what SIFT
    matches; a pixel that has not fired lately stays at 0.5.

    Returns:
        ``(images [n, H, W, 1] float32 in [0, 1], times [n] s, names, t_range)``: ``t_range`` is the
        events' span, which the poses must cover.
    """
    from fusiongs.train.data import even_instants, event_stereo_images

    ev = scene.events
    t0, t1 = float(ev.t[0]) * 1e-6, float(ev.t[-1]) * 1e-6
    first = t0 + min(2.0 * tau, 0.5 * (t1 - t0) / max(n, 1))
    images = event_stereo_images(ev, (first, t1), n, tau, theta0, ev.cfa is not None).numpy()
    times = even_instants((first, t1), n)
    return images, times, [f"events@{t:.4f}s" for t in times], (t0, t1)


def estimate_scene_poses(scene: Scene, *, thresholds=None, per_exposure: int = 1,
                         options: PoseOptions | None = None, work_dir: str | Path | None = None,
                         event_views: int = 16, event_tau: float = 0.05,
                         event_theta: float = 0.2) -> PoseStageResult:
    """EDI images of the frames, registered by pycolmap: the scene's missing camera and/or poses.

    Args:
        scene: a scene with frames (events make the images sharp; without them the blurry frames
            are registered, which is less reliable), or, with fewer than two frames, with events:
            then ``event_views`` images of the events (:func:`event_instants`, time constant
            ``event_tau`` s, contrast ``event_theta``) are registered instead.
        thresholds: event thresholds for EDI (:func:`stage_thresholds`); ``None`` estimates them.
        per_exposure: instants registered per exposure (more views, more time).
        options: :class:`~fusiongs.sfm.options.PoseOptions` (default: its defaults
            with ``no_parallax``: a camera on a tripod or one that only turns gets a static or
            rotation-only path instead of an error).
        work_dir: where COLMAP works (default a temporary folder).

    Raises:
        InputError: a scene with neither two frames nor events, or too few registered images (one
            line naming the counts and how to supply a trajectory or the intrinsics instead).
    """
    fs = scene.frames
    has_events = scene.events is not None and len(scene.events) > 0
    options = options or PoseOptions(no_parallax=True)
    if len(fs) < 2:
        if not has_events:
            raise InputError("pose estimation", "frames", "two frames or events to estimate the camera "
                             "path from (else a trajectory file and the intrinsics)",
                             f"{len(fs)} frame(s) and no events")
        images, times, names, (t0, t1) = event_instants(scene, event_views, event_tau, event_theta)
        source = f"event images at {len(times)} instants (leaky integrator, tau {event_tau:g} s)"
        # half of them at least: on real recordings a few registered event images were no sign
        # of a right path (eslnet_cups: 3 of 16, 4° RMS and 2/3 of the path's extent off the frames'
        # poses; benchmarks/RESULTS.md), and the rest would only be interpolated
        options = dataclasses.replace(options, min_registered=max(3, -(-len(times) // 2)))
        if len(fs):  # one frame: its exposure is inside the poses too
            t0, t1 = min(t0, float(fs.t_start[0])), max(t1, float(fs.t_end[-1]))
    else:
        if thresholds is None:
            thresholds = stage_thresholds(scene)
        images, times, names = edi_instants(scene, thresholds, per_exposure)
        source = ("blurry frames (no events)" if not has_events else "EDI at mid-exposure"
                  if per_exposure <= 1 else f"EDI at {per_exposure} instants per exposure")
        t0, t1 = float(fs.t_start[0]), float(fs.t_end[-1])
    try:
        est = estimate_camera_and_trajectory(scene.camera, images, times, names,
                                             t_range=(t0 - PAD_S, t1 + PAD_S),
                                             options=options, work_dir=work_dir)
    except InputError as e:
        if e.field != "frames" or len(fs) >= 2:
            raise
        raise InputError(e.where, "events", f"{e.expected} (the {source})", e.got) from None
    poses = scene.poses if scene.poses is not None else est.poses
    new = dataclasses.replace(scene, camera=est.camera, poses=poses)
    return PoseStageResult(new, est, thresholds, source)


def summary_line(result: PoseStageResult) -> str:
    """One line for the log: registered count, failed images, focal length, error, time."""
    r = result.estimate.report
    failed = ", ".join(r.failed) if r.failed else "none"
    if not r.focal_estimated:
        focal = f"focal {r.focal[0]:.1f} px (given)"
    elif r.focal_observable:
        focal = f"focal {r.focal[0]:.1f} px (estimated)"
    else:
        focal = f"focal {r.focal[0]:.1f} px (the starting guess: the images do not constrain it)"
    motion = {"static": "; camera static (no parallax: one pose for every frame)",
              "rotation": "; camera only turns (no parallax: rotations from the matches, no "
                          "translation)"}.get(r.motion, "")
    what = "registered" if r.motion == "general" else "linked by matches"
    error = "reprojection error" if r.motion == "general" else "median match residual"
    return (f"poses from {result.source}: {what} {r.registered}/{r.n_images}, failed: {failed}{motion}; "
            f"{focal}; {error} {r.reprojection_error_px:.2f} px; {r.seconds:.1f} s")


def write_pose_outputs(out: str | Path, result: PoseStageResult) -> None:
    """``out/trajectory_initial.txt`` (the scene's poses, TUM) and ``out/camera.json``."""
    from fusiongs.atomic import write_text
    from fusiongs.camera.tum import write_tum

    out = Path(out)
    cam = result.scene.camera
    est = result.estimate
    doc = {"camera": {"width": cam.width, "height": cam.height, "fx": cam.fx, "fy": cam.fy,
                      "cx": cam.cx, "cy": cam.cy},
           "intrinsics": "estimated" if est.report.focal_estimated else "given",
           "trajectory": "estimated" if result.scene.poses is est.poses else "given",
           "source": result.source, "report": est.report.to_dict()}
    write_tum(out / TRAJECTORY_FILE, result.scene.poses)
    write_text(out / CAMERA_FILE, json.dumps(doc, indent=2) + "\n")


def read_pose_outputs(out: str | Path, scene: Scene) -> Scene | None:
    """The scene with the camera and poses of an earlier run's :func:`write_pose_outputs`
    (``None`` when either file is missing)."""
    from fusiongs.camera.tum import read_tum

    out = Path(out)
    cp, tp = out / CAMERA_FILE, out / TRAJECTORY_FILE
    if not (cp.is_file() and tp.is_file()):
        return None
    try:
        c = json.loads(cp.read_text())["camera"]
        cam = PinholeCamera(int(c["width"]), int(c["height"]), float(c["fx"]), float(c["fy"]),
                            float(c["cx"]), float(c["cy"]), scene.camera.distortion)
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise InputError(cp, "camera", "the camera.json of an earlier run (width, height, fx, fy, cx, "
                         "cy)", repr(e)) from None
    if (cam.width, cam.height) != (scene.camera.width, scene.camera.height):
        raise InputError(cp, "camera", f"a {scene.camera.width}x{scene.camera.height} camera like the "
                         "scene", f"{cam.width}x{cam.height}")
    return dataclasses.replace(scene, camera=cam,
                               poses=scene.poses if scene.poses is not None else read_tum(tp))


def run_pose_stage(scene: Scene, cfg: DeblurConfig, out: str | Path,
                   calibration: SensorThresholds | None = None, *, resume: bool = False,
                   log=print) -> tuple[Scene, SensorThresholds | None]:
    """The stage as ``fusiongs deblur`` runs it, before training.

    Args:
        scene: the loaded scene; returned unchanged when it has its trajectory and intrinsics.
        cfg: the run's :class:`~fusiongs.train.settings.DeblurConfig` (threshold settings).
        out: the run folder (``trajectory_initial.txt`` and ``camera.json`` are written there).
        calibration: thresholds from ``--calibration``, or ``None``.
        resume: reuse ``trajectory_initial.txt`` and ``camera.json`` of ``out`` when both exist.
        log: where the summary line goes.

    Returns:
        ``(scene with camera and poses, calibration for training)``: the thresholds estimated here
        are handed on when none were given, so the trainer does not estimate them again.
    """
    if not needs_pose_stage(scene):
        return scene, calibration
    if resume:
        restored = read_pose_outputs(out, scene)
        if restored is not None:
            log(f"poses: camera and trajectory of the earlier run in {out}")
            return restored, calibration
    theta = stage_thresholds(scene, calibration, cfg.threshold.estimate, cfg.threshold.init)
    edi_theta = cfg.priors.edi_theta if cfg.priors.edi_theta else theta  # as the trainer's EDI
    result = estimate_scene_poses(scene, thresholds=edi_theta, event_views=EVENT_ONLY_VIEWS,
                                  event_tau=cfg.event_only.intensity_tau, event_theta=cfg.threshold.init)
    write_pose_outputs(out, result)
    log(summary_line(result))
    if (calibration is None and theta is not None and cfg.events.enabled
            and theta.method != "threshold.init"):
        calibration = theta
    return result.scene, calibration
