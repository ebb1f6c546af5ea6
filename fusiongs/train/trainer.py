"""The training loop of ``fusiongs deblur``: a short list of named steps.

Each iteration: pick a frame → schedules (λ_ev, learning rates, θ frozen or not) → render and
losses (:func:`fusiongs.train.step.training_step`) → backward → densify → optimiser steps →
history, progress bar and checkpoints.

On a GPU the loop does not wait for the device: the recorded values stay there and are read back
together every ``FLUSH_EVERY`` iterations and at checkpoints (the only synchronisations, besides
densification's refinement steps and what the rasteriser does inside).
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fusiongs.camera.trajectory import Trajectory
from fusiongs.configs.load import to_dict
from fusiongs.errors import ConfigError, InputError
from fusiongs.events.thresholds import (
    SensorThresholds,
    calibration_event_weights,
    calibration_warnings,
    detail_number,
)
from fusiongs.io.scene import Scene
from fusiongs.losses.blur import exposure_instants
from fusiongs.scene.densify import DensifyConfig, DensifyStrategy
from fusiongs.scene.gaussians import GaussianModel
from fusiongs.scene.optim import GaussianLR, make_optimizer, relative_colour_step
from fusiongs.train.checkpoint import checkpoint_errors, load_checkpoint, save_checkpoint
from fusiongs.train.data import (
    TrainData,
    edi_images,
    event_stereo_images,
    hpf_images,
    prepare_data,
    pvc_readouts,
)
from fusiongs.train.exposure_samples import derived_samples
from fusiongs.train.history import FLUSH_EVERY, History, PendingRow, flush_pending, history_row, write_history
from fusiongs.train.lowpass_term import LowpassHistory
from fusiongs.train.render_io import auto_exposure
from fusiongs.train.schedules import event_only_alpha, event_weight, log_linear_lr
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.state import EVENT_ONLY_VIEWS, FusionState, build_state, event_stereo_start, scene_extent
from fusiongs.train.step import training_step
from fusiongs.train.trained import Trained
from fusiongs.train.truth_probe import probe_psnr, should_probe, truth_probe

MOTION_POINTS = 4096  # initial Gaussians whose motion sizes the renders per exposure (at most)


def _densify_config(cfg: DeblurConfig) -> DensifyConfig:
    d = cfg.densify
    return DensifyConfig(grow_grad2d=d.grad_threshold, refine_start=d.start, refine_stop=d.stop,
                         refine_every=d.every, reset_opacity_every=d.reset_opacity_every,
                         max_gaussians=d.max_gaussians)


def colour_lr_scale(fill: torch.Tensor | None) -> float:
    """The colour learning rates' factor for a start at ``fill`` (``[3]`` linear; 1 for grey 0.5):
    its mean level / 0.5, so that an Adam step (a fixed change of linear colour) changes log
    intensity, where the event loss acts, as much as from the grey start."""
    return 1.0 if fill is None else float(fill.mean()) / 0.5


def _optimizers(state: FusionState, cfg: DeblurConfig, extent: float,
                colour_scale: float = 1.0) -> dict[str, torch.optim.Optimizer]:
    o = cfg.optim
    lr_colors = o.lr_colors * colour_scale
    lr = GaussianLR(means=o.lr_means, log_scales=o.lr_scales, quats=o.lr_quats,
                    opacity_logits=o.lr_opacities, sh0=lr_colors, shN=lr_colors / 20)
    opts: dict[str, torch.optim.Optimizer] = {"gaussians": make_optimizer(state.model, lr, extent)}
    opts["threshold"] = torch.optim.Adam(state.threshold.parameters(), lr=cfg.threshold.lr)
    if state.trajectory.delta is not None:
        opts["pose"] = torch.optim.Adam([state.trajectory.delta], lr=o.lr_pose)
    if state.log_gain.requires_grad:
        opts["gain"] = torch.optim.Adam([state.log_gain], lr=o.lr_gain)
    return opts


def _set_learning_rates(opts: dict[str, torch.optim.Optimizer], cfg: DeblurConfig, it: int,
                        extent: float) -> None:
    o = cfg.optim
    for g in opts["gaussians"].param_groups:
        if g["name"] == "means":
            g["lr"] = log_linear_lr(it, o.lr_means * extent, o.lr_means_final * extent, o.iterations)
    if "pose" in opts:
        span = max(o.iterations - o.pose_start, 1)
        for g in opts["pose"].param_groups:
            g["lr"] = log_linear_lr(max(it - o.pose_start, 0), o.lr_pose, o.lr_pose_final, span)


def check_device(name: str) -> None:
    """Raise :class:`ConfigError` (one line, before any work) when ``device`` names no device this
    machine has: not a torch device string, or CUDA without a usable card."""
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError):
        raise ConfigError("config", "device", "a torch device such as 'cpu', 'cuda' or 'cuda:0'",
                          repr(name)) from None
    if device.type == "cuda":
        n = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if n == 0 or (device.index is not None and device.index >= n):
            raise ConfigError("config", "device", f"a CUDA device this machine has ({n} found; "
                              "device=cpu runs anywhere)", repr(name))


def training_device(name: str) -> torch.device:
    """``torch.device(name)`` with the card named: ``"cuda"`` becomes ``cuda:<current device>``.

    Tensors made on ``"cuda"`` land on the current card and report ``cuda:0`` (say), while a
    ``torch.Generator(device="cuda")`` reports plain ``cuda``; naming the index once makes every
    tensor, generator and comparison of devices in the run agree (found by the CUDA half of
    tests/train/test_device_clean.py on an H200).
    """
    device = torch.device(name)
    if device.type == "cuda" and device.index is None:
        device = torch.device("cuda", torch.cuda.current_device())
    return device


def build_trajectory(scene: Scene, cfg: DeblurConfig) -> Trajectory:
    """The scene's poses as a refinable trajectory (clamped outside its time range), on the host
    whatever the training device (:class:`~fusiongs.train.state.FusionState` says why)."""
    return Trajectory(scene.poses, mode=cfg.trajectory, refine=cfg.optim.refine_poses,
                      knot_spacing=cfg.knot_spacing or None, outside="clamp", device="cpu")


def renders_per_exposure(cfg: DeblurConfig, data: TrainData, state: FusionState
                         ) -> tuple[DeblurConfig, float | None]:
    """``(cfg, motion)``: with ``blur.sample_spacing > 0`` and frames, ``cfg`` with
    ``blur.n_samples`` derived from the exposures' image motion of the initial Gaussians
    (:func:`~fusiongs.train.exposure_samples.derived_samples`) and the spacing set to 0 (what the
    run used, as its config.yaml records it), and that motion (px); else ``(cfg, None)``."""
    b = cfg.blur
    if b.sample_spacing <= 0 or data.n_frames == 0:
        return cfg, None
    ex = data.exposures.detach().cpu().to(torch.float64)
    means = state.model.means.detach().cpu()
    points = means[::max(1, len(means) // MOTION_POINTS)]
    with torch.no_grad():
        start, end = state.trajectory.c2w(ex[:, 0]), state.trajectory.c2w(ex[:, 1])
    n, motion = derived_samples(points, start, end, data.camera, b.sample_spacing, b.n_samples)
    return replace(cfg, blur=replace(b, n_samples=n, sample_spacing=0.0)), motion


def _payload(tr: Trained, opts: dict[str, torch.optim.Optimizer], gen: torch.Generator,
             device_gen: torch.Generator, strategy: DensifyStrategy,
             psnr_running: torch.Tensor | None) -> dict[str, Any]:
    """Everything a resumed run needs to go on exactly as this one would (same frames, draws,
    densification and optimiser steps)."""
    s = tr.state
    return {
        "iteration": tr.iteration,
        "config": to_dict(tr.config),
        "camera": asdict(tr.data.camera),
        "n_gaussians": s.model.n,
        "sh_degree": s.model.max_sh_degree,
        "model": s.model.state_dict(),
        "trajectory": {"state": s.trajectory.state_dict(), "mode": s.trajectory.mode,
                       "spacing": s.trajectory.spacing, "t": tr.poses.t, "c2w": tr.poses.c2w},
        "threshold": s.threshold.state_dict(),
        "threshold_channels": s.threshold.channels,
        "threshold_time_range": s.threshold.time_range,
        "log_gain": s.log_gain.detach().clone(),
        "optimizers": {k: o.state_dict() for k, o in opts.items()},
        "history": asdict(tr.history),
        "generator": gen.get_state(),
        "device_generator": {"device": device_gen.device.type, "state": device_gen.get_state()},
        "densify": strategy.state_dict(),
        "psnr_running": None if psnr_running is None else psnr_running.detach().cpu(),
        "threshold_floor": None if tr.threshold_floor is None else list(tr.threshold_floor),
    }


def _restore(ckpt: dict[str, Any], state: FusionState) -> None:
    state.model = GaussianModel.empty(int(ckpt["n_gaussians"]), int(ckpt["sh_degree"]),
                                      device=state.log_gain.device)
    state.model.load_state_dict(ckpt["model"])
    state.trajectory.load_state_dict(ckpt["trajectory"]["state"])
    state.threshold.load_state_dict(ckpt["threshold"])
    with torch.no_grad():
        state.log_gain.copy_(ckpt["log_gain"])


def train(scene: Scene, cfg: DeblurConfig, out_dir: Path, *, resume: bool = False,
          calibration: SensorThresholds | None = None, until: int | None = None) -> Trained:
    """Fit the scene; checkpoints go to ``out_dir/checkpoint.pt`` (also on Ctrl-C).

    ``calibration`` gives the starting ON/OFF thresholds (``fusiongs calibrate``); without it they
    are estimated the same way (:func:`initial_theta`).

    ``until``: stop at that iteration, before its step (after ``threshold.render_floor`` when that
    is the iteration the events start), with every schedule still that of the whole run: the state
    is the one a full run has there (``fusiongs calibrate --refine``).

    The progress bar shows the loss, the number of Gaussians and a running PSNR of the re-rendered
    blurry frames against the captured ones.
    """
    from tqdm import tqdm

    check_device(cfg.device)
    device = training_device(cfg.device)
    torch.manual_seed(cfg.seed)
    # `gen` (host) draws what the host needs as numbers: the frame order, event window times,
    # exposure pairs and crops (the same on every device); `device_gen` draws the event pixels
    # where the count maps are
    gen = torch.Generator(device="cpu").manual_seed(cfg.seed)
    device_gen = torch.Generator(device=device).manual_seed(cfg.seed)
    data = prepare_data(scene, device, cfg.events.enabled)
    theta0 = initial_theta(scene, data, cfg, calibration)
    wants_edi = cfg.priors.edi_weight > 0 or (cfg.init.method != "random" and data.n_frames >= 2)
    if wants_edi and data.events is not None and data.n_frames:
        # thresholds of the EDI images: configured, else the calibration (reused, not redone)
        data.edi = edi_images(scene, cfg.priors.edi_theta or theta0, device, cfg.events.reset_weights)
    if data.n_frames == 0:  # event-only: the HPF intensity anchor (Event-3DGS)
        eo = cfg.event_only
        data.hpf_times, data.hpf = hpf_images(data.events, data.t_range, eo.hpf_readouts,
                                              eo.intensity_tau, cfg.threshold.init, device)
    if cfg.events.censor > 0 and data.events is not None:
        data.fast = censor_events(data, cfg, theta0, device)
    if cfg.events.reset_weights and data.events is not None:
        data.event_weight = reset_event_weights(data, theta0, device)
    trajectory = build_trajectory(scene, cfg)
    fill = frame_colour(scene, data, cfg)
    colour_scale = colour_lr_scale(fill)
    state = build_state(data, scene.poses.c2w, trajectory, cfg, device, theta0.as_array(),
                        init_images(scene, data, cfg, fill), fill)
    cfg, motion = renders_per_exposure(cfg, data, state)
    if cfg.events.loss == "pvc" and data.events is not None:  # read-outs at the N exposure instants
        data.pvc_times, data.pvc = pvc_readouts_for(data, cfg, device)
    extent = scene_extent(scene.poses.c2w, state.depth_far)
    start, history = 0, History()
    # the frame order is the first draw of `gen`, made before a checkpoint replaces its state: a
    # resumed run visits the frames in the same order
    order = torch.randperm(max(data.n_frames, 1), generator=gen, device=gen.device).tolist()
    ckpt_path = out_dir / "checkpoint.pt"
    ckpt = load_checkpoint(ckpt_path) if resume and ckpt_path.exists() else None
    strategy = DensifyStrategy(_densify_config(cfg), extent, seed=cfg.seed)
    psnr_now = None  # running mean of the blurry-frame PSNR (re-rendered input), on the device
    if ckpt is None:
        opts = _optimizers(state, cfg, extent, colour_scale)
        # said once, when the run starts (a resumed run's calibration.json carries them)
        for warning in calibration_warnings(theta0):
            print(f"fusiongs: calibration warning: {warning}", file=sys.stderr)
    else:
        with checkpoint_errors(ckpt_path):  # a foreign or edited checkpoint: one line, not a trace
            _restore(ckpt, state)
            start = int(ckpt["iteration"])
            history = History(**ckpt["history"])
            gen.set_state(ckpt["generator"])
            saved = ckpt.get("device_generator", {})
            if saved.get("device") == device_gen.device.type:  # else (another device) freshly seeded
                device_gen.set_state(saved["state"])
            opts = _optimizers(state, cfg, extent, colour_scale)
            for k, o in opts.items():
                if k in ckpt.get("optimizers", {}):
                    o.load_state_dict(ckpt["optimizers"][k])
            if "densify" in ckpt:  # statistics since the last refinement, the split generator
                strategy.load_state_dict(ckpt["densify"], state.model.means.device)
            if ckpt.get("psnr_running") is not None:
                psnr_now = ckpt["psnr_running"].to(device)
    tr = Trained(state, data, cfg, history, start, scene.poses, theta0, exposure_motion_px=motion)
    if ckpt is not None and ckpt.get("threshold_floor") is not None:
        with checkpoint_errors(ckpt_path):
            before, after = (torch.as_tensor(v, dtype=torch.float64) for v in ckpt["threshold_floor"])
            shape = tuple(state.threshold.log_theta.shape)
            if before.shape != shape or after.shape != shape:
                raise ValueError(f"threshold_floor of shape {tuple(before.shape)}, not {shape}")
            tr.threshold_floor = before, after
    # a bar on a terminal only: a log or CI gets pipeline.run_deblur's one summary line
    tty = sys.stderr is not None and sys.stderr.isatty()
    bar = tqdm(range(start, cfg.optim.iterations), initial=start, total=cfg.optim.iterations,
               disable=not (cfg.output.progress and tty), desc="fusiongs", dynamic_ncols=True,
               file=sys.stderr)
    pending: list[PendingRow] = []
    # kept window ends of the last steps (not in the checkpoint: a resumed run starts it empty)
    lp_history = LowpassHistory(cfg.events.lowpass_history) if cfg.events.lowpass_history else None
    probe = truth_probe(scene) if cfg.output.truth_every > 0 else None
    t_begin, seconds_before = time.perf_counter(), history.seconds

    def save() -> None:
        flush_pending(history, pending, bar)
        history.seconds = seconds_before + time.perf_counter() - t_begin
        save_checkpoint(ckpt_path, _payload(tr, opts, gen, device_gen, strategy, psnr_now))
        write_history(history, out_dir / "history.jsonl")

    try:
        for it in bar:
            t_step = time.perf_counter()
            frame = order[it % len(order)]
            lam_ev = _event_weight(cfg, data, it)
            if it == cfg.events.warmup and cfg.threshold.render_floor:
                tr.threshold_floor = _floor_thresholds(state, data, cfg)
            if until is not None and it >= until:
                break
            _schedule(state, strategy, opts, cfg, it, extent, lam_ev)
            res = training_step(state, data, cfg, frame, lam_ev, gen, it, _coarse(cfg, data, it, lam_ev),
                                device_gen=device_gen, lowpass_history=lp_history)
            strategy.step_pre_backward(res.meta)
            loss = res.loss + _regularisers(state, cfg, data.n_frames)
            t_back = time.perf_counter()
            loss.backward()
            history.backward_seconds += time.perf_counter() - t_back
            history.render_seconds += res.render_seconds
            _optimise(opts, cfg, it, state, colour_scale)
            if cfg.densify.enabled:
                strategy.step_post_backward(state.model, opts["gaussians"], res.meta, it)
            tr.iteration = it + 1
            history.step_seconds.append(time.perf_counter() - t_step)
            if "psnr" in res.parts:
                p = res.parts["psnr"]
                psnr_now = p if psnr_now is None else 0.9 * psnr_now + 0.1 * p
            row = history_row(loss.detach(), res.parts, state, psnr_now)
            pending.append(PendingRow(it, row, state.model.n, lam_ev))
            if (it + 1) % FLUSH_EVERY == 0:
                flush_pending(history, pending, bar)
            if probe is not None and should_probe(it, cfg.output.truth_every, cfg.optim.iterations):
                raw, fit = probe_psnr(state, data.camera, probe, cfg.backend,
                                      auto_exposure=auto_exposure(cfg, data.n_frames))
                history.truth_iteration.append(it)
                history.psnr_truth.append(raw)
                history.psnr_truth_fit.append(fit)
            every = cfg.output.checkpoint_every
            if every and (it + 1) % every == 0 and it + 1 < cfg.optim.iterations:
                save()
    except KeyboardInterrupt:
        save()
        raise
    save()
    return tr


def pvc_readouts_for(data: TrainData, cfg: DeblurConfig, device: torch.device
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``pvc`` targets' read-outs: every exposure instant, the event-only anchor instants and a
    grid of ``events.min_window`` spacing (at most 2000 steps over the stream)."""
    instants = [exposure_instants(data.exposures[:, 0], data.exposures[:, 1], cfg.blur.n_samples)
                .reshape(-1).numpy()]  # host tensors
    if data.hpf_times is not None:
        instants.append(data.hpf_times.numpy())
    span = data.t_range[1] - data.t_range[0]
    spacing = max(cfg.events.min_window, span / 2000)
    flat = np.concatenate(instants)
    return pvc_readouts(data.events, flat, data.t_range, spacing, cfg.events.hpf_tau,
                        cfg.threshold.init, device)


