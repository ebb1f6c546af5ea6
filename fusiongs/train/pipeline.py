"""``fusiongs deblur`` as a function: load → train → write outputs → evaluate against truth."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fusiongs.atomic import write_text
from fusiongs.eval.evaluate import compare_methods, format_table
from fusiongs.frames.response import linear_to_srgb
from fusiongs.io.scene import Scene
from fusiongs.io.scene_io import load_scene
from fusiongs.train.config import load_config
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.trainer import Trained, train

EVENT_ONLY_NOTE = ("event-only reconstruction: events fix log-intensity changes, not absolute "
                   "brightness or colour balance; renders are defined up to a per-channel scale and "
                   "offset, so metrics are also given after a per-channel affine fit")


def resolve_config(config: str | Path | None, overrides: Sequence[str]) -> DeblurConfig:
    """The dataclass defaults (= configs/deblur.yaml), then the file (a path, or the name of a
    preset shipped in the package such as ``deblur_fast``), then ``key=value`` overrides."""
    from fusiongs.configs import resolve_config_path

    return load_config(DeblurConfig, resolve_config_path(config) if config is not None else None,
                       overrides)


def baseline_images(scene: Scene, thresholds=None) -> dict[str, dict[str, np.ndarray]]:
    """Blurry input and EDI as sRGB, keyed ``deblur_<stem>`` like the truth.

    ``"edi"`` uses ``thresholds`` (the run's calibration; estimated when None); when the scene is
    simulated and knows its true thresholds, ``"edi_true_theta"`` is EDI with those (the honest
    peer, METHOD.md section 8).
    """
    from fusiongs.eval.edi import edi_scene
    from fusiongs.eval.truth import true_thresholds
    from fusiongs.train.outputs import frames_srgb

    if len(scene.frames) == 0:
        return {}
    names = [f"deblur_{n}" for n in scene.frames.names]
    out = {"blurry": dict(zip(names, frames_srgb(scene)))}
    if scene.events is None or not len(scene.events):
        return out
    runs = {"edi": thresholds}
    truth = true_thresholds(scene.root, scene.events.cfa) if scene.root is not None else None
    if truth is not None:
        runs["edi_true_theta"] = truth
    for key, th in runs.items():
        edi = edi_scene(scene, theta=th)
        if edi.shape[-1] == 1:
            edi = np.repeat(edi, 3, axis=-1)
        out[key] = dict(zip(names, linear_to_srgb(np.clip(edi, 0, 1)).astype(np.float32)))
    return out


def evaluate_outputs(tr: Trained, scene: Scene, images: dict[str, np.ndarray], out: Path,
                     gt_dir: Path) -> dict | None:
    """metrics.json and report.png when truth exists; returns the metrics (or None)."""
    from fusiongs.eval.report import write_report
    from fusiongs.train.outputs import read_gt

    ours = {k: v for k, v in images.items() if not k.startswith("deblur/")}
    for k, v in images.items():
        if k.startswith("deblur/"):
            ours.setdefault(f"deblur_{k.split('/', 1)[1]}", v)
    gt = read_gt(gt_dir, ours.keys())
    if not gt:
        return None
    methods = {"fusiongs": ours, **baseline_images(scene, tr.initial_thresholds)}
    result = compare_methods(methods, gt)
    if len(scene.frames) == 0:  # event-only: brightness and colour balance are not observable
        result["affine_fit"] = compare_methods(methods, gt, affine=True)
        result["note"] = EVENT_ONLY_NOTE
    result["seconds"] = tr.history.seconds
    result["render_seconds"] = tr.history.render_seconds
    result["backward_seconds"] = tr.history.backward_seconds
    result["iterations"] = tr.iteration
    result["n_gaussians"] = tr.state.model.n
    write_text(out / "metrics.json", json.dumps(result, indent=2) + "\n")
    write_report(out / "report.png", result, tr.history, methods, gt)
    return result


def run_deblur(scene_path: str | Path, out: str | Path, *, config: str | Path | None = None,
               overrides: Sequence[str] = (), resume: bool = False, log=print,
               calibration: str | Path | None = None) -> dict | None:
    """Fit, write every output of ``fusiongs deblur`` into ``out``, and evaluate when truth exists.

    ``calibration``: a ``calibration.json`` from ``fusiongs calibrate`` (the starting thresholds);
    without it they are estimated the same way. Either way they are written to
    ``out/calibration.json``.

    A scene without trajectory or intrinsics first goes through the pose stage
    (:func:`fusiongs.train.poses_stage.run_pose_stage`: EDI images registered by pycolmap), which
    writes ``out/trajectory.txt`` and ``out/camera.json``.
    """
    from fusiongs.events.thresholds import read_calibration, write_calibration
    from fusiongs.train.outputs import write_outputs
    from fusiongs.train.poses_stage import needs_pose_stage, run_pose_stage

    cfg = resolve_config(config, overrides)
    calib = read_calibration(calibration)[0] if calibration is not None else None
    scene = load_scene(scene_path)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if needs_pose_stage(scene):  # no trajectory or no intrinsics: EDI + pycolmap first
        scene, calib = run_pose_stage(scene, cfg, out, calib, resume=resume, log=log)
    tr = train(scene, cfg, out, resume=resume, calibration=calib)
    if tr.initial_thresholds is not None:
        write_calibration(out / "calibration.json", tr.initial_thresholds, scene=str(scene_path))
    if len(scene.frames) == 0:
        log(EVENT_ONLY_NOTE)
    images = write_outputs(tr, scene, out)
    n_it = max(tr.iteration, 1)
    h = tr.history
    log(f"trained {tr.iteration} iterations in {h.seconds:.1f} s ({h.seconds / n_it:.3f} s/it; "
        f"render forward {h.render_seconds / max(h.seconds, 1e-9):.0%}, backward "
        f"{h.backward_seconds / max(h.seconds, 1e-9):.0%}), {tr.state.model.n} Gaussians")
    result = None
    if scene.root is not None and (scene.root / "gt").is_dir():
        result = evaluate_outputs(tr, scene, images, out, scene.root / "gt")
        if result is not None:
            log(format_table(result))
            if "affine_fit" in result:
                log("after a per-channel affine fit (EventNeRF's protocol):")
                log(format_table(result["affine_fit"]))
    log(f"outputs in {out}")
    return result
