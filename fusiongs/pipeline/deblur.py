"""``fusiongs deblur`` as a function: load → train → write outputs → evaluate (against truth when
the scene has it; held-out frames and sharpness without)."""

from __future__ import annotations

import dataclasses
import functools
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fusiongs.atomic import remove_temporaries, write_text
from fusiongs.configs.load import load_config
from fusiongs.eval.evaluate import compare_methods, format_table
from fusiongs.eval.holdout import format_heldout, frame_subset, holdout_indices, parse_holdout
from fusiongs.frames.response import linear_to_srgb
from fusiongs.io.scene import Scene
from fusiongs.io.scene_io import load_scene
from fusiongs.outputs.colour_anchor import ColourAnchor, anchor_run, apply_anchor, write_anchor
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.trained import Trained
from fusiongs.train.trainer import check_device, train

EVENT_ONLY_NOTE = ("event-only reconstruction: events fix log-intensity changes, not absolute "
                   "brightness or colour balance; renders are defined up to a per-channel scale and "
                   "offset, so metrics are also given after a per-channel affine fit")
NO_TRUTH_NOTE = ("no truth images (gt/): held-out frames (--holdout) and no-reference sharpness "
                 "(Tenengrad: rises with edges and with noise) only")


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
    peer, docs/method.md section 8).
    """
    from fusiongs.edi import edi_scene
    from fusiongs.io.truth import true_thresholds
    from fusiongs.outputs.write import frames_srgb

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
        if th is None:
            from fusiongs.calibrate.estimate import estimate_thresholds

            th = estimate_thresholds(scene.frames, scene.events)
        edi = edi_scene(scene, theta=th)
        if edi.shape[-1] == 1:
            edi = np.repeat(edi, 3, axis=-1)
        out[key] = dict(zip(names, linear_to_srgb(np.clip(edi, 0, 1)).astype(np.float32)))
    return out


def _by_view(images: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Output images keyed like the truth: renders by name, deblurred frames as ``deblur_<stem>``."""
    ours = {k: v for k, v in images.items() if not k.startswith("deblur/")}
    for k, v in images.items():
        if k.startswith("deblur/"):
            ours.setdefault(f"deblur_{k.split('/', 1)[1]}", v)
    return ours


def threshold_summary(tr: Trained) -> dict | None:
    """θ of the run as ``[[ON per channel], [OFF per channel]]``: where it started (the
    calibration), at the first event iteration (after ``threshold.render_floor``) and at the end;
    None without events."""
    th, h = tr.initial_thresholds, tr.history
    if th is None or tr.data.events is None or not h.theta_pos:
        return None
    out = {"calibration": [list(map(float, th.theta_pos)), list(map(float, th.theta_neg))]}
    if tr.config.events.warmup in h.iteration:
        j = h.iteration.index(tr.config.events.warmup)
        out["events_start"] = [h.theta_pos[j], h.theta_neg[j]]
    out["final"] = [h.theta_pos[-1], h.theta_neg[-1]]
    return out


