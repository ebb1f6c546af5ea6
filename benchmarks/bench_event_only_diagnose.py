"""Issue 18 diagnosis: event-only reconstruction with the true log-intensity changes as targets.

The *oracle* run keeps everything of ``fusiongs deblur --config event_only`` (windows, sampled
pixels, renders, α schedule, intensity anchor, densification) and replaces only the event target:
instead of ``θ+ n+ − θ− n−`` (or the band loss on counts) each sampled pixel is compared with the
true change of the log intensity it sees, ``log(I(t_b) + ε) − log(I(t_a) + ε)``, from the
simulator's own renderer (1 kHz renders, linear in time in between: what the DVS model sees). The
loss is the mse of the rendered change against it. If the oracle is sharp, the optimiser is not the
limit; if it is not, the event model is not the (only) limit.

Also reported: the *HPF floor*, the affine-fit PSNR of the leaky-integrator (high-pass filter)
intensity image that anchors event-only training, at the held-out instants.

``--true-theta`` gives every pixel its true ON and OFF threshold (fixed): what the per-pixel
threshold mismatch costs, e.g. of long windows. ``--true-geometry`` starts the Gaussians on the
simulator's true surfaces instead of the events' stereo points (grey, as the stereo's colours
would be replaced; the random share stays): what the first geometry is worth.
``--stereo-accuracy`` prints how close the stereo points of the events' HPF images lie to those
surfaces and exits. ``--sensor refractory_s=0,...`` first writes the scene again with those
sensor-model fields changed (same seed, scene, path and thresholds) and trains on that: what each
part of the sensor model costs.

Scenes are tuning seeds of the sweep (``fusiongs simulate --sweep-seed N --split tuning``) without
frames; the hook is installed only in this process (no production code path changes).

    PYTHONPATH=. python benchmarks/bench_event_only_diagnose.py SCENE OUT [--oracle] [--true-geometry]
        [--true-theta] [--sensor FIELD=V,...] [K=V]
    PYTHONPATH=. python benchmarks/bench_event_only_diagnose.py SCENE --stereo-accuracy
    PYTHONPATH=. python benchmarks/bench_event_only_diagnose.py SCENE --floor
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
# before torch: spinning OpenMP threads made runs 4.5x slower on a shared CPU
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from fusiongs.eval.truth import read_sim_facts  # noqa: E402
from fusiongs.losses.event import delta_log, sample_event_pixels, select_channel  # noqa: E402


def sim_config(scene: Path):
    """The :class:`SimConfig` a simulated scene was written with (from ``gt/sim.json``)."""
    from fusiongs.sim.dvs import DVSParams
    from fusiongs.sim.simulate import SimConfig

    cfg = dict(json.loads((scene / "gt" / "sim.json").read_text())["config"])
    cfg["dvs"] = DVSParams(**cfg["dvs"])
    return SimConfig(**cfg)


def true_logs(scene: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(times [K], logs [K, H*W])``: the log intensity each event pixel sees, at the simulator's
    render rate (cached in ``scene/gt/true_logs.npz``)."""
    from fusiongs.sim import dvs
    from fusiongs.sim.simulate import scene_renderer

    cache = scene / "gt" / "true_logs.npz"
    if cache.is_file():
        z = np.load(cache)
        return z["times"], z["logs"]
    cfg = sim_config(scene)
    render = scene_renderer(cfg).render
    times = np.linspace(0.0, cfg.duration, int(round(cfg.duration * cfg.dvs_rate_hz)) + 1)
    logs = np.stack([dvs.sensor_log(render(float(t)), cfg.cfa, cfg.dvs.eps) for t in times])
    from fusiongs.atomic import atomic_path

    with atomic_path(cache) as tmp:  # a run stopped midway leaves no half-written cache
        np.savez(tmp, times=times, logs=logs)
    return times, logs


