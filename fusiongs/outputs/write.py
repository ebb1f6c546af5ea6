"""Everything ``fusiongs deblur`` writes after training (see the README's output list)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from fusiongs.atomic import write_text
from fusiongs.camera.trajectory import Trajectory
from fusiongs.camera.tum import PoseSamples, write_tum
from fusiongs.configs.load import save_config
from fusiongs.frames.image_io import write_png
from fusiongs.frames.response import response_to_linear
from fusiongs.io.scene import Scene
from fusiongs.outputs.display_ply import DisplayFit, DisplayFitOptions, fit_run_display
from fusiongs.scene.ply import save_ply
from fusiongs.train.render_io import (
    EXPOSURE_LEVEL,
    EXPOSURE_PERCENTILE,
    auto_exposure,
    exposed_srgb,
    exposure_gain,
    render_linear,
    render_srgb,
)
from fusiongs.train.state import FusionState
from fusiongs.train.trained import Trained

PLY_FILE = "model.ply"  # the Gaussians for 3DGS viewers: the display copy (display_ply.py)
FRAMES_FILE = "frames.json"  # the frames' names and exposure windows, the render instants, the scene
TRAJECTORY_FILE = "trajectory.txt"  # the refined camera path (the pose stage's own is trajectory_initial.txt)
TRAJECTORY_RATE_HZ = 200.0  # the written path is at least this dense
EXPOSURE_FILE = "exposure.json"  # the gain of an event-only run's renders (fusiongs render reuses it)



def frames_srgb(scene: Scene) -> np.ndarray:
    """The captured (blurry) frames as sRGB ``[F, H, W, 3]`` for side-by-side comparison."""
    f = scene.frames
    lin = response_to_linear(f.images.astype(np.float64), f.response)
    if lin.shape[-1] == 1:
        lin = np.repeat(lin, 3, axis=-1)
    return exposed_srgb(lin)


def write_thresholds(state: FusionState, path: Path) -> dict:
    """``thresholds.json``: learned θ per polarity (and colour channel)."""
    with torch.no_grad():
        tp, tn = state.threshold.scalar()
    names = ["grey"] if tp.numel() == 1 else ["R", "G", "B"]
    doc = {"channels": names, "theta_pos": [float(v) for v in tp.reshape(-1)],
           "theta_neg": [float(v) for v in tn.reshape(-1)]}
    write_text(path, json.dumps(doc, indent=2) + "\n")
    return doc


def trajectory_times(sample_t: np.ndarray, keep_t=(), rate_hz: float = TRAJECTORY_RATE_HZ,
                     min_gap: float = 1e-6) -> np.ndarray:
    """Instants (s) at which to write a refined trajectory: its own sample times, intervals longer
    than ``1 / rate_hz`` split evenly, and ``keep_t`` (e.g. the frame mid-times, clamped into the
    sampled range) exactly.

    Args:
        sample_t: ``[M]`` strictly increasing sample times of the trajectory (s).
        keep_t: instants that must appear as they are; a grid instant closer than ``min_gap`` to
            one of them is dropped (the file's times stay strictly increasing after rounding).
        rate_hz: the slowest sampling rate of the result.
        min_gap: smallest spacing kept (s).

    Returns:
        ``[N]`` strictly increasing times within ``[sample_t[0], sample_t[-1]]``.
    """
    st = np.asarray(sample_t, dtype=np.float64).reshape(-1)
    step = 1.0 / rate_hz
    if st.size > 1:
        gaps = np.diff(st)
        parts = np.maximum(np.ceil(gaps / step - 1e-9), 1).astype(np.int64)
        seg = np.repeat(np.arange(gaps.size), parts)
        k = np.arange(seg.size) - np.repeat(np.cumsum(parts) - parts, parts)
        grid = np.append(st[seg] + gaps[seg] * k / parts[seg], st[-1])
    else:
        grid = st
    keep = np.unique(np.clip(np.asarray(keep_t, dtype=np.float64).reshape(-1), st[0], st[-1]))
    if keep.size:
        i = np.searchsorted(keep, grid)
        near = np.minimum(np.abs(grid - keep[np.clip(i, 0, keep.size - 1)]),
                          np.abs(grid - keep[np.clip(i - 1, 0, keep.size - 1)]))
        grid = grid[near >= min_gap]
    t = np.union1d(grid, keep)
    ok = np.concatenate([[True], np.diff(t) >= min_gap])  # drop one of two instants closer than min_gap
    return t[ok]


def refined_poses(trajectory: Trajectory, keep_t=(), rate_hz: float = TRAJECTORY_RATE_HZ,
                  batch: int = 20000) -> PoseSamples:
    """The trajectory as it was optimised (knot corrections included), evaluated at
    :func:`trajectory_times` of its sample times (host float64)."""
    ts = trajectory_times(trajectory.sample_t.cpu().numpy(), keep_t, rate_hz)
    c2w = [trajectory.as_pose_samples(ts[i:i + batch]).c2w for i in range(0, ts.size, batch)]
    return PoseSamples(t=ts, c2w=np.concatenate(c2w))


def write_trajectory(tr: Trained, scene: Scene, path: Path) -> PoseSamples:
    """``trajectory.txt``: the refined camera path in the scene format's own layout (docs/scene-format.md),
    dense (:data:`TRAJECTORY_RATE_HZ`) and exact at the frame mid-times; usable as a scene's
    ``trajectory.txt``."""
    traj = tr.state.trajectory
    mids = scene.frames.mid_times() if len(scene.frames) else ()
    poses = refined_poses(traj, mids)
    refined = "refined" if traj.delta is not None else "fitted (pose refinement off)"
    write_tum(path, poses, comment=f"camera path {refined} by fusiongs deblur, {tr.iteration} "
              f"iterations ({traj.mode} trajectory); samples at least {TRAJECTORY_RATE_HZ:g} Hz "
              "and at every frame's mid-exposure")
    return poses


def write_exposure(path: Path, gain: float) -> None:
    """``exposure.json``: the linear gain of an event-only run's renders (what the outputs and
    ``fusiongs render`` apply before clipping at white)."""
    write_text(path, json.dumps({
        "gain": gain, "percentile": EXPOSURE_PERCENTILE, "level": EXPOSURE_LEVEL,
        "note": "no frame fixes the renders' level (events measure changes of log intensity): one "
                f"gain in linear light puts the {EXPOSURE_PERCENTILE}th percentile of the requested "
                f"renders at {EXPOSURE_LEVEL}"}, indent=2) + "\n")


def read_exposure(run: Path) -> float:
    """The gain of ``run/exposure.json``; 1 when the run has none (frames fixed its level)."""
    from fusiongs.errors import InputError

    path = run / EXPOSURE_FILE
    if not path.is_file():
        return 1.0
    expected = "a JSON object whose 'gain' is a finite number > 0"
    try:
        gain = float(json.loads(path.read_text())["gain"])
    except (ValueError, KeyError, TypeError) as e:
        raise InputError(path, "gain", expected, f"{type(e).__name__}: {e}") from None
    if not (gain > 0 and np.isfinite(gain)):
        raise InputError(path, "gain", expected, repr(gain))
    return gain


def write_outputs(tr: Trained, scene: Scene, out: Path,
                  adjust: Callable[[np.ndarray], np.ndarray] | None = None,
                  kept: np.ndarray | None = None, colour: tuple[np.ndarray, np.ndarray] | None = None
                  ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, np.ndarray], DisplayFit]:
    """Write renders, deblurred frames and video, model, config, thresholds, the refined
    camera path (``trajectory.txt``) and the frames' instants (``frames.json``).

    Without frames (and ``output.exposure`` auto) the renders get one linear gain
    (:func:`fusiongs.train.render_io.exposure_gain`, written to ``exposure.json``) before they are
    clipped. The deblurred frames are the renders at the frames' mid-exposure; with
    ``output.exposure_ratio`` on, they and every requested render inside a frame's exposure (with
    ``output.ratio_between``, also between two exposures) are exposure-ratio corrected
    (:mod:`fusiongs.outputs.exposure_ratio`): the ratio is taken on the renders with ``colour``
    applied, so ``adjust`` is not applied to them again. ``model.ply`` is the display copy of the
    Gaussians (:func:`write_model_ply`).

    Args:
        adjust: applied to every sRGB image ``[H, W, 3]`` before it is written (the colour anchor,
            :func:`fusiongs.outputs.colour_anchor.apply_anchor`); None writes them as rendered.
        kept: the frames of ``scene`` the run was trained on (``--holdout``); None: all of them.
        colour: the linear ``(gain, offset)`` that ``adjust`` applies (the colour anchor), for the
            corrected images.

    Returns:
        ``(rendered, written, render_only, ply)``: ``{name: sRGB image}`` for every ``renders`` entry
        and ``deblur/<stem>`` frame as rendered and as written (the same dict without ``adjust``
        or correction), the images the correction replaced as rendered, ``adjust`` applied, and
        the display fit of ``model.ply``.
    """
    from fusiongs.outputs.exposure_ratio import corrected_renders, frame_log_gains
    from fusiongs.outputs.video import write_mp4

    state, cfg = tr.state, tr.config
    keys = [r.name for r in scene.renders] + [f"deblur/{name}" for name in scene.frames.names]
    times = np.concatenate([np.asarray([r.t for r in scene.renders], np.float64), scene.frames.mid_times()])
    corrected: dict[str, np.ndarray] = {}
    gain = 1.0
    (out / EXPOSURE_FILE).unlink(missing_ok=True)  # an earlier event-only run's, in this folder
    if cfg.output.exposure_ratio and len(scene.frames):
        gains = frame_log_gains(state, len(scene.frames), kept)
        plain, fixed, applied = corrected_renders(state, scene, times, gains, cfg.blur.n_samples,
                                                cfg.output.ratio_eps, cfg.events.grey_weights, cfg.backend,
                                                colour, cfg.output.ratio_iterations, cfg.output.ratio_between)
        srgb, fixed = exposed_srgb(plain), exposed_srgb(fixed)
        corrected = {k: fixed[j] for j, k in enumerate(keys) if applied[j]}
    elif adjust is None and auto_exposure(cfg, len(scene.frames)):  # no level fixed: expose
        lin = render_linear(state, scene.camera, times, cfg.backend)
        gain = exposure_gain(lin)
        write_exposure(out / EXPOSURE_FILE, gain)
        srgb = exposed_srgb(lin, gain)
    else:
        srgb = render_srgb(state, scene.camera, times, cfg.backend)
    rendered = dict(zip(keys, srgb))
    written = rendered if adjust is None else {k: adjust(v) for k, v in rendered.items()}
    render_only = {k: written[k] for k in corrected}
    written = {**written, **corrected}
    deblurred = []
    for key, img in written.items():
        if key.startswith("deblur/"):
            write_png(out / "deblurred" / f"{key.split('/', 1)[1]}.png", img)
            deblurred.append(img)
        else:
            write_png(out / "renders" / f"{key}.png", img)
    if deblurred:
        write_mp4(out / "deblurred.mp4", deblurred, cfg.output.video_fps)
    ply = write_model_ply(state, scene.camera, times, out / PLY_FILE, gain, adjust, cfg.backend,
                          cfg.output.ply_fit_steps)
    save_config(cfg, out / "config.yaml")
    write_thresholds(state, out / "thresholds.json")
    write_trajectory(tr, scene, out / TRAJECTORY_FILE)
    write_frames(scene, out / FRAMES_FILE, kept)
    return rendered, written, render_only, ply


def write_model_ply(state: FusionState, camera, times, path: Path, gain: float = 1.0,
                    adjust: Callable[[np.ndarray], np.ndarray] | None = None, backend: str = "auto",
                    steps: int = DisplayFitOptions.steps) -> DisplayFit:
    """``model.ply``: the run's Gaussians with colours and opacities fitted for display-space
    compositing (:func:`fusiongs.outputs.display_ply.fit_run_display`, ``steps`` Adam steps) against
    its renders at ``times`` (s) with ``gain`` and ``adjust`` (as the written images have them).
    The linear model of ``checkpoint.pt`` is not changed.

    Returns:
        the fit, with the PSNR of the file composited as viewers do, before and after.
    """
    fit = fit_run_display(state, camera, times, gain, adjust, backend, DisplayFitOptions(steps=steps))
    save_ply(fit.model, path, colours="display",
             comment=f"colours and opacities for display-space compositing ({fit.steps} fit steps): "
                     f"{fit.psnr_after:.2f} dB from the run's renders "
                     f"({fit.psnr_before:.2f} dB per-Gaussian sRGB)")
    return fit


def write_frames(scene: Scene, path: Path, kept: np.ndarray | None = None) -> dict:
    """``frames.json``: the scene folder, each frame's name and exposure window (s), whether the run
    was trained on it, and the render instants; what ``fusiongs view`` places its cameras with."""
    f = scene.frames
    trained = np.ones(len(f), bool)
    if kept is not None:
        trained[:] = False
        trained[np.asarray(kept, dtype=np.int64)] = True
    doc = {"scene": str(Path(scene.root).resolve()) if scene.root else None,
           "frames": [{"name": n, "t_start": float(s), "t_end": float(e), "t_mid": float(m),
                       "trained": bool(k)}
                      for n, s, e, m, k in zip(f.names, f.t_start, f.t_end, f.mid_times(), trained)],
           "renders": [{"name": r.name, "t": float(r.t)} for r in scene.renders]}
    write_text(path, json.dumps(doc, indent=2) + "\n")
    return doc
