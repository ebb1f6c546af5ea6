"""One training iteration's losses (docs/method.md, 'Losses and schedule'), as a function of the state.

The N exposure instants of one frame and the instants of the free event windows are rendered in
one rasteriser call; the blur loss uses the first N renders, the event windows pairs of them
(E2NeRF) and the free renders.

Host and device: the step's draws (crop, window times, exposure pairs) come from a host generator
and stay Python numbers; the render instants are copied to the device without waiting, and the
event pixels are drawn by a generator on the device. Nothing here reads a device value back, so
a step queues its GPU work without synchronising (the loss terms stay on the device).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import torch

from fusiongs.losses.blur import apply_response, blur_loss, exposure_average, exposure_instants
from fusiongs.losses.colour import channel_weights_for, demosaic_event_maps
from fusiongs.losses.event import (
    delta_log,
    event_loss_band,
    event_loss_mse,
    event_loss_pvc,
    sample_event_pixels,
    select_channel,
    to_grey,
)
from fusiongs.losses.priors import (
    edi_prior_loss,
    intensity_prior_loss,
    smooth_log_gradient,
    total_variation_prior,
)
from fusiongs.render.rasterize import RenderMeta
from fusiongs.train.crop import Crop
from fusiongs.train.data import TrainData, block_mean, hpf_image_at
from fusiongs.train.lowpass_term import LowpassHistory, lowpass_term
from fusiongs.train.schedules import sample_chained_windows, sample_exposure_pairs, sample_free_windows
from fusiongs.train.settings import DeblurConfig
from fusiongs.train.state import FusionState


@dataclass
class StepResult:
    """One step's outputs. ``parts``: detached 0-dim tensors on the render device (``blur``,
    ``event``, ``edi``, ``intensity``, ``psnr`` of the re-rendered blurry frame), read with
    ``float()`` only when needed (a host sync on a GPU)."""

    loss: torch.Tensor
    parts: dict[str, torch.Tensor]
    meta: RenderMeta
    renders: torch.Tensor  # [T, H, W, 3] linear
    render_seconds: float = 0.0  # host time of the rasteriser call (launch time on a GPU)


def predict_blurry(linear: torch.Tensor, log_gain: torch.Tensor, response: str, channels: int,
                   grey_weights: tuple[float, float, float]) -> torch.Tensor:
    """Blurry frame ``[H, W, C]`` from ``[N, H, W, 3]`` sharp linear renders of one exposure.

    ``B = CRF(g · mean_k L_k)`` (docs/method.md §1); a monochrome frame (C = 1) sees ``w · L``.
    """
    mean = exposure_average(linear) * torch.exp(log_gain)
    if channels == 1:
        mean = to_grey(mean, grey_weights)
    return apply_response(mean, response)


def nearest_readout(times: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Index of the read-out in sorted ``times`` ``[R]`` nearest to each of ``t`` ``[...]`` (a tie
    goes to the later one)."""
    idx = torch.searchsorted(times, t.contiguous()).clamp(1, len(times) - 1)
    left_closer = (t - times[idx - 1]) < (times[idx] - t)
    return torch.where(left_closer, idx - 1, idx)


def snap_windows(windows: torch.Tensor, readouts: torch.Tensor) -> torch.Tensor:
    """Move both ends of each window ``[W, 2]`` to their nearest read-outs, keeping ``t_a < t_b``
    (when both meet one read-out, the start moves one read-out earlier)."""
    idx = nearest_readout(readouts, windows)
    ib = idx[:, 1].clamp(min=1)
    ia = torch.minimum(idx[:, 0], ib - 1)
    return torch.stack([readouts[ia], readouts[ib]], dim=1)


def _pvc_target(data: TrainData, t_a: float, t_b: float) -> torch.Tensor:
    """``[H, W]`` photovoltage contrast ``(V(t_b) − V(t_a)) / θ0`` (Event-3DGS; docs/method.md §2) from
    the precomputed read-outs; both ends must be read-out instants (found on the host)."""
    if data.pvc is None or data.pvc_times is None:
        raise RuntimeError("the pvc loss needs TrainData.pvc (see fusiongs.train.data.pvc_readouts)")
    t = torch.tensor([t_a, t_b], dtype=torch.float64, device=data.pvc_times.device)
    idx = nearest_readout(data.pvc_times, t)
    if float((data.pvc_times[idx] - t).abs().max()) > 1e-9:
        raise RuntimeError(f"event window [{t_a}, {t_b}) s does not end on pvc read-outs")
    a, b = idx.tolist()
    return data.pvc[b] - data.pvc[a]