def frame_colour(scene: Scene, data: TrainData, cfg: DeblurConfig) -> torch.Tensor | None:
    """``[3]`` float32 linear: the mean colour of a one-frame scene's frame, which the first
    Gaussians start from when they come from the events (:func:`event_stereo_start`) and
    ``init.start_colour`` is ``"frame"``, or ``"auto"`` with grey events; None otherwise (grey 0.5).

    Grey events carry no colour and the band loss no level, so what the frame never saw keeps the
    colour it started with: the frame's mean is a measured guess, not an assumed grey. Colour
    events see each channel's changes, and there the near-black mean of a mostly unlit frame (with
    the colour rates scaled to it) kept the lit objects too dark: on the one-frame `dark` RGGB
    scenes the grey start scored 1.5-3 dB higher.
    """
    mode = cfg.init.start_colour
    if mode == "auto":
        mode = "grey" if data.cfa_index is not None else "frame"
    if mode != "frame" or data.n_frames == 0 or not event_stereo_start(data, cfg):
        return None
    lin = np.asarray(scene.frames.to_linear(), dtype=np.float64)  # [F, H, W, C]
    mean = torch.from_numpy(lin.reshape(-1, lin.shape[-1]).mean(axis=0)).float()
    return mean.expand(3).clone() if mean.numel() == 1 else mean