class TrueLog:
    """``at(t)``: ``[H*W]`` true log intensity at ``t`` (linear between render instants)."""

    def __init__(self, times: np.ndarray, logs: np.ndarray):
        self.times, self.logs = times, torch.from_numpy(logs)

    def at(self, t: float) -> torch.Tensor:
        k = int(np.clip(np.searchsorted(self.times, t) - 1, 0, len(self.times) - 2))
        w = float((t - self.times[k]) / (self.times[k + 1] - self.times[k]))
        return (1.0 - w) * self.logs[k] + w * self.logs[k + 1]


def install_oracle(truth: TrueLog, units: float = 1.0) -> None:
    """Replace the training step's event loss by the mse against the true log change (same
    sampled pixels; grey sensors and colour ``mask`` mode, whole-sensor renders), the residual
    divided by ``units`` (log units by default; the scene's mean threshold gives count units, a
    term of about the band loss's size, so the anchor and the low-pass term keep their default share)."""
    import fusiongs.train.step as step
    from fusiongs.losses.colour import channel_weights_for

    def oracle_window_loss(state, data, cfg, lin_a, lin_b, t_a, t_b, gen, crop=None):
        ev = cfg.events
        counts = data.count_maps(t_a, t_b, lin_a.device)
        pix = sample_event_pixels(counts, min(ev.pixels, counts[0].numel()), ev.frac_with_events, gen)
        la, lb = lin_a.reshape(-1, 3)[pix], lin_b.reshape(-1, 3)[pix]
        target = (truth.at(t_b) - truth.at(t_a))[pix, None].to(lin_a)
        if data.cfa_index is None:
            d = delta_log(la, lb, "grey", ev.grey_weights, ev.log_eps)
            return (((d - target) / units) ** 2).mean()
        if ev.colour_mode != "mask":
            raise SystemExit("the oracle supports grey sensors and events.colour_mode=mask")
        ch = data.cfa_index.reshape(-1)[pix]
        d = select_channel(delta_log(la, lb, "rgb", eps=ev.log_eps), ch)
        w = channel_weights_for(ch, ev.channel_weights)
        return (w * ((d - target) / units) ** 2).sum() / w.sum()

    step.event_window_loss = oracle_window_loss


def install_max_window(seconds: float) -> None:
    """Cap the free windows' length at ``seconds`` (event-only scenes draw them log-uniform up to
    the whole recording, since their "frame interval" is the recording's span)."""
    import fusiongs.train.step as step

    draw = step.sample_free_windows

    def capped(n, t_range, frame_interval, generator=None, min_duration=1e-3):
        return draw(n, t_range, min(frame_interval, seconds), generator, min(min_duration, seconds))

    step.sample_free_windows = capped


def true_surface_points(scene: Path, c2w: torch.Tensor) -> torch.Tensor:
    """``[M, 3]`` points of the simulator's surfaces seen through every pixel centre of the views
    posed by ``c2w`` ``[N, 4, 4]`` (float32, CPU)."""
    from fusiongs.sim.simulate import scene_renderer

    caster = scene_renderer(sim_config(scene)).caster
    return torch.cat([caster.surface_points(c.float()).cpu() for c in torch.as_tensor(c2w)]).float()


def install_true_geometry(scene: Path) -> None:
    """Make the stereo initialisation return the true surface points of its views (grey 0.5,
    confidence 1): the trainer keeps ``init.stereo_share`` of them and adds its random points."""
    import fusiongs.camera.stereo as stereo

    def true_points(images, c2w, camera, near, far, **_):
        xyz = true_surface_points(scene, c2w)
        return xyz, torch.full((xyz.shape[0], images.shape[-1]), 0.5), torch.ones(xyz.shape[0])

    stereo.stereo_points = true_points


def true_thresholds(scene: Path) -> tuple[torch.Tensor, torch.Tensor]:
    """``([H*W], [H*W])`` float32 ON and OFF thresholds of each pixel as the simulator drew them
    (:func:`fusiongs.sim.dvs.pixel_thresholds` from the seed's threshold stream, times the scale
    it tuned; a leak's drift is left out)."""
    from fusiongs.sim import dvs

    cfg = sim_config(scene)
    facts = json.loads((scene / "gt" / "sim.json").read_text())
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed).spawn(7)[1])
    on, off = dvs.pixel_thresholds(cfg.dvs, cfg.width * cfg.height, rng, width=cfg.width)
    scale = float(facts["threshold_scale"])
    return torch.as_tensor(on * scale, dtype=torch.float32), torch.as_tensor(off * scale, dtype=torch.float32)