def evaluate_outputs(tr: Trained, scene: Scene, images: dict[str, np.ndarray], out: Path,
                     gt_dir: Path | None, heldout: tuple[dict, dict] | None = None,
                     anchor: ColourAnchor | None = None,
                     unanchored: dict[str, np.ndarray] | None = None,
                     render_only: dict[str, np.ndarray] | None = None, ply: dict | None = None) -> dict:
    """metrics.json and report.png; returns the metrics.

    Against truth when ``gt_dir`` holds images named like the outputs; always the no-reference
    sharpness of the deblurred frames (:func:`fusiongs.eval.holdout.compare_sharpness`) and, with
    ``heldout`` (from :func:`score_holdout`), the held-out scores and pictures. With no frame or
    an applied colour ``anchor`` (``images`` anchored, ``unanchored`` before), also the colour
    figures of :func:`fusiongs.eval.evaluate.colour_metrics` and the anchor. ``render_only``: the
    deblurred frames before the exposure-ratio correction, scored as ``fusiongs_render``. ``ply``:
    the figures of ``model.ply``'s display fit (:meth:`fusiongs.outputs.display_ply.DisplayFit.as_dict`),
    written as ``model_ply``.
    """
    from fusiongs.eval.evaluate import colour_metrics
    from fusiongs.eval.holdout import compare_sharpness
    from fusiongs.eval.report import write_report
    from fusiongs.train.render_io import read_gt

    anchor = anchor or ColourAnchor()
    ours = _by_view(images)
    gt = read_gt(gt_dir, ours.keys()) if gt_dir is not None and gt_dir.is_dir() else {}
    methods = {"fusiongs": ours, **baseline_images(scene, tr.initial_thresholds)}
    if render_only:
        methods["fusiongs_render"] = _by_view(render_only)
    colour = len(scene.frames) == 0 or anchor.applied  # colours the events alone do not fix
    if gt:
        result = compare_methods(methods, gt, delta_e=anchor.applied)
        if colour:
            result |= colour_metrics(methods, gt, anchor, _by_view(unanchored or images))
        if len(scene.frames) == 0:  # event-only: brightness and colour balance are not observable
            result["note"] = EVENT_ONLY_NOTE
    else:
        result = {"note": NO_TRUTH_NOTE} | ({"colour_anchor": anchor.as_dict()} if colour else {})
    sharp = compare_sharpness(methods)
    if sharp:
        result["sharpness"] = sharp
    if heldout is not None:
        result["heldout"] = heldout[0]
    thresholds = threshold_summary(tr)
    if thresholds is not None:
        result["thresholds"] = thresholds
    result["seconds"] = tr.history.seconds
    result["render_seconds"] = tr.history.render_seconds
    result["backward_seconds"] = tr.history.backward_seconds
    result["iterations"] = tr.iteration
    result["n_gaussians"] = tr.state.model.n
    if ply is not None:
        result["model_ply"] = ply
    write_text(out / "metrics.json", json.dumps(result, indent=2) + "\n")
    write_report(out / "report.png", result, tr.history, methods, gt,
                 heldout=heldout[1] if heldout is not None else None)
    return result