def init_images(scene: Scene, data: TrainData, cfg: DeblurConfig,
                fill: torch.Tensor | None = None) -> torch.Tensor | None:
    """Images the stereo initialisation matches: the EDI frames when there are events, else the
    (blurry) frames in linear light; without frames, or with one frame (:func:`event_stereo_start`),
    the HPF images of the events at the instants the first Gaussians are posed at
    (:func:`fusiongs.train.data.event_stereo_images`), tinted to ``fill`` (``[3]`` linear, the
    level their ``exp(V) = 1`` maps to; grey 0.5 when None); None for the random initialisation."""
    if cfg.init.method == "random":
        return None
    if event_stereo_start(data, cfg):
        if data.events is None or not len(data.events):
            return None
        hpf = event_stereo_images(data.events, data.t_range, EVENT_ONLY_VIEWS, cfg.event_only.intensity_tau,
                                  cfg.threshold.init, data.cfa_index is not None)
        return hpf if fill is None else (hpf * (fill.to(hpf) / 0.5)).clamp(0.0, 1.0)
    if data.edi is not None:
        return data.edi
    return torch.from_numpy(np.ascontiguousarray(scene.frames.to_linear(), dtype=np.float32))


def initial_theta(scene: Scene, data: TrainData, cfg: DeblurConfig,
                  calibration: SensorThresholds | None = None) -> SensorThresholds:
    """Thresholds to start from (docs/method.md section 4): ``calibration`` when given, else the
    estimate of ``fusiongs calibrate`` when ``threshold.estimate`` is on and there are events,
    else ``threshold.init`` for both polarities. One pair per CFA channel for colour events."""
    from fusiongs.events.thresholds import SensorThresholds

    cfa = scene.events.cfa if scene.events is not None else None
    if calibration is not None:
        return calibration.for_sensor(cfa)
    if not (cfg.threshold.estimate and scene.events is not None and len(scene.events)):
        return SensorThresholds.uniform(cfg.threshold.init, cfg.threshold.init, cfa, "threshold.init")
    from fusiongs.calibrate.estimate import estimate_thresholds
    from fusiongs.calibrate.options import CalibrateOptions

    opts = CalibrateOptions(unknown_scale=cfg.threshold.init)
    try:
        return estimate_thresholds(scene.frames, scene.events, opts).for_sensor(cfa)
    except InputError as e:  # too little data to measure: say so, start from threshold.init
        print(f"fusiongs: thresholds not estimated ({e}); starting from threshold.init = "
              f"{cfg.threshold.init}", file=sys.stderr)
        return SensorThresholds.uniform(cfg.threshold.init, cfg.threshold.init, cfa, "threshold.init")


