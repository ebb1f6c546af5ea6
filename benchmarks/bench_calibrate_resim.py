"""Issue 13 diagnosis: does re-simulating a scene reproduce the threshold estimator's bias?

Indirect inference (Gouriéroux, Monfort & Renault, J. Applied Econometrics 1993): run the
estimator on the scene, ``θ̂ = E(frames, events)``; make the scene's events again from a video of
it with nominal thresholds ``θ'`` (first ``θ̂``), run the same estimator on that, ``θ̂'``, and take its
bias ``b = θ̂' / θ'`` (per polarity and channel) off the first estimate: ``θ_corr = θ̂ / b``;
``--iters`` repeats it with ``θ'`` = the last ``θ_corr``, ``--reps`` averages ``log b`` over that many
sensor draws. If the bias comes from the scene and the sensor (dead time at steep edges, the
reference level's lag, the gates), a faithful re-simulation shows it, whatever its mechanism.

The video (``--video``):

- ``sim``: the simulator's own dense renders of a simulated scene (1 kHz, as its DVS model saw
  them) and the scene's own frames: the ceiling, since no real recording has it;
- ``flow``: EDI-sharp frames (with ``θ̂``) warped along OpenCV DIS optical flow between
  neighbouring frames (linear motion, both neighbours blended), at the simulator's rate;
- ``model``: the renders of a finished ``fusiongs deblur`` run of the scene (``--run``: its
  Gaussians, refined trajectory and exposure gains).

Two diagnosis variants of ``sim`` (frames made again from the video, as below): ``--blur SIGMA``
blurs every image of the simulator's video by a Gaussian of ``SIGMA`` px before the sensor sees
it (how sharp must a twin be?), and ``--trajectory run`` renders the simulator's world along the
refined trajectory of ``--run`` instead of the true one (is the trajectory what a twin misses?).
Every row prints the video's *fast steps*, the changes of log intensity above 0.3 within one
1-ms render step, beside the scene's own (the simulator's video) where it differs.

For ``flow`` and ``model`` the blurry frames are made again too: the video's mean over each
exposure, encoded as the scene's frames (``--real-frames`` keeps the scene's own instead, to tell
whether the events or the frames of a video miss the bias). The sensor's other parameters
(``--sensor``): ``true`` (the simulator's; a diagnosis only) or ``est``, from the recording
alone (:func:`estimated_sensor`: the estimator's dead time and threshold spread, the spatial hot
pixels and their rate, background activity and leak from isolated events,
:func:`isolated_rates`). ``--spread N`` instead reports the estimator's own spread: N draws of
the scene's sensor at its true thresholds (``sim`` video).

Simulated scenes only (the truth is read to score), tuning seeds for any choice.

    PYTHONPATH=. python benchmarks/bench_calibrate_resim.py SCENE [--video sim|flow|model]
        [--run RUN] [--sensor true|est] [--real-frames] [--blur SIGMA] [--trajectory true|run]
        [--iters 2] [--reps 1] [--spread N] [--json FILE]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_event_only_diagnose import sim_config, true_logs  # noqa: E402
from fusiongs.errors import InputError  # noqa: E402
from fusiongs.eval.calibrate import estimate_thresholds  # noqa: E402
from fusiongs.eval.edi import edi_scene  # noqa: E402
from fusiongs.eval.truth import read_sim_facts  # noqa: E402
from fusiongs.events.cfa import cfa_channel_index  # noqa: E402
from fusiongs.events.stats import spatial_hot_pixels  # noqa: E402
from fusiongs.events.stream import EventStream  # noqa: E402
from fusiongs.frames.frameset import FrameSet  # noqa: E402
from fusiongs.io import load_scene  # noqa: E402
from fusiongs.sim import dvs  # noqa: E402
from fusiongs.sim.dvs import REC601, DVSParams  # noqa: E402
from fusiongs.sim.exposure import encode_linear16, encode_srgb8  # noqa: E402
from fusiongs.sim.simulate import (  # noqa: E402
    SimConfig,
    _pixel_events,
    noise_events,
    scene_renderer,
    sensor_draws,
)


def scene_truth(scene: Path) -> tuple[SimConfig, dict]:
    """The scene's :class:`SimConfig` and ``gt/sim.json`` facts; ``ValueError`` (one line) for a
    scene without them (simulated scenes only)."""
    facts = read_sim_facts(scene)
    if facts is None or "config" not in facts:
        raise ValueError(f"{scene}: no gt/sim.json with its config (a simulated scene is needed)")
    return sim_config(scene), facts


def dense_times(cfg: SimConfig) -> np.ndarray:
    """``[K+1]`` instants (s) of the simulator's event renders."""
    return np.linspace(0.0, cfg.duration, int(round(cfg.duration * cfg.dvs_rate_hz)) + 1)