def split_holdout(scene: Scene, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``(held, kept)`` frame indices for ``--holdout k`` (rule: :mod:`fusiongs.eval.holdout`).

    Raises:
        InputError: ``k >= 2`` leaves no frame out (fewer than 3 frames, or K too large).
    """
    from fusiongs.errors import InputError

    n = len(scene.frames)
    held = holdout_indices(n, k)
    if k and not held.size:
        raise InputError("--holdout", "K", f"a period that leaves a frame out of the {n} frames "
                         "(the first and last are always kept: K <= number of frames - 1)", k)
    return held, np.setdiff1d(np.arange(n), held)


def score_holdout(tr: Trained, scene: Scene, held: np.ndarray, kept: np.ndarray, k: int
                  ) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
    """Predict each held-out blurry frame four ways and score it against the real one (METHOD §6a).

    Args:
        tr: the run, trained on the frames ``kept`` of ``scene``.
        scene: every frame (with the run's camera and trajectory).
        held, kept: frame indices from :func:`split_holdout`.
        k: the ``--holdout`` period (recorded).

    Returns:
        ``(document, pictures)``: the ``heldout.json`` document (per frame the PSNR of each of
        :data:`~fusiongs.eval.holdout.METHODS` on 8-bit values in the frames' own encoding, plus
        the means), and per frame ``{column: sRGB image}`` for the report. fusiongs uses the mean
        gain ``g`` of the kept frames (1 when gains are not learned), and ``fusiongs_ratio`` the
        kept neighbours' factors as ``output.ratio_iterations`` computes them; EDI-carried uses the
        run's starting thresholds (``calibration.json``) and is ``None`` without events.
    """
    import torch

    from fusiongs.edi import edi_deblur
    from fusiongs.eval.holdout import (
        METHODS,
        RULE,
        carried_exposure,
        heldout_summary,
        kept_neighbours,
        nearest_kept,
    )
    from fusiongs.eval.metrics import psnr
    from fusiongs.frames.response import linear_to_response, response_to_linear
    from fusiongs.losses.blur import exposure_instants
    from fusiongs.outputs.exposure_ratio import factor_carried, frame_factor, frame_log_gains
    from fusiongs.train.step import predict_blurry

    fs, cfg, state = scene.frames, tr.config, tr.state
    n, lin, mids = cfg.blur.n_samples, fs.to_linear(), fs.mid_times()
    events = scene.events if scene.events is not None and len(scene.events) else None
    theta = tr.initial_thresholds
    if events is not None and theta is None:
        from fusiongs.calibrate.estimate import estimate_thresholds

        theta = estimate_thresholds(frame_subset(fs, kept), events)
    log_gains = frame_log_gains(state, len(fs), kept)
    log_g = log_gains[int(held[0])]  # held-out frames: the mean gain
    gain = float(log_g.exp())
    out_cfg = cfg.output
    factors: dict[int, torch.Tensor] = {}

    def factor(j: int) -> torch.Tensor:
        if j not in factors:
            factors[j] = frame_factor(state, scene, j, log_gains, n, out_cfg.ratio_eps,
                                      cfg.events.grey_weights, cfg.backend, out_cfg.ratio_iterations)
        return factors[j]

    def display(encoded: np.ndarray) -> np.ndarray:
        out = linear_to_srgb(np.clip(response_to_linear(np.asarray(encoded, np.float64), fs.response), 0, 1))
        return np.asarray(out, np.float32)

    edi: dict[int, np.ndarray] = {}
    frames, pictures = {}, {}
    for i in (int(v) for v in held):
        s, e, name = float(fs.t_start[i]), float(fs.t_end[i]), fs.names[i]
        sides = [j for j in kept_neighbours(kept, i) if j is not None]
        times = exposure_instants(s, e, n)
        channels, grey = fs.images.shape[-1], cfg.events.grey_weights
        with torch.no_grad():
            renders, _, _ = state.render(scene.camera, times, cfg.backend)
            ours = predict_blurry(renders, log_g, fs.response, channels, grey)
            depth = state.render_depth(scene.camera, times, cfg.backend)  # once for both sides
            detail = torch.stack([renders * factor_carried(state, scene, factor(j), j, times, cfg.backend,
                                                           depth) for j in sides]).mean(0)
            ours_ratio = predict_blurry(detail, log_g, fs.response, channels, grey)
        near = nearest_kept(mids, kept, i)
        preds = {"fusiongs": ours.cpu().numpy(), "fusiongs_ratio": ours_ratio.cpu().numpy(),
                 "nearest": fs.images[near], "edi_carried": None}
        if events is not None:
            carried = []
            for j in sides:
                if j not in edi:
                    edi[j] = edi_deblur(lin[j], events, float(fs.t_start[j]), float(fs.t_end[j]), theta)
                carried.append(carried_exposure(edi[j], events, float(mids[j]), s, e, n, theta))
            preds["edi_carried"] = linear_to_response(np.clip(np.mean(carried, axis=0), 0, 1), fs.response)
        real = fs.images[i]
        frames[name] = {m: (psnr(p, real) if p is not None else None) for m, p in preds.items()}
        frames[name] |= {"nearest_frame": fs.names[near], "neighbours": [fs.names[j] for j in sides]}
        pictures[name] = {m: display(p) for m, p in preds.items() if p is not None} | {"real": display(real)}
    doc = {"holdout": k, "rule": RULE, "methods": list(METHODS), "n_samples": n, "gain": gain,
           "psnr": "8-bit values in the frames' own encoding", "frames": frames,
           "mean": heldout_summary(frames)}
    return doc, pictures


def run_deblur(scene_path: str | Path, out: str | Path, *, config: str | Path | None = None,
               overrides: Sequence[str] = (), resume: bool = False, log=print,
               calibration: str | Path | None = None, holdout: int | str | None = None) -> dict:
    """Fit, write every output of ``fusiongs deblur`` into ``out``, and evaluate.

    Returns the metrics (``metrics.json``): against truth when the scene has ``gt/``, else held-out
    and sharpness figures only.

    ``calibration``: a ``calibration.json`` from ``fusiongs calibrate`` (the starting thresholds);
    without it they are estimated the same way. Either way they are written to
    ``out/calibration.json``.

    A scene without trajectory or intrinsics first goes through the pose stage
    (:func:`fusiongs.pipeline.poses.run_pose_stage`: EDI images registered by pycolmap), which
    writes ``out/trajectory_initial.txt`` and ``out/camera.json`` (the refined path,
    ``out/trajectory.txt``, is written with the other outputs after training).

    ``holdout = K`` (``--holdout``; 0 or None = off) trains without every K-th frame
    (:mod:`fusiongs.eval.holdout`), then predicts them and writes ``out/heldout.json``; the other
    outputs (deblurred frames, metrics) still cover every frame.
    """
    from fusiongs.events.thresholds import read_calibration, write_calibration
    from fusiongs.outputs.write import EXPOSURE_FILE, read_exposure, write_outputs
    from fusiongs.pipeline.poses import needs_pose_stage, run_pose_stage
    from fusiongs.pipeline.refine import REFINED_FILE, floor_calibration

    k = parse_holdout(holdout)
    cfg = resolve_config(config, overrides)
    check_device(cfg.device)  # before the calibration and the pose stage spend minutes
    calib = read_calibration(calibration)[0] if calibration is not None else None
    scene = load_scene(scene_path)
    held, kept = split_holdout(scene, k)
    fit_scene = dataclasses.replace(scene, frames=frame_subset(scene.frames, kept)) if held.size else scene
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    remove_temporaries(out)  # half-written files of a run killed in this folder (kill -9)
    if needs_pose_stage(fit_scene):  # no trajectory or no intrinsics: EDI + pycolmap first
        fit_scene, calib = run_pose_stage(fit_scene, cfg, out, calib, resume=resume, log=log)
    tr = train(fit_scene, cfg, out, resume=resume, calibration=calib)
    tr.data.event_index = tr.data.fast = None  # training's per-event buffers (0.5 GB at 1e8 events)
    scene = dataclasses.replace(fit_scene, frames=scene.frames)  # every frame, the run's camera/poses
    if tr.initial_thresholds is not None:
        write_calibration(out / "calibration.json", tr.initial_thresholds, scene=str(scene_path))
    refined = floor_calibration(tr)  # θ when the events started, as `fusiongs calibrate --refine`
    if refined is not None:
        write_calibration(out / REFINED_FILE, refined, scene=str(scene_path))
    else:  # an earlier run's, in this folder, is not this run's
        (out / REFINED_FILE).unlink(missing_ok=True)
    if len(scene.frames) == 0:
        log(EVENT_ONLY_NOTE)
    cfg = tr.config  # with what training derived (blur.n_samples)
    anchor = anchor_run(tr.state, scene, cfg)  # one frame fixes each channel's gain and offset
    write_anchor(out, anchor)  # for `fusiongs render`; an earlier run's is removed when there is none
    unanchored, images, render_only, ply = write_outputs(
        tr, scene, out, functools.partial(apply_anchor, anchor) if anchor.applied else None,
        kept if held.size else None, (anchor.gain, anchor.offset) if anchor.applied else None)
    log(f"model.ply: colours fitted for 3DGS viewers (display-space compositing), {ply.psnr_after:.2f} dB "
        f"from the run's renders ({ply.psnr_before:.2f} dB unfitted), {ply.seconds:.1f} s")
    if anchor.applied:
        log(f"colour: {anchor.label}, gain {_fmt(anchor.gain)}, offset {_fmt(anchor.offset)} (linear)")
    if (out / EXPOSURE_FILE).is_file():
        log(f"exposure: renders x {read_exposure(out):.3g} in linear light (no frame fixes their level; "
            f"{EXPOSURE_FILE}; output.exposure=none writes them as rendered)")
    n_it = max(tr.iteration, 1)
    h = tr.history
    log(f"trained {tr.iteration} iterations in {h.seconds:.1f} s ({h.seconds / n_it:.3f} s/it; "
        f"render forward {h.render_seconds / max(h.seconds, 1e-9):.0%}, backward "
        f"{h.backward_seconds / max(h.seconds, 1e-9):.0%}), {tr.state.model.n} Gaussians, "
        f"far bound {tr.state.depth_far:.3g}, {cfg.blur.n_samples} renders per exposure"
        + (f" (image motion {tr.exposure_motion_px:.1f} px, blur.sample_spacing)"
           if tr.exposure_motion_px is not None else ""))
    heldout = score_holdout(tr, scene, held, kept, k) if held.size else None
    if heldout is not None:
        write_text(out / "heldout.json", json.dumps(heldout[0], indent=2) + "\n")
        log(format_heldout(heldout[0]))
    result = evaluate_outputs(tr, scene, images, out, scene.root / "gt" if scene.root else None, heldout,
                              anchor, unanchored, render_only, ply.as_dict())
    if "mean" in result:
        log(format_table(result))
        if "affine_fit" in result:
            log("after a per-channel affine fit (EventNeRF's protocol):")
            log(format_table(result["affine_fit"]))
        if "global_affine_fit" in result:
            log("after one per-channel affine fit over all views (Robust e-NeRF's protocol):")
            log(format_table(result["global_affine_fit"]))
    if "colour_anchor" in result:
        log(f"colour anchor: {result['colour_anchor']['label']}")
    if "sharpness" in result:
        log("sharpness of the deblurred frames (Tenengrad, no reference): " + ", ".join(
            f"{m} {v['tenengrad']:.4g}" for m, v in result["sharpness"].items()))
    log(f"outputs in {out}")
    return result


def _fmt(values) -> str:
    return "(" + ", ".join(f"{v:.3g}" for v in values) + ")"