def censor_events(data: TrainData, cfg: DeblurConfig, theta0: SensorThresholds,
                  device: torch.device) -> torch.Tensor | None:
    """``[E]`` bool: the fast events, whose pixels' counts are lower bounds (``events.censor`` times
    the dead time; the calibration's estimate, else measured here); None when the stream shows no
    refractory floor."""
    from fusiongs.events.dead_time import dead_time_us
    from fusiongs.train.data import fast_events

    dead = detail_number(theta0, "dead_time_us")  # a calibration.json may come from elsewhere
    if dead is None:
        dead = dead_time_us(data.events)
    if dead <= 0:
        return None
    return fast_events(data.events, cfg.events.censor * float(dead), device)


def reset_event_weights(data: TrainData, theta0: SensorThresholds, device: torch.device
                        ) -> torch.Tensor | None:
    """``[E]`` float32 crossings each event stands for on ``device``, where the calibration chose
    the pixel model of a pixel held in reset; None otherwise, and the events count once each
    (:func:`~fusiongs.events.thresholds.calibration_event_weights`, which EDI uses too). A reset
    calibration whose dead time or cap is not a number (a file from elsewhere) is an
    :class:`InputError`."""
    w = calibration_event_weights(data.events, theta0)
    return None if w is None else torch.from_numpy(w).to(device)