def parse_sensor(sensor: str) -> dict[str, float]:
    """``"name=value,..."`` -> ``{name: value}`` for fields of :class:`fusiongs.sim.dvs.DVSParams`;
    raises ValueError naming the bad item."""
    import dataclasses

    from fusiongs.sim.dvs import DVSParams

    fields = {f.name for f in dataclasses.fields(DVSParams)}
    changes = {}
    for item in sensor.split(","):
        name, _, value = item.partition("=")
        if name not in fields:
            raise ValueError(f"--sensor: {name!r} is not a DVSParams field ({', '.join(sorted(fields))})")
        try:
            changes[name] = float(value)
        except ValueError:
            raise ValueError(f"--sensor: {name}: expected a number, got {value!r}") from None
    return changes


def resimulate(scene: Path, out: Path, sensor: str) -> Path:
    """Write ``scene`` again to ``out`` with some ``DVSParams`` fields changed (``sensor``:
    ``name=value,...``, e.g. ``refractory_s=0,ba_rate_hz=0``): the same seed, scene, camera path
    and thresholds, another sensor model, with its own ``gt/sim.json``. Returns ``out``."""
    import dataclasses

    from fusiongs.sim.simulate import run_simulation
    from fusiongs.sim.write import write_simulated_scene

    cfg = sim_config(scene)
    changes = parse_sensor(sensor)
    cfg = dataclasses.replace(cfg, dvs=dataclasses.replace(cfg.dvs, **changes))
    res = run_simulation(cfg)
    sweep = (read_sim_facts(scene) or {}).get("sweep")
    stats = res.stats | ({"sweep": sweep} if sweep else {})  # the twin's own facts, its sweep draw kept
    write_simulated_scene(res.scene, res.gt, out, stats=stats, overwrite=True)
    print(json.dumps({"resimulated": str(out), "events": len(res.scene.events), **changes}))
    return out


def install_true_theta(scene: Path) -> None:
    """Make every threshold the training reads the pixel's true one (θ is then fixed: the learnt
    parameters are no longer read)."""
    from fusiongs.losses.threshold import ContrastThreshold

    on, off = true_thresholds(scene)
    mean = (on.mean().reshape(1), off.mean().reshape(1))

    def theta(self, pixels=None, t=None, channel=None):
        if pixels is None:
            return mean[0].expand(self.channels), mean[1].expand(self.channels)
        idx = pixels.reshape(-1).cpu()
        return on[idx][:, None].to(pixels.device), off[idx][:, None].to(pixels.device)

    ContrastThreshold.theta = theta


def install_anchor_from(events) -> None:
    """Take the HPF anchor images and the stereo images of the first Gaussians from ``events``, a
    twin's (:func:`twin_events`: the same scene written with another sensor model, e.g.
    ``--sensor refractory_s=0``'s output), while the event loss keeps the scene's own events:
    whether a sensor effect does its harm through the anchor and the first geometry or through the
    event term."""
    import fusiongs.train.trainer as trainer

    hpf, stereo = trainer.hpf_images, trainer.event_stereo_images
    trainer.hpf_images = lambda _events, *a, **k: hpf(events, *a, **k)
    trainer.event_stereo_images = lambda _events, *a, **k: stereo(events, *a, **k)