def own_log(img: np.ndarray, cfa_idx: np.ndarray | None, eps: float) -> np.ndarray:
    """``[H*W]`` ``log(I + eps)`` each event pixel sees of a linear RGB image ``[H, W, 3]``."""
    inten = img @ np.asarray(REC601, np.float32) if cfa_idx is None else np.take_along_axis(
        img, cfa_idx[..., None], -1)[..., 0]
    return np.log(np.maximum(inten, 0) + eps).reshape(-1)


def video_from(image_at, frames: FrameSet, times: np.ndarray, cfa: str | None, eps: float,
               shape: tuple[int, int], gains: np.ndarray | None = None) -> tuple[np.ndarray, FrameSet]:
    """Sensor logs ``[K+1, H*W]`` of the linear images ``image_at(k, t)`` ``[H, W, 3]`` and blurry
    frames made from them (each exposure's mean, times ``gains [F]`` when given, encoded as
    ``frames``)."""
    h, w = shape
    idx = None if cfa is None else cfa_channel_index(cfa, h, w).astype(np.int64)
    ts, te = np.asarray(frames.t_start), np.asarray(frames.t_end)
    logs = np.empty((len(times), h * w), np.float32)
    sums = np.zeros((len(frames), h, w, 3), np.float64)
    n = np.zeros(len(frames))
    for k, t in enumerate(times):
        img = np.clip(image_at(k, float(t)), 0, None)
        logs[k] = own_log(img, idx, eps)
        inside = (ts <= t) & (t <= te)
        sums[inside] += img
        n[inside] += 1
    mean = sums / np.maximum(n, 1)[:, None, None, None]
    if gains is not None:
        mean = mean * np.asarray(gains, np.float64)[:, None, None, None]
    enc = encode_linear16 if frames.response == "linear" else encode_srgb8
    imgs = np.stack([enc(m) for m in mean]).astype(np.float32)
    if frames.images.shape[-1] == 1:
        imgs = (imgs @ np.asarray(REC601, np.float32))[..., None]
    return logs, FrameSet(imgs, frames.t_start, frames.t_end, frames.names, frames.response)