def event_window_loss(state: FusionState, data: TrainData, cfg: DeblurConfig, lin_a: torch.Tensor,
                      lin_b: torch.Tensor, t_a: float, t_b: float, gen: torch.Generator,
                      crop: Crop | None = None) -> torch.Tensor:
    """Event loss of one window ``[t_a, t_b)`` from the linear renders ``[h, w, 3]`` at its ends.

    Args:
        gen: generator of the sampled pixels, on the renders' device.
        crop: the part of the sensor that ``lin_a`` / ``lin_b`` show (the whole sensor if None);
            pixels are sampled inside it.
    """
    ev = cfg.events
    device = lin_a.device
    crop = Crop.whole(data.camera) if crop is None else crop
    full_counts = data.count_maps(t_a, t_b, device)  # [2, H, W]
    counts = crop.maps(full_counts)
    pix = sample_event_pixels(counts, min(ev.pixels, counts[0].numel()), ev.frac_with_events, gen)
    full_pix = crop.full_index(pix)  # for θ fields and the CFA
    la, lb = lin_a.reshape(-1, 3)[pix], lin_b.reshape(-1, 3)[pix]
    full_signed = _pvc_target(data, t_a, t_b) if ev.loss == "pvc" else full_counts[0] - full_counts[1]
    signed = crop.maps(full_signed)
    th = state.threshold
    t_mid = 0.5 * (t_a + t_b)  # for a drifting θ
    censored = None  # [P, 1] counts that are lower bounds (grey and mask modes)
    if ev.loss in ("mse", "band") and (data.cfa_index is None or ev.colour_mode == "mask"):
        cens = data.censored_map(t_a, t_b, ev.censor_radius)
        censored = None if cens is None else cens.reshape(-1)[full_pix, None]
    if data.cfa_index is None:  # grey sensor: I = w · L
        d = delta_log(la, lb, "grey", ev.grey_weights, ev.log_eps)
        th_p, th_n = th.theta(full_pix, t=t_mid)
        n_pos, n_neg = counts[0].reshape(-1)[pix, None], counts[1].reshape(-1)[pix, None]
        d_gt = signed.reshape(-1)[pix, None]
        weights = None
    elif ev.colour_mode == "mask":  # each pixel in its own CFA channel on the raw grid
        ch = data.cfa_index.reshape(-1)[full_pix]
        d = select_channel(delta_log(la, lb, "rgb", eps=ev.log_eps), ch)
        th_p, th_n = th.theta(full_pix, t=t_mid, channel=ch)
        n_pos, n_neg = counts[0].reshape(-1)[pix, None], counts[1].reshape(-1)[pix, None]
        d_gt = signed.reshape(-1)[pix, None]
        weights = channel_weights_for(ch, ev.channel_weights)
    else:  # demosaic the window's event maps into three-channel targets (Event-3DGS app. C)
        pattern = data.events.cfa
        maps = demosaic_event_maps(torch.stack([full_counts[0], full_counts[1], full_signed]), pattern)
        flat = crop.images(maps).reshape(3, -1, 3)[:, pix]  # [3, P, 3]
        n_pos, n_neg, d_gt = flat[0], flat[1], flat[2]
        d = delta_log(la, lb, "rgb", eps=ev.log_eps)
        th_p, th_n = th.theta(full_pix, t=t_mid)
        # made on the host, copied without waiting (torch.tensor(..., device=cuda) would wait)
        weights = torch.tensor(ev.channel_weights, dtype=d.dtype, device="cpu").to(device, non_blocking=True)
    if ev.loss == "mse":
        return event_loss_mse(d, n_pos, n_neg, th_p, th_n, weights, censored)
    if ev.loss == "band":
        return event_loss_band(d, d_gt, th_p, th_n, ev.beta, weights, censored=censored)
    return event_loss_pvc(d, d_gt, th_p, th_n, kind="band", beta=ev.beta, channel_weights=weights)


def edi_prior_weight(cfg: DeblurConfig, it: int) -> float:
    """EDI prior weight: ``edi_weight`` decaying linearly to 0 at ``edi_until`` (docs/method.md §3)."""
    p = cfg.priors
    if p.edi_weight <= 0 or it >= p.edi_until:
        return 0.0
    return p.edi_weight * (1.0 - it / p.edi_until)