def install_censor_from(events, twin_counts: bool = False) -> None:
    """Take the censored counts (which pixels' counts in a window are lower bounds,
    ``TrainData.censored_map`` and the fast rows of ``cumulative_counts``) from the events of
    ``events`` (:func:`twin_events`) while the counts themselves stay the scene's own: trained on
    a scene without dead time with ``events`` its dead-time twin's, what the information at the
    censored pixels is worth apart from the losses the censoring misses. ``twin_counts``: the
    censored pixels' counts are the twin's too (lower bounds as short as the dead-time sensor's),
    so that only the losses the censoring misses are undone."""
    import fusiongs.train.trainer as trainer
    from fusiongs.events.stats import dead_time_us
    from fusiongs.train.data import fast_events

    own = trainer.censor_events

    def censor_events(data, cfg, theta0, device):
        twin = copy.copy(data)
        twin.events, twin.event_index, twin._coarse = events, None, {}
        twin.fast = fast_events(events, cfg.events.censor * dead_time_us(events), device)
        cumulative = type(data).cumulative_counts
        data.censored_map = twin.censored_map
        if twin_counts:
            own_counts = type(data).count_maps

            def count_maps(t_a, t_b, dev):
                cens = twin.censored_map(t_a, t_b).to(dev)
                return torch.where(cens, twin.count_maps(t_a, t_b, dev), own_counts(data, t_a, t_b, dev))

            data.count_maps = count_maps
        data.cumulative_counts = lambda times, dev: (cumulative(data, times, dev)[0],
                                                     cumulative(twin, times, dev)[1])
        return own(data, cfg, theta0, device)

    trainer.censor_events = censor_events


def true_fast_events(scene: Path, events) -> np.ndarray:
    """``[E]`` bool: the events of ``events`` (the scene's own) that fire while the true log
    intensity at their pixel changes by more than one threshold per dead time, in the render step
    they fall in or one next to it: where the sensor's dead time can swallow crossings. The
    simulator's losses happen only there (RESULTS.md session 33: every wrong count of tuning
    seeds 5 and 8 lies in a window holding such a step), so these marks are what a perfect model of
    the losses would censor; a real sensor's run cannot know them."""
    from benchmarks.bench_dead_time_losses import true_fast_steps
    from fusiongs.sim.simulate import sensor_draws

    cfg = sim_config(scene)
    scale = float(json.loads((scene / "gt" / "sim.json").read_text())["threshold_scale"])
    times, logs = true_logs(scene)
    th_on, th_off, _, _ = sensor_draws(cfg.dvs, logs.shape[1], cfg.width,
                                       np.random.SeedSequence(cfg.seed).spawn(7))
    steps = np.diff(true_fast_steps(logs, times, th_on * scale, th_off * scale, cfg.dvs.refractory_s),
                    axis=0) > 0  # [K - 1, P] per render step
    fast = steps.copy()
    fast[1:] |= steps[:-1]
    fast[:-1] |= steps[1:]
    step = np.clip(np.searchsorted(times, events.t * 1e-6, side="right") - 1, 0, len(fast) - 1)
    return fast[step, events.y.astype(np.int64) * events.width + events.x]


def install_censor_oracle(scene: Path) -> None:
    """Censor (treat as lower bounds) exactly the counts of windows holding a
    :func:`true_fast_events` event, instead of ``events.censor``'s fast pairs: what a perfect
    model of the dead time's losses is worth."""
    import fusiongs.train.trainer as trainer

    def censor_events(data, cfg, theta0, device):
        return torch.from_numpy(true_fast_events(scene, data.events)).to(device)

    trainer.censor_events = censor_events


def twin_events(other: Path, scene: Path, option: str):
    """The events of ``other``, checked to be a twin of ``scene`` (the same sensor size); raises
    ``ValueError`` with one line naming ``option`` and the folder otherwise."""
    from fusiongs.errors import FusionGSError
    from fusiongs.io.scene_io import load_scene

    try:
        events, own = load_scene(other).events, load_scene(scene).camera
    except FusionGSError as err:
        raise ValueError(f"{option}: {err}") from None
    if events is None or not len(events):
        raise ValueError(f"{option}: {other}: expected a scene with events, got none")
    if (events.width, events.height) != (own.width, own.height):
        raise ValueError(f"{option}: {other}: expected a twin of {scene} ({own.width}x{own.height} "
                         f"events), got {events.width}x{events.height}")
    return events