def flows(sharp: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Forward (i -> i+1) and backward (i+1 -> i) DIS flows ``[H, W, 2]`` of sharp linear frames."""
    lum = sharp.mean(-1)
    g = (255 * np.clip(lum / np.quantile(lum, 0.995), 0, 1) ** (1 / 2.2)).astype(np.uint8)
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return ([dis.calc(g[i], g[i + 1], None) for i in range(len(g) - 1)],
            [dis.calc(g[i + 1], g[i], None) for i in range(len(g) - 1)])


def warp(img: np.ndarray, flow: np.ndarray, u: float) -> np.ndarray:
    """``img`` sampled at ``x + u * flow(x)`` (bilinear, borders replicated)."""
    h, w = flow.shape[:2]
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    u = np.float32(u)
    return cv2.remap(img, gx + u * flow[..., 0], gy + u * flow[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


def flow_video(scene, theta, cfg: SimConfig) -> tuple[np.ndarray, FrameSet]:
    """``flow`` video: EDI-sharp frames (thresholds ``theta``) moved along their flows."""
    fs = scene.frames
    sharp = np.clip(edi_scene(scene, theta).astype(np.float32), 0, None)
    if sharp.shape[-1] == 1:
        sharp = np.repeat(sharp, 3, -1)
    mids = 0.5 * (np.asarray(fs.t_start) + np.asarray(fs.t_end))
    fw, bw = flows(sharp)

    def image_at(_k: int, t: float) -> np.ndarray:
        if t <= mids[0]:  # before the first frame: its forward flow, backwards
            return warp(sharp[0], fw[0], -(t - mids[0]) / (mids[1] - mids[0]))
        if t >= mids[-1]:
            return warp(sharp[-1], bw[-1], (t - mids[-1]) / (mids[-1] - mids[-2]))
        i = min(int(np.searchsorted(mids, t, side="right")) - 1, len(mids) - 2)
        s = (t - mids[i]) / (mids[i + 1] - mids[i])
        return (1 - s) * warp(sharp[i], fw[i], -s) + s * warp(sharp[i + 1], bw[i], -(1 - s))

    return video_from(image_at, fs, dense_times(cfg), cfg.cfa, cfg.dvs.eps, sharp.shape[1:3])


def model_video(scene, run: Path, cfg: SimConfig) -> tuple[np.ndarray, FrameSet]:
    """``model`` video: a finished deblur run's renders, its median exposure gain applied (each
    frame's own gain in the re-made blurry frames)."""
    from fusiongs.train.render_io import render_linear
    from fusiongs.train.restore import restore_state

    state, camera, _ = restore_state(run / "checkpoint.pt")
    gains = np.exp(state.log_gain.detach().cpu().numpy().astype(np.float64))
    g_mid = float(np.median(gains))
    times = dense_times(cfg)
    chunk: dict[int, np.ndarray] = {}

    def image_at(k: int, _t: float) -> np.ndarray:
        if k not in chunk:
            chunk.clear()
            lin = render_linear(state, camera, times[k:k + 50], batch=10) * g_mid
            chunk.update({k + j: img for j, img in enumerate(lin)})
        return chunk[k]

    return video_from(image_at, scene.frames, times, cfg.cfa, cfg.dvs.eps, (camera.height, camera.width),
                      gains / g_mid)


def sim_video(scene, cfg: SimConfig, blur: float = 0.0, run: Path | None = None
              ) -> tuple[np.ndarray, FrameSet]:
    """``sim`` video variants: the simulator's world along its true trajectory (or the refined one
    of the deblur run ``run``), every image blurred by a Gaussian of ``blur`` px (0: none)."""
    sr = scene_renderer(cfg)
    if run is not None:
        from fusiongs.train.restore import restore_state

        traj = restore_state(run / "checkpoint.pt")[0].trajectory

        def pose(t: float) -> np.ndarray:
            with torch.no_grad():
                return traj.c2w(torch.tensor([t], dtype=torch.float64))[0].double().cpu().numpy()
    else:
        def pose(t: float) -> np.ndarray:
            return sr.trajectory.c2w(np.array([t]))[0]

    def image_at(_k: int, t: float) -> np.ndarray:
        img = np.ascontiguousarray(sr.caster.render(pose(t)).cpu().numpy(), np.float32)
        return cv2.GaussianBlur(img, (0, 0), blur, borderType=cv2.BORDER_REPLICATE) if blur > 0 else img

    return video_from(image_at, scene.frames, dense_times(cfg), cfg.cfa, cfg.dvs.eps, (cfg.height, cfg.width))


def fast_steps(logs: np.ndarray, step: float = 0.3) -> int:
    """How many changes of log intensity above ``step`` one render step of ``logs [K+1, P]`` holds
    (the fast, large changes where the dead time loses crossings)."""
    return int(sum(int((np.abs(logs[k + 1] - logs[k]) > step).sum()) for k in range(len(logs) - 1)))


def isolated_rates(events: EventStream, hot: np.ndarray, duration: float, bin_s: float = 0.01
                   ) -> tuple[float, float]:
    """ON and OFF rates (Hz per pixel) of isolated events: those in (``bin_s`` x 1 px) cells whose
    3 x 3 x 3 neighbourhood (pixels x time bins) holds no other event, over the time-area of such
    empty neighbourhoods. Background activity fires either polarity alike, a leaking pixel ON
    only, and neither waits for its neighbours, so ``2 OFF`` and ``ON − OFF`` estimate the two
    (edges' events come in spatio-temporal groups and are mostly not isolated).

    Args:
        events: the stream. hot: ``[H*W]`` bool pixels left out (hot pixels).
        duration: the stream's span (s).
    """
    nb = max(int(np.ceil(duration / bin_s)), 1)
    h, w = events.height, events.width
    pix = events.y.astype(np.int64) * w + events.x
    keep = ~hot[pix]
    step = np.minimum((events.t[keep] - events.t[0]) * 1e-6 / bin_s, nb - 1).astype(np.int64)
    cell = step * (h * w) + pix[keep]
    on = events.p[keep] > 0
    cnt_on = np.bincount(cell[on], minlength=nb * h * w).reshape(nb, h, w).astype(np.float32)
    cnt_off = np.bincount(cell[~on], minlength=nb * h * w).reshape(nb, h, w).astype(np.float32)
    cnt = torch.from_numpy(cnt_on + cnt_off)
    around = torch.nn.functional.avg_pool3d(cnt[None, None], 3, stride=1, padding=1)[0, 0] * 27 - cnt
    quiet = (around < 0.5).numpy()
    quiet[:, hot.reshape(h, w)] = False
    area = max(float(quiet.sum()) * bin_s, 1e-12)
    return float(cnt_on[quiet].sum()) / area, float(cnt_off[quiet].sum()) / area


def estimated_sensor(params: DVSParams, est, events: EventStream, duration: float) -> tuple[DVSParams, float]:
    """``params`` with the dead time (the located refractory period), hot pixels, background
    activity and leak as the recording tells them (θ fields unchanged; ``eps`` kept), and the
    relative threshold spread (from the estimator's details)."""
    d = est.details
    var = (d.get("threshold_spread") or {}).get("log_variance", [0.0, 0.0])
    rel = float(np.sqrt(max(float(np.mean(var)), 0.0)))
    hot = spatial_hot_pixels(events).reshape(-1)
    per = np.bincount(events.y.astype(np.int64) * events.width + events.x, minlength=hot.size)
    r_on, r_off = isolated_rates(events, hot, duration)
    # the refractory period located to 1 µs (session 55; before it the histogram bin's left edge,
    # up to 15 % short, made the twin's dead time)
    dead_us = d.get("refractory_period_us", d["dead_time_us"])
    out = dataclasses.replace(params, refractory_s=float(dead_us) * 1e-6,
                              ba_rate_hz=2.0 * r_off, leak_rate_hz=max(r_on - r_off, 0.0),
                              hot_pixel_fraction=float(hot.sum()) / hot.size,
                              hot_pixel_rate_hz=float(per[hot].mean() / duration) if hot.any() else 0.0)
    return out, rel


def events_with(cfg: SimConfig, params: DVSParams, logs: np.ndarray, theta: tuple[float, float],
                sigma: float, seed: int) -> EventStream:
    """The DVS model of :func:`fusiongs.sim.simulate.run_simulation` on sensor logs ``[K+1, P]``
    with nominal thresholds ``theta`` (ON, OFF), spread ``sigma`` and the other fields of
    ``params``; ``seed`` draws the pixels' thresholds, noise, hot pixels and leak."""
    p = dataclasses.replace(params, theta_on=theta[0], theta_off=theta[1], theta_sigma=sigma)
    seeds = np.random.SeedSequence([cfg.seed, seed]).spawn(7)
    th_on, th_off, drift, phase = sensor_draws(p, logs.shape[1], cfg.width, seeds)
    ev = _pixel_events(logs, dense_times(cfg), th_on, th_off, p.refractory_s, drift, phase, 1.0,
                       p.refractory_reset)
    t_us, pix, pol = dvs.merge_sorted(ev, *noise_events(p, logs.shape[1], cfg.duration, seeds))
    return EventStream.create(t_us, pix % cfg.width, pix // cfg.width, pol, cfg.width, cfg.height,
                              cfg.cfa, source="re-simulation")


def _pct(err) -> str:
    return " ".join(f"{100 * v:+.1f}" for v in np.ravel(err))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", type=Path)
    ap.add_argument("--video", choices=("sim", "flow", "model"), default="sim")
    ap.add_argument("--run", type=Path, default=None, help="finished deblur run (--video model)")
    ap.add_argument("--sensor", choices=("true", "est"), default="true")
    ap.add_argument("--real-frames", action="store_true",
                    help="pair the video's events with the scene's own frames (which half is off)")
    ap.add_argument("--blur", type=float, default=0.0,
                    help="sim video: Gaussian blur (px) of every image, frames made again")
    ap.add_argument("--trajectory", choices=("true", "run"), default="true",
                    help="sim video: the simulator's world along the --run's refined trajectory")
    ap.add_argument("--iters", type=int, default=2)
    ap.add_argument("--reps", type=int, default=1)
    ap.add_argument("--spread", type=int, default=0, help="N draws at the true thresholds instead")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    needs_run = args.video == "model" or args.trajectory == "run"
    if needs_run and args.run is None:
        ap.error("--video model and --trajectory run need --run (a finished fusiongs deblur run of "
                 "the scene)")
    variant = bool(args.blur) or args.trajectory == "run"  # a changed simulator video
    if variant and args.video != "sim":
        ap.error("--blur and --trajectory run are variants of --video sim")
    if not (np.isfinite(args.blur) and args.blur >= 0):
        ap.error(f"--blur must be a finite number of pixels >= 0, got {args.blur}")
    if needs_run and not (args.run / "checkpoint.pt").is_file():
        ap.error(f"{args.run / 'checkpoint.pt'}: not found (--run: a finished fusiongs deblur run)")
    if min(args.iters, args.reps) < 1 or args.spread < 0:
        ap.error("--iters and --reps must be at least 1, --spread at least 0")
    try:
        cfg, facts = scene_truth(args.scene)
    except ValueError as exc:
        ap.error(str(exc))
    true = np.array([facts["theta_on"], facts["theta_off"]], np.float64)
    t0 = time.perf_counter()
    scene = load_scene(args.scene)
    row = {"scene": args.scene.name, "preset": facts["preset"], "cfa": facts["cfa"] or "grey",
           "true": true.tolist(), "refractory_ms": 1e3 * facts["refractory_s"], "video": args.video,
           "sensor": args.sensor, "events": len(scene.events)}
    head = f"{row['scene']} ({row['preset']} {row['cfa']}, dead time {row['refractory_ms']:.2f} ms)"
    if args.spread:
        logs = true_logs(args.scene)[1]
        errs = []
        for r in range(args.spread):
            ev = events_with(cfg, cfg.dvs, logs, (float(true[0]), float(true[1])),
                             float(facts["theta_sigma"]), 100 + r)
            e = estimate_thresholds(scene.frames, ev)
            errs.append(np.stack([e.theta_pos, e.theta_neg]) / true[:, None] - 1)
            print(f"{head} draw {r}: ON/OFF error per channel {_pct(errs[-1])} %", flush=True)
        row["spread_err"] = np.array(errs).tolist()
        print(f"{head} mean {_pct(np.mean(errs, 0))} %, std "
              + " ".join(f"{100 * v:.1f}" for v in np.std(errs, 0).ravel()) + " %")
    else:
        est = estimate_thresholds(scene.frames, scene.events)
        first = np.stack([est.theta_pos, est.theta_neg])  # [2, C]
        params, rel_sigma = cfg.dvs, facts["theta_sigma"] / float(true.mean())
        if args.sensor == "est":
            params, rel_sigma = estimated_sensor(cfg.dvs, est, scene.events, cfg.duration)
            row["sensor_est"] = dataclasses.asdict(params) | {"relative_spread": rel_sigma}
        frames = scene.frames
        if args.video == "sim" and variant:
            try:
                logs, frames = sim_video(scene, cfg, args.blur,
                                         args.run if args.trajectory == "run" else None)
            except InputError as exc:  # a checkpoint that does not load
                ap.error(str(exc))
            row |= {"blur_px": args.blur, "trajectory": args.trajectory}
        elif args.video == "sim":
            logs = true_logs(args.scene)[1]
        elif args.video == "flow":
            logs, frames = flow_video(scene, est, cfg)
        else:
            try:
                logs, frames = model_video(scene, args.run, cfg)
            except InputError as exc:  # a checkpoint that does not load
                ap.error(str(exc))
        if args.real_frames:
            frames = scene.frames
            row["frames"] = "the scene's own"
        row["fast_steps"] = fast_steps(logs)
        if args.video != "sim" or variant:
            row["fast_steps_scene"] = fast_steps(true_logs(args.scene)[1])
        row["first_err"] = (first / true[:, None] - 1).tolist()
        row["iters"] = []
        cur = first
        for it in range(args.iters):
            nominal = np.exp(np.log(cur).mean(1))  # one θ' per polarity, as the simulator draws
            log_b, n_ev = np.zeros_like(first), []
            for r in range(args.reps):
                ev = events_with(cfg, params, logs, (float(nominal[0]), float(nominal[1])),
                                 float(rel_sigma * nominal.mean()), 1 + it * args.reps + r)
                sim = estimate_thresholds(frames, ev)
                log_b += np.log(np.stack([sim.theta_pos, sim.theta_neg]) / nominal[:, None]) / args.reps
                n_ev.append(len(ev))
            cur = first / np.exp(log_b)
            row["iters"].append({"nominal": nominal.tolist(), "bias": (np.exp(log_b) - 1).tolist(),
                                 "corr_err": (cur / true[:, None] - 1).tolist(), "events": n_ev})
        print(f"{head} | {args.video} video, {args.sensor} sensor | estimate {_pct(row['first_err'])} % | "
              + " | ".join(f"iteration {k}: bias {_pct(r['bias'])}, corrected {_pct(r['corr_err'])}"
                           for k, r in enumerate(row["iters"]))
              + f" | events {len(scene.events)} real, {row['iters'][-1]['events'][0]} re-simulated"
              + f" | fast steps {row['fast_steps']}"
              + (f" (scene's own {row['fast_steps_scene']})" if "fast_steps_scene" in row else ""),
              flush=True)
    row["seconds"] = time.perf_counter() - t0
    if args.json:
        Path(args.json).write_text(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