def _floor_thresholds(state: FusionState, data: TrainData, cfg: DeblurConfig
                      ) -> tuple[torch.Tensor, torch.Tensor] | None:
    """``threshold.render_floor``: raise θ to what the renders fit to the counts; says so.
    Returns ``(θ before, θ after)`` (``[2, C]`` host float64), or None where it does not apply."""
    from fusiongs.train.render_threshold import apply_render_floor

    moved = apply_render_floor(state, data, cfg)
    if moved is not None and not torch.equal(*moved):
        def fmt(t: torch.Tensor) -> str:
            return "ON " + "/".join(f"{v:.3f}" for v in t[0].tolist()) + ", OFF " + "/".join(
                f"{v:.3f}" for v in t[1].tolist())
        print(f"fusiongs: θ raised to the renders' floor when the events start: {fmt(moved[0])} -> "
              f"{fmt(moved[1])}", file=sys.stderr)
    return None if moved is None else (moved[0].double(), moved[1].double())


def _event_weight(cfg: DeblurConfig, data: TrainData, it: int) -> float:
    """λ_ev with frames; α of ``α·L_ev + (1−α)·L_intensity`` without them (event-only mode)."""
    if data.n_frames == 0:
        eo = cfg.event_only
        return event_only_alpha(it, eo.alpha_warmup, eo.alpha_final, eo.alpha_ramp)
    return event_weight(it, cfg.events.warmup, cfg.events.weight, cfg.events.ramp)