def stereo_accuracy(scene_path: Path, config: str = "event_only", n_truth: int = 30000) -> dict:
    """How close the event-only stereo points (:func:`fusiongs.train.trainer.init_images` at the
    trainer's :data:`EVENT_ONLY_VIEWS` instants, the config's depth range and confidence) lie to
    the true surfaces: the distance to the nearest of ``n_truth`` true surface points over the
    point's distance from the path's mean camera centre, as shares below 5 % and 20 % and the median."""
    from fusiongs.camera.stereo import stereo_points
    from fusiongs.io.scene_io import load_scene
    from fusiongs.train.data import prepare_data
    from fusiongs.train.pipeline import resolve_config
    from fusiongs.train.state import EVENT_ONLY_VIEWS
    from fusiongs.train.trainer import build_trajectory, init_images

    scene, cfg = load_scene(scene_path), resolve_config(config, [])
    data = prepare_data(scene, torch.device("cpu"), True)
    images = init_images(scene, data, cfg)
    with torch.no_grad():
        instants = torch.linspace(data.t_range[0], data.t_range[1], EVENT_ONLY_VIEWS, dtype=torch.float64)
        c2w = build_trajectory(scene, cfg).c2w(instants).float()
    xyz, _, _ = stereo_points(images, c2w, data.camera, cfg.init.depth_min, cfg.init.depth_max,
                              n_planes=cfg.init.stereo_planes, min_confidence=cfg.init.stereo_min_confidence)
    truth = true_surface_points(scene_path, c2w)
    truth = truth[torch.randperm(truth.shape[0], generator=torch.Generator().manual_seed(0))[:n_truth]]
    dist = torch.cat([torch.cdist(x, truth).min(dim=1).values for x in xyz.split(2000)])
    rel = (dist / (xyz - c2w[:, :3, 3].mean(dim=0)).norm(dim=1)).numpy()
    return {"points": int(xyz.shape[0]), "within_5pct": float(np.mean(rel < 0.05)),
            "within_20pct": float(np.mean(rel < 0.2)), "median_rel": float(np.median(rel))}


def hpf_floor(scene_path: Path, theta0: float = 0.22, tau: float = 0.05) -> dict[str, float]:
    """Affine-fit PSNR / SSIM of the HPF intensity image (the event-only anchor) at the held-out
    instants (:func:`fusiongs.eval.event_floor.leaky_integrator_floor`)."""
    from fusiongs.eval.event_floor import leaky_integrator_floor

    return leaky_integrator_floor(scene_path, theta0, tau)