def snap_to_readouts(windows: torch.Tensor, readouts: torch.Tensor, t_min: float
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """Move each window ``[W, 2]`` so that it ends on its nearest read-out instant (same length).

    Returns:
        ``(windows [W, 2], readout index [W])``; starts are clamped to ``t_min``.
    """
    idx = nearest_readout(readouts, windows[:, 1])
    t_b = readouts[idx]
    t_a = (t_b - (windows[:, 1] - windows[:, 0])).clamp(min=t_min)
    return torch.stack([t_a, t_b], dim=1), idx


def longest_free_window(cfg: DeblurConfig, data: TrainData) -> float:
    """The longest free event window (s): one frame interval (the whole recording without frames),
    at most ``events.max_window`` (when set) and at most the time in which an average pixel fires
    ``events.window_events`` events (when set: the sensor's mean rate over all pixels and the
    recording). A window's count carries every event's share of threshold mismatch, refractory
    loss and noise, so capping the events it holds caps that accumulated error, while a slow
    scene (few events per second) keeps long windows."""
    ev = cfg.events
    span = data.t_range[1] - data.t_range[0]
    longest = min(ev.max_window or data.frame_interval, span)
    if ev.window_events > 0 and data.events is not None and len(data.events):
        rate = len(data.events) / (data.camera.width * data.camera.height * span)  # events / pixel / s
        longest = min(longest, ev.window_events / rate)
    return float(longest)


def own_channel(linear: torch.Tensor, data: TrainData, grey_weights) -> torch.Tensor:
    """``[H, W, 1]``: what each event pixel sees of a linear render ``[H, W, 3]``."""
    if data.cfa_index is None:
        return to_grey(linear, grey_weights)
    return linear.gather(-1, data.cfa_index[..., None])


def training_step(state: FusionState, data: TrainData, cfg: DeblurConfig, frame: int,
                  lam_ev: float, gen: torch.Generator, it: int = 0, coarse: int = 1, *,
                  device_gen: torch.Generator | None = None,
                  lowpass_history: LowpassHistory | None = None) -> StepResult:
    """Render and compute the losses of one iteration (docs/method.md §3).

    With frames: ``L_blur + λ_ev · L_ev`` (+ EDI prior) for one frame's exposure. Without frames
    (event-only mode): ``α · L_ev + (1 − α) · L_intensity`` on free windows, with ``lam_ev`` = α
    and the HPF intensity image at each window's end as the anchor (Event-3DGS), plus
    ``α · events.lowpass_weight · L_lowpass`` on the long windows between two free windows' ends
    (:mod:`fusiongs.train.lowpass_term`).

    Args:
        frame: index of the frame whose exposure is rendered (ignored without frames).
        gen: host (CPU) generator of the crop, the event window times and the exposure pairs.
        device_gen: generator on the state's device for the event pixels; ``gen`` if None (then
            the state must be on ``gen``'s device).
        lam_ev: event weight now (0 during the warm-up: no event renders are made then, except
            in event-only mode).
        it: the iteration (for the EDI prior's schedule).
        lowpass_history: the window ends of earlier steps for the low-pass term
            (``events.lowpass_history``); it is given this step's ends.
        coarse: render at ``1/coarse`` resolution against block-averaged frames (only without
            events in this step: count maps do not average like log intensities), with
            ``blur.coarse_n_samples`` renders per exposure when set.

    With ``blur.crop = (w, h)`` (and frames, at full resolution) every render of the step shows one
    random ``w`` × ``h`` crop; the blur and event losses are taken on it.
    """
    n = cfg.blur.n_samples
    if coarse > 1 and cfg.blur.coarse_n_samples is not None:
        n = cfg.blur.coarse_n_samples
    has_frames = data.n_frames > 0
    use_events = data.events is not None and (lam_ev > 0 or not has_frames)
    camera, targets = data.camera, data.targets
    if coarse > 1:
        if use_events or not has_frames:
            raise ValueError("coarse rendering is only for steps without events")
        camera, targets = data.coarse(coarse)
    crop = Crop.whole(camera)
    if has_frames and coarse == 1 and cfg.blur.crop is not None:
        crop = Crop.random(camera, cfg.blur.crop, gen)
        camera, targets = crop.camera(camera), crop.images(targets)
    times = []
    if has_frames:
        s, e = data.exposures[frame]
        times.append(exposure_instants(s, e, n).to(torch.float64))
    free = torch.zeros(0, 2, dtype=torch.float64, device=gen.device)
    readout = None
    has_free = use_events and cfg.events.windows_free > 0
    chain = has_free and cfg.events.chain_windows
    if has_free:
        longest = longest_free_window(cfg, data)
        shortest = min(cfg.events.min_window, longest)
    if chain:  # n windows in n + 1 renders; the anchors between read-outs (hpf_image_at)
        points = sample_chained_windows(cfg.events.windows_free, data.t_range, longest, gen, shortest)
        free = torch.stack((points[:-1], points[1:]), 1)
        times.append(points)
    elif has_free:
        free = sample_free_windows(cfg.events.windows_free, data.t_range, longest, gen, shortest)
        if data.hpf is not None:
            free, readout = snap_to_readouts(free, data.hpf_times, data.t_range[0])
        if data.pvc_times is not None:  # pvc targets exist at read-outs only
            free = snap_windows(free, data.pvc_times)
            if readout is not None:
                readout = nearest_readout(data.hpf_times, free[:, 1])
        times.append(free.reshape(-1))
    t_host = torch.cat(times)  # [T] float64 s, on the host
    t0 = time.perf_counter()
    lin, _, meta = state.render(camera, t_host, cfg.backend, check_values=False)  # poses on the host
    render_seconds = time.perf_counter() - t0
    eo = cfg.event_only
    if not has_frames and eo.gradient_blur > 0 and lin.requires_grad:
        values = lin.detach()
        lin.register_hook(lambda g: smooth_log_gradient(g, values, eo.gradient_blur, eo.gradient_blur_weight,
                                                        cfg.events.log_eps))
    parts: dict[str, torch.Tensor] = {}
    loss = lin.new_zeros(())
    if has_frames:
        pred = predict_blurry(lin[:n], state.log_gain[frame], data.response,
                              targets.shape[-1], cfg.events.grey_weights)
        l_blur = blur_loss(pred[None], targets[frame][None], cfg.blur.ssim_lambda)
        loss = loss + cfg.blur.weight * l_blur
        parts["blur"] = l_blur.detach()
        mse = ((pred.detach().clamp(0, 1) - targets[frame]) ** 2).mean()
        parts["psnr"] = -10.0 * torch.log10(mse.clamp_min(1e-12))
    lam_edi = edi_prior_weight(cfg, it)
    if has_frames and data.edi is not None and lam_edi > 0 and n % 2 == 1:
        edi = block_mean(data.edi[frame], coarse) if coarse > 1 else crop.images(data.edi[frame])
        l_edi = edi_prior_loss(lin[n // 2], edi)
        loss = loss + lam_edi * l_edi
        parts["edi"] = l_edi.detach()
    if use_events:
        t_list = t_host.tolist()
        windows = []
        if has_frames and n >= 2 and cfg.events.windows_inside > 0:
            pairs = sample_exposure_pairs(n, cfg.events.windows_inside, gen).tolist()
            windows += [(j, k, t_list[j], t_list[k]) for j, k in pairs]
        base = n if has_frames else 0
        stride = 1 if chain else 2  # renders per window: a chain's windows share their ends
        windows += [(base + stride * i, base + stride * i + 1, a, b)
                    for i, (a, b) in enumerate(free.tolist())]
        pixel_gen = gen if device_gen is None else device_gen
        if lam_ev > 0 and windows:
            l_ev = sum(event_window_loss(state, data, cfg, lin[j], lin[k], ta, tb, pixel_gen, crop)
                       for j, k, ta, tb in windows) / len(windows)
            loss = loss + lam_ev * l_ev
            parts["event"] = l_ev.detach()
        if lam_ev > 0 and cfg.events.lowpass_weight > 0 and not has_frames and len(free):
            if chain:  # each instant once: the long windows are its pairs at least `longest` apart
                ends = [(base + k, t, k) for k, t in enumerate(t_list[base:])]
            else:
                ends = [(base + 2 * i + k, t, i)
                        for i, ab in enumerate(free.tolist()) for k, t in enumerate(ab)]
            l_lp = lowpass_term(state, data, cfg, lin, ends, longest, lowpass_history)
            if l_lp is not None:
                loss = loss + lam_ev * cfg.events.lowpass_weight * l_lp
                parts["event_lowpass"] = l_lp.detach()
        anchors = []  # (render index, HPF image) at each window's end
        if readout is not None:
            anchors = [(base + 2 * i + 1, data.hpf[g]) for i, g in enumerate(readout.tolist())]
        elif chain and data.hpf is not None:
            anchors = [(base + k, hpf_image_at(data, t, eo.intensity_tau, cfg.threshold.init))
                       for k, t in enumerate(t_list[base:]) if k > 0]
        if anchors:
            seen = [own_channel(lin[j], data, cfg.events.grey_weights) for j, _ in anchors]
            l_int = sum(intensity_prior_loss(v, a, cfg.events.log_eps, cfg.event_only.anchor_highpass)
                        for v, (_, a) in zip(seen, anchors)) / len(anchors)
            loss = loss + (1.0 - lam_ev) * l_int
            parts["intensity"] = l_int.detach()
        if not has_frames and cfg.event_only.tv_weight > 0:
            l_tv = total_variation_prior(lin, cfg.event_only.tv_space, cfg.events.log_eps)  # every window end
            loss = loss + cfg.event_only.tv_weight * l_tv
            parts["tv"] = l_tv.detach()
    return StepResult(loss=loss, parts=parts, meta=meta, renders=lin, render_seconds=render_seconds)