def _coarse(cfg: DeblurConfig, data: TrainData, it: int, lam_ev: float) -> int:
    """Resolution divisor now: ``blur.coarse_factor`` before ``blur.coarse_until`` while the
    event loss is off (with frames), else 1."""
    b = cfg.blur
    if data.n_frames and lam_ev == 0 and it < b.coarse_until and b.coarse_factor > 1:
        return b.coarse_factor
    return 1


def _schedule(state: FusionState, strategy: DensifyStrategy, opts, cfg: DeblurConfig, it: int,
              extent: float, lam_ev: float) -> None:
    """Learning rates, θ frozen during the warm-up, opacity reset off once events are on."""
    _set_learning_rates(opts, cfg, it, extent)
    learn_theta = cfg.threshold.learn and lam_ev > 0
    state.threshold.unfreeze() if learn_theta else state.threshold.freeze()
    if lam_ev > 0:
        strategy.disable_opacity_reset()


def _regularisers(state: FusionState, cfg: DeblurConfig, n_frames: int) -> torch.Tensor:
    """θ pulled toward its start (event-only mode) and the smoothness of a θ field / drift.

    The pull is for scenes without frames only, whose events cannot fix θ's common scale. With a
    frame the scale is observable (the frame fixes the log contrast of the texture the events see
    move): on four one-frame tuning scenes θ then moved toward the truth, from 26-28 % low to
    within 6 %, and from 33-44 % high to 23-24 % high.
    """
    total = state.log_gain.new_zeros(())
    if cfg.threshold.regularise > 0 and n_frames == 0:
        total = total + cfg.threshold.regularise * state.threshold.regularisation()
    if cfg.threshold.grid is not None or cfg.threshold.time_knots:
        total = total + cfg.threshold.smoothness * state.threshold.smoothness()
    return total


def _optimise(opts: dict[str, torch.optim.Optimizer], cfg: DeblurConfig, it: int,
              state: FusionState, colour_scale: float = 1.0) -> None:
    """One step of every optimiser. With ``optim.colour_step: relative`` (from
    ``colour_step_start``) each colour's step is scaled by its level over the start level
    ``0.5 * colour_scale`` (grey, or the frame's fill, for which :func:`colour_lr_scale` has
    already scaled the colour rates)."""
    for name, opt in opts.items():
        if name == "pose" and it < cfg.optim.pose_start:
            opt.zero_grad(set_to_none=True)
            continue
        if name == "gaussians" and cfg.optim.colour_step == "relative" and it >= cfg.optim.colour_step_start:
            relative_colour_step(state.model, opt.step, cfg.optim.colour_step_floor, 0.5 * colour_scale)
        else:
            opt.step()
        opt.zero_grad(set_to_none=True)
