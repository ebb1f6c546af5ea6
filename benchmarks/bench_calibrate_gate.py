"""Issue 13 diagnosis: is a threshold estimate off because of the counts the dead time loses, or
because of which pixel pairs the refractory gate keeps?

The scene's *twin* is the same scene written again with the sensor's dead time set to 0 and
every other sensor field kept (same seed, scene, path, frames, thresholds, spread and noise; the
twin's frames are the scene's). The twin's counts have lost no crossing. The rows:

- ``scene``: the estimator's default on the scene (``fusiongs calibrate``);
- ``scene, step``: the same with the simulator's pixel model forced (the model of its pixel);
- ``twin, no gate``: the twin's counts and the twin's own gate (it has no dead time, so none);
- ``scene, gate off``: the scene's counts, every pixel pair kept (``refractory_gate=0``);
- ``twin counts, scene's gate``: the twin's counts through the gate of the scene's own events
  (the scene's dead time and fast events): the same pixel pairs as ``scene, step``, and none of
  their counts short.

If ``twin counts, scene's gate`` is as far off as ``scene, step``, the error comes from the pairs
the gate selects; if it is near the truth, from the crossings lost in the kept pairs.

Two more rows test the pixel's own gate (the estimator's fallback where the neighbours' gate
leaves no measurement), the only gate in both:

- ``scene, own gate``: the scene's counts, pairs gated by the pixel's own fast events;
- ``twin, own gate``: the twin's counts, gated by the twin's own fast events at the scene's dead
  time: an ideal sensor (no crossing lost anywhere) with the same selection rule. If it is as far
  off as ``scene, own gate``, the own gate's error is its selection on the pixel's own counts,
  which the dead time does not need to make.

Two more move the own gate's selection off the fitted pixel (:func:`instrument_gated_pairs`):

- ``scene, own gate on the instrument`` / ``twin, own gate on the instrument``: each entry fits a
  pixel ``A``'s counts, instrumented by the counts of one same-channel neighbour ``B`` (each of
  the four), and is left out when ``B`` has fast events in the pair; ``A`` is not gated. A
  selection on the instrument's own counts does not bias an IV fit when ``B``'s count noise is
  independent of ``A``'s (it is, on an ideal sensor), so on the twin this row should read near
  the truth where ``twin, own gate`` reads high; on the scene it keeps ``A``'s lost crossings.

Two more gate each pixel pair on something no pixel's counts carry (:func:`true_rate_fast`):

- ``scene, true-rate gate`` / ``twin, true-rate gate``: a pixel is left out of a pair where the
  simulator's true log intensity at that pixel (its render instants, linear in between) changes
  by more than ``RATE_FACTOR`` thresholds within one gap somewhere in the pair. It selects on the
  image's speed alone, not on a count, and it also catches the edges that leave a single event,
  which no interval shows. It is an oracle, not an estimator: it tells how far the best gate on
  the image's speed gets, i.e. how much of an error is the choice of the pairs.

Simulated scenes only (the truth and the simulator's configuration are read). The gate is swapped
in this process only (:func:`estimate_with_gate`); no production code path changes.

    PYTHONPATH=. python benchmarks/bench_calibrate_gate.py SCENE [SCENE ...] [--twins DIR] [--json FILE]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

# before torch: spinning OpenMP threads slow a shared CPU
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import fusiongs.eval.calibrate as calibrate  # noqa: E402
from benchmarks.bench_calibrate import relative_errors  # noqa: E402
from fusiongs.eval.calibrate import CalibrateOptions, estimate_thresholds  # noqa: E402
from fusiongs.eval.calibrate_data import active_pairs, frame_pairs, gate_inputs, pair_sums, tile_ids  # noqa: E402
from fusiongs.eval.calibrate_fit import PairData  # noqa: E402
from fusiongs.events.stats import interval_floor  # noqa: E402
from fusiongs.events.stream import EventStream  # noqa: E402
from fusiongs.frames.frameset import FrameSet  # noqa: E402


@contextlib.contextmanager
def _swapped(inputs=None, floor=None):
    """Within the block, :func:`estimate_thresholds` calls ``inputs`` instead of
    :func:`~fusiongs.eval.calibrate_data.gate_inputs` and takes ``floor`` as the interval floor of
    the stream it fits (each only when given); both are restored after it."""
    saved = calibrate.gate_inputs, calibrate.interval_floor
    if inputs is not None:
        calibrate.gate_inputs = inputs
    if floor is not None:
        calibrate.interval_floor = lambda _ev, _jump: floor
    try:
        yield
    finally:
        calibrate.gate_inputs, calibrate.interval_floor = saved


@contextlib.contextmanager
def gate_from(events: EventStream, jump: float, floor_events: EventStream | None = None):
    """Within the block, :func:`estimate_thresholds` takes its dead time (the interval floor of
    ``floor_events``, by default ``events``) and its refractory gate from ``events`` instead of the
    stream it fits."""
    floor = interval_floor(events if floor_events is None else floor_events, jump)
    with _swapped(lambda frames, _ev, opts, dead: gate_inputs(frames, events, opts, dead), floor):
        yield


def estimate_with_gate(frames: FrameSet, events: EventStream, gate_events: EventStream,
                       opts: CalibrateOptions, floor_events: EventStream | None = None):
    """:func:`estimate_thresholds` on ``events`` with the gate of ``gate_events`` and the dead time
    of ``floor_events`` (default ``gate_events``; streams of the same sensor size and span)."""
    for other, what in ((gate_events, "gate's"), (floor_events, "dead time's")):
        if other is not None and (other.width, other.height) != (events.width, events.height):
            raise ValueError(f"the {what} stream is {other.width}x{other.height}, the fitted "
                             f"one {events.width}x{events.height}")
    with gate_from(gate_events, opts.dead_time_jump, floor_events):
        return estimate_thresholds(frames, events, opts)


def instrument_gated_pairs(sens: np.ndarray, counts: list[np.ndarray], between: np.ndarray,
                           pix: np.ndarray, fast: np.ndarray, frame_ok: np.ndarray, height: int,
                           width: int, step: int, tile: int, max_gap: int) -> PairData:
    """:class:`PairData` whose entries are (pixel ``A``, instrument pixel ``B``) for every ``B`` in
    ``pix`` and each of its four same-channel neighbours ``A`` (``step`` pixels away, inside the
    sensor), gated by ``B``'s own fast events only.

    Args:
        sens, counts, between, frame_ok: as for :func:`fusiongs.eval.calibrate_data.prepare_channel`.
        pix: ``[P]`` flat indices of the instrument pixels ``B``.
        fast: ``[F-1, H*W]`` bool, the pixel has two events closer than the gap in the pair
            (:func:`fusiongs.eval.calibrate_data.gate_inputs`).
        height, width: the sensor. step: 1 (grey) or 2 (CFA). tile: bootstrap tile side (``B``'s tile).
        max_gap: longest baseline of the compared frame pairs.

    Returns:
        ``E <= 4 P`` entries: ``A``'s frames and counts, ``z`` = ``B``'s counts, ``valid`` where
        ``A`` is lit and unsaturated in both frames, ``B`` has no fast events in any gap the pair
        spans, and ``A`` moved.
    """
    y, x = pix // width, pix % width
    a_pix, b_pix = [], []
    for dy, dx in ((step, 0), (-step, 0), (0, step), (0, -step)):
        yy, xx = y + dy, x + dx
        inside = (yy >= 0) & (yy < height) & (xx >= 0) & (xx < width)
        a_pix.append((yy * width + xx)[inside])
        b_pix.append(pix[inside])
    a_pix, b_pix = np.concatenate(a_pix), np.concatenate(b_pix)
    pairs = frame_pairs(sens.shape[0], max_gap)
    n = np.stack([c[..., a_pix] for c in counts]).astype(np.float32)
    dn = pair_sums(between[..., a_pix].astype(np.float32), pairs)
    z = pair_sums(between[..., b_pix].astype(np.float32), pairs)
    gated = pair_sums(fast[:, b_pix].astype(np.int32), pairs) > 0
    valid = (frame_ok[pairs[:, 0]][:, a_pix] & frame_ok[pairs[:, 1]][:, a_pix] & ~gated
             & active_pairs(n, dn, pairs))
    uniq, tid = np.unique(tile_ids(b_pix, width, tile), return_inverse=True)
    return PairData(torch.as_tensor(np.log(np.maximum(sens[:, a_pix], 1e-12)), dtype=torch.float32),
                    torch.as_tensor(n), torch.as_tensor(pairs), torch.as_tensor(dn), torch.as_tensor(valid),
                    torch.as_tensor(tid.astype(np.int64)), int(uniq.size), torch.as_tensor(z))


@contextlib.contextmanager
def own_gate_on_instrument(height: int, step: int):
    """Within the block, the pixel pairs that :func:`estimate_thresholds` builds are made by
    :func:`instrument_gated_pairs` (``height``, ``step`` of the sensor): with the options
    ``refractory_self=True, refractory_radius=0`` the gate mask it passes is the pixel's own fast
    events, which then gate the instrument instead of the fitted pixel. A mask that gates nothing
    (the gate off, or the fallback where it left no pairs) is built as usual."""
    saved = calibrate.prepare_channel

    def prepare(sens, counts, between, pix, bad_pair, frame_ok, width, tile, max_gap=1, neighbours=None):
        if not bad_pair.any():
            return saved(sens, counts, between, pix, bad_pair, frame_ok, width, tile, max_gap, neighbours)
        return instrument_gated_pairs(sens, counts, between, pix, bad_pair, frame_ok, height, width,
                                      step, tile, max_gap)

    calibrate.prepare_channel = prepare
    try:
        yield
    finally:
        calibrate.prepare_channel = saved


RATE_FACTOR = 1.5  # true-rate gate: thresholds crossed within one gap (2 = crossings one dead time apart)


def true_rate_fast(times: np.ndarray, logs: np.ndarray, t_start: np.ndarray, t_end: np.ndarray,
                   gap_us: float, theta_on: float, theta_off: float,
                   factor: float = RATE_FACTOR) -> np.ndarray:
    """``[F-1, H*W]`` bool: somewhere between frame ``i``'s exposure start and frame ``i+1``'s
    exposure end, the pixel's true log intensity rises faster than ``factor * theta_on`` or falls
    faster than ``factor * theta_off`` per ``gap_us`` microseconds.

    Args:
        times: ``[K]`` s, the simulator's render instants; logs: ``[K, H*W]`` the log intensity
            each pixel sees there (linear in between, as the simulator's DVS model takes it).
        t_start, t_end: ``[F]`` s, the frames' exposures. gap_us: the refractory gate's gap (µs).
        theta_on, theta_off: the thresholds (log units). factor: see ``RATE_FACTOR``.
    """
    rate = np.diff(logs, axis=0) / np.diff(times)[:, None]  # [K-1, P] log / s, constant per interval
    g = gap_us * 1e-6
    over = (rate * g > factor * theta_on) | (-rate * g > factor * theta_off)
    cum = np.concatenate([np.zeros((1, over.shape[1]), np.int64), np.cumsum(over, axis=0)])
    # interval j = [times[j], times[j+1]] overlaps (a, b) when times[j+1] > a and times[j] < b
    first = np.searchsorted(times[1:], np.asarray(t_start[:-1]), side="right")
    last = np.searchsorted(times[:-1], np.asarray(t_end[1:]), side="left")
    return (cum[last] - cum[first]) > 0


@contextlib.contextmanager
def gate_mask(fast_of_gap, floor_events: EventStream | None = None, jump: float = 5.0):
    """Within the block, :func:`estimate_thresholds`'s refractory gate leaves out the pixel pairs
    ``fast_of_gap(gap_us)`` (``[F-1, H*W]`` bool) marks, the pixel's own only (every fallback sees
    the same mask); the dead time (and with it the gap) is the fitted stream's, or the interval
    floor of ``floor_events`` (histogram jump ``jump``) when given."""
    def inputs(frames, events, opts, dead):
        gap, _, _ = gate_inputs(frames, events, opts, dead)
        fast = fast_of_gap(gap)
        return gap, fast, fast.copy()

    with _swapped(inputs, None if floor_events is None else interval_floor(floor_events, jump)):
        yield


def errors(est, truth) -> np.ndarray:
    """Relative errors ``[2 C]`` (ON per channel, then OFF per channel)."""
    return np.concatenate(relative_errors(est, truth))


def rows(scene: Path, twin: Path) -> list[dict]:
    """The eleven estimates of the module docstring on ``scene`` and its ``twin``."""
    from benchmarks.bench_event_only_diagnose import true_logs
    from fusiongs.eval.truth import true_thresholds
    from fusiongs.io.scene_io import load_scene

    sc, tw = load_scene(scene), load_scene(twin)
    truth = true_thresholds(scene, sc.events.cfa)
    step = CalibrateOptions(pixel_model="step")

    def on_instrument(run):
        with own_gate_on_instrument(sc.events.height, 1 if sc.events.cfa is None else 2):
            return run()

    own = replace(step, refractory_self=True, refractory_radius=0)  # the pixel's own gate only
    facts = json.loads((scene / "gt" / "sim.json").read_text())
    times, logs = true_logs(scene)  # the twin's images are the scene's

    def true_rate(fit_events, floor_events=None):
        def fast(gap):
            return true_rate_fast(times, logs, sc.frames.t_start, sc.frames.t_end, gap,
                                  facts["theta_on"], facts["theta_off"])
        with gate_mask(fast, floor_events, own.dead_time_jump):
            return estimate_thresholds(sc.frames, fit_events, own)

    runs = [("scene", lambda: estimate_thresholds(sc.frames, sc.events, CalibrateOptions())),
            ("scene, step", lambda: estimate_thresholds(sc.frames, sc.events, step)),
            ("twin, no gate", lambda: estimate_thresholds(sc.frames, tw.events, step)),
            ("scene, gate off", lambda: estimate_thresholds(sc.frames, sc.events,
                                                            replace(step, refractory_gate=0.0))),
            ("twin counts, scene's gate", lambda: estimate_with_gate(sc.frames, tw.events, sc.events, step)),
            ("scene, own gate", lambda: estimate_thresholds(sc.frames, sc.events, own)),
            ("twin, own gate", lambda: estimate_with_gate(sc.frames, tw.events, tw.events, own,
                                                          floor_events=sc.events)),
            ("scene, own gate on the instrument",
             lambda: on_instrument(lambda: estimate_thresholds(sc.frames, sc.events, own))),
            ("twin, own gate on the instrument",
             lambda: on_instrument(lambda: estimate_with_gate(sc.frames, tw.events, tw.events, own,
                                                              floor_events=sc.events))),
            ("scene, true-rate gate", lambda: true_rate(sc.events)),
            ("twin, true-rate gate", lambda: true_rate(tw.events, sc.events))]
    out = []
    for name, run in runs:
        est = run()
        err = errors(est, truth)
        per = est.details.get("per_channel", [])
        out.append({"scene": scene.name, "run": name, "errors": [float(v) for v in err],
                    "largest": float(err[np.argmax(np.abs(err))]),
                    "kept": [c.get("kept") for c in per],
                    "gate": per[0].get("refractory_gate") if per else None})
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+", type=Path)
    p.add_argument("--twins", type=Path, default=Path("bench_out/gate_twins"),
                   help="where the dead-time-free twins are written (reused when present)")
    p.add_argument("--json", type=Path, default=None, help="append one JSON line per row")
    args = p.parse_args(argv)
    for scene in args.scenes:
        if not (scene / "gt" / "sim.json").is_file():
            p.error(f"{scene}: expected a scene of fusiongs simulate (its gt/sim.json is read to make "
                    "the twin and score it); not found")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_event_only_diagnose import resimulate

    print("| scene | run | largest error | errors (ON per channel, OFF per channel) | kept pairs | gate |")
    print("|---|---|---|---|---|---|")
    for scene in args.scenes:
        twin = args.twins / f"{scene.name}_d0"
        if not (twin / "scene.json").exists():
            resimulate(scene, twin, "refractory_s=0")
        for r in rows(scene, twin):
            errs = " ".join(f"{100 * v:+.1f}" for v in r["errors"])
            print(f"| {r['scene']} | {r['run']} | {100 * r['largest']:+.1f} % | {errs} | "
                  f"{sum(k or 0 for k in r['kept'])} | {r['gate']} |", flush=True)
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(r) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