def summarise(out: Path) -> dict:
    """Affine-fit and raw PSNR from metrics.json, and the history at a few iterations."""
    m = json.loads((out / "metrics.json").read_text())
    rows = [json.loads(line) for line in (out / "history.jsonl").read_text().splitlines()]
    marks = sorted({0, 299, 599, len(rows) // 2, len(rows) - 1} & set(range(len(rows))))
    keep = ("iteration", "loss", "event", "intensity", "event_weight", "theta_pos", "theta_neg",
            "n_gaussians")
    return {"affine_psnr": m["affine_fit"]["mean"]["novel"]["fusiongs"]["psnr"],
            "affine_ssim": m["affine_fit"]["mean"]["novel"]["fusiongs"]["ssim"],
            "raw_psnr": m["mean"]["novel"]["fusiongs"]["psnr"], "seconds": m.get("seconds"),
            "history": [{k: rows[i].get(k) for k in keep} for i in marks]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", type=Path)
    p.add_argument("out", type=Path, nargs="?")
    p.add_argument("--oracle", action="store_true", help="true log changes as event targets")
    p.add_argument("--oracle-counts", action="store_true",
                   help="the oracle's residual in count units (divided by the scene's mean true threshold)")
    p.add_argument("--max-window", type=float, default=None, help="cap on free windows (s)")
    p.add_argument("--floor", action="store_true", help="print the HPF floor and exit")
    p.add_argument("--true-geometry", action="store_true", help="first Gaussians on the true surfaces")
    p.add_argument("--true-theta", action="store_true", help="every pixel's true threshold, fixed")
    p.add_argument("--sensor", default=None,
                   help="first re-simulate the scene into OUT_scene with these DVSParams fields "
                        "changed, e.g. refractory_s=0,ba_rate_hz=0,hot_pixel_fraction=0,leak_rate_hz=0")
    p.add_argument("--stereo-accuracy", action="store_true",
                   help="print how close the events' stereo points lie to the true surfaces and exit")
    p.add_argument("--anchor-from", type=Path, default=None,
                   help="HPF anchor and stereo images from this scene's events (same scene, another sensor)")
    p.add_argument("--censor-from", type=Path, default=None,
                   help="censored counts from this scene's events (same scene, another sensor)")
    p.add_argument("--twin-counts", action="store_true",
                   help="with --censor-from: the censored pixels' counts from that scene too")
    p.add_argument("--censor-oracle", action="store_true",
                   help="censor the windows where the true log rate exceeds a threshold per dead time")
    p.add_argument("--config", default="event_only")
    p.add_argument("overrides", nargs="*")
    args = p.parse_intermixed_args(argv)
    torch.set_num_threads(1)
    facts = args.scene / "gt" / "sim.json"
    needs_facts = (args.oracle or args.true_geometry or args.true_theta or args.stereo_accuracy or args.sensor
                   or args.censor_oracle)
    if needs_facts and not facts.is_file():
        p.error(f"{facts}: not found; --oracle, --true-geometry, --true-theta, --sensor, --censor-oracle "
                "and --stereo-accuracy need a scene written by fusiongs simulate")
    if args.out is None and not (args.floor or args.stereo_accuracy):
        p.error("OUT: expected an output folder for the training run")
    if args.oracle_counts and not args.oracle:
        p.error("--oracle-counts: only with --oracle")
    if args.floor:
        print(json.dumps(hpf_floor(args.scene)))
        return 0
    if args.stereo_accuracy:
        print(json.dumps(stereo_accuracy(args.scene, args.config)))
        return 0
    from fusiongs.train.pipeline import run_deblur

    if args.sensor:
        if args.oracle or args.true_geometry or args.true_theta or args.censor_oracle:
            p.error("--sensor: not with the truth options (they were written for the scene as drawn)")
        try:
            args.scene = resimulate(args.scene, args.out.parent / f"{args.out.name}_scene", args.sensor)
        except ValueError as err:
            p.error(str(err))
    if args.oracle:
        doc = read_sim_facts(args.scene)
        units = (float(np.sqrt(doc["theta_on"] * doc["theta_off"]) * doc.get("threshold_scale", 1.0))
                 if args.oracle_counts else 1.0)
        install_oracle(TrueLog(*true_logs(args.scene)), units)
    if args.max_window is not None:
        install_max_window(args.max_window)
    if args.true_geometry:
        install_true_geometry(args.scene)
    if args.true_theta:
        install_true_theta(args.scene)
    if args.censor_oracle:
        install_censor_oracle(args.scene)
    if args.twin_counts and args.censor_from is None:
        p.error("--twin-counts: only with --censor-from")
    try:
        options = (("--anchor-from", args.anchor_from), ("--censor-from", args.censor_from))
        twins = {opt: twin_events(path, args.scene, opt) for opt, path in options if path is not None}
    except ValueError as err:
        p.error(str(err))
    if "--anchor-from" in twins:
        install_anchor_from(twins["--anchor-from"])
    if "--censor-from" in twins:
        install_censor_from(twins["--censor-from"], args.twin_counts)
    overrides = ["output.progress=false", *args.overrides, *(["events.loss=mse"] if args.oracle else [])]
    run_deblur(args.scene, args.out, config=args.config, overrides=overrides, log=lambda *_: None)
    s = summarise(args.out)
    (args.out / "diagnose.json").write_text(json.dumps(s, indent=1))
    print(json.dumps({k: v for k, v in s.items() if k != "history"}))
    for row in s["history"]:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())

