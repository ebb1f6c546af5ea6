"""The strongest EDI peer on a recording without truth: EDI carried to held-out frames, best thresholds.

On a real recording nothing knows the true thresholds, so the honest EDI peer of the held-out score
(:mod:`fusiongs.eval.holdout`, docs/method.md §6a) is EDI at the thresholds that predict the held-out
blurry frames best. For every ``(theta_+, theta_-)`` of a grid, each held-out frame is predicted as
``fusiongs deblur --holdout K`` predicts it (the kept neighbours EDI-deblurred, carried with the
events to the held-out exposure, averaged in linear light, encoded by the frames' response) and
scored against the real frame. Every event counts once (the step pixel model).

Reference in the same run: the same prediction at the thresholds the calibration estimates from the
kept frames (what ``heldout.json`` reports as ``edi_carried``), and the nearest kept frame.
The counts do not depend on the thresholds: they are taken once, and each grid cell costs only the
exponentials.

    PYTHONPATH=. python benchmarks/bench_holdout_edi_grid.py path/to/eslnet_cups \
        --holdout 5 [--grid 0.15,0.2,...] [--json F]
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from fusiongs.atomic import write_text
from fusiongs.calibrate.estimate import estimate_thresholds
from fusiongs.edi import EDI_SAMPLES, edi_ratio, event_count_samples
from fusiongs.errors import FusionGSError, InputError
from fusiongs.eval.holdout import carried_counts, frame_subset, kept_neighbours, nearest_kept
from fusiongs.eval.metrics import psnr
from fusiongs.frames.response import linear_to_response
from fusiongs.io.scene_io import load_scene
from fusiongs.pipeline.deblur import resolve_config, split_holdout

GRID = (0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5, 0.6, 0.75)


def held_out_scores(scene, held, kept, thetas, n_edi: int = EDI_SAMPLES, n_carry: int | None = None
                    ) -> np.ndarray:
    """Mean held-out PSNR of EDI carried from the kept neighbours, one value per threshold pair.

    Args:
        scene: a scene with frames and events.
        held, kept: frame indices (:func:`fusiongs.pipeline.deblur.split_holdout`).
        thetas: ``[T]`` ``(theta_+, theta_-)`` pairs (log units) or threshold objects.
        n_edi: instants of each neighbour's EDI (``fusiongs deblur`` uses the default).
        n_carry: instants of the held-out exposure; None: the default config's ``blur.n_samples``,
            as ``fusiongs deblur --holdout`` with the default config.

    Returns:
        ``[T, H]`` PSNR (dB, 8-bit values in the frames' own encoding) per threshold and held frame.
    """
    fs, ev = scene.frames, scene.events
    n_carry = resolve_config(None, ()).blur.n_samples if n_carry is None else n_carry
    lin, mids = fs.to_linear(), fs.mid_times()
    sides = {int(i): [j for j in kept_neighbours(kept, int(i)) if j is not None] for i in held}
    own = {j: event_count_samples(ev, float(fs.t_start[j]), float(fs.t_end[j]), n_edi)
           for j in sorted({j for s in sides.values() for j in s})}
    carry = {(i, j): carried_counts(ev, float(mids[j]), float(fs.t_start[i]), float(fs.t_end[i]), n_carry)
             for i, s in sides.items() for j in s}
    out = np.zeros((len(thetas), len(held)))
    for a, th in enumerate(thetas):
        sharp = {j: lin[j] / edi_ratio(c, th, ev.cfa) for j, c in own.items()}
        for b, i in enumerate(sides):
            pred = np.mean([sharp[j] * edi_ratio(carry[i, j], th, ev.cfa) for j in sides[i]], axis=0)
            out[a, b] = psnr(linear_to_response(np.clip(pred, 0, 1), fs.response), fs.images[i])
    return out


def thresholds_list(text: str) -> list[float]:
    """``--grid``: comma-separated positive thresholds (log units)."""
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if not vals or not all(np.isfinite(v) and v > 0 for v in vals):
        raise argparse.ArgumentTypeError(f"expected comma-separated positive thresholds, got {text!r}")
    return vals


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--holdout", type=int, default=5, help="K of fusiongs deblur --holdout")
    ap.add_argument("--grid", type=thresholds_list, default=list(GRID),
                    help="thresholds tried for ON and OFF (comma-separated)")
    ap.add_argument("--json", help="write every cell here")
    args = ap.parse_args(argv)
    if args.holdout < 2:
        ap.error(f"--holdout: expected an integer >= 2 (every K-th frame is left out), got {args.holdout}")
    try:
        scene = load_scene(args.scene)
        if scene.events is None or len(scene.events) == 0:
            raise InputError(args.scene, "events", "a scene with an event stream", "none")
        held, kept = split_holdout(scene, args.holdout)
        t0 = time.perf_counter()
        est = estimate_thresholds(frame_subset(scene.frames, kept), scene.events)
    except FusionGSError as e:
        ap.error(str(e))
    t_est = time.perf_counter() - t0
    grid = args.grid
    pairs = [(p, n) for p in grid for n in grid]
    t0 = time.perf_counter()
    scores = held_out_scores(scene, held, kept, [est, *pairs])
    t_grid = time.perf_counter() - t0
    mids = scene.frames.mid_times()
    near = np.mean([psnr(scene.frames.images[nearest_kept(mids, kept, int(i))], scene.frames.images[i])
                    for i in held])
    means = scores.mean(axis=1)
    best = 1 + int(np.argmax(means[1:]))
    order = 1 + np.argsort(-means[1:])
    e_pos = "/".join(f"{v:.3f}" for v in est.theta_pos)
    e_neg = "/".join(f"{v:.3f}" for v in est.theta_neg)
    print(f"{args.scene}: {len(held)} held-out frames (K = {args.holdout}), {len(pairs)} grid cells, "
          f"estimate {t_est:.1f} s, grid {t_grid:.1f} s")
    print("| EDI carried at θ₊ / θ₋ | mean held-out PSNR | per frame |\n|---|---|---|")
    rows = [(f"**{pairs[k - 1][0]:.2f} / {pairs[k - 1][1]:.2f}**" if k == best
             else f"{pairs[k - 1][0]:.2f} / {pairs[k - 1][1]:.2f}", k) for k in order[:5]]
    rows.append((f"{e_pos} / {e_neg} (estimated from the kept frames)", 0))
    for label, k in rows:
        print(f"| {label} | {means[k]:.2f} | {' '.join(f'{v:.2f}' for v in scores[k])} |")
    print(f"| nearest kept frame | {near:.2f} | |")
    print(f"best grid cell over the estimate: {means[best] - means[0]:+.2f} dB")
    if args.json:
        doc = {"scene": args.scene, "holdout": args.holdout, "held": [int(i) for i in held],
               "estimate": {"theta_pos": list(est.theta_pos), "theta_neg": list(est.theta_neg),
                            "psnr": scores[0].tolist()},
               "grid": [{"theta_pos": p, "theta_neg": n, "psnr": scores[1 + k].tolist()}
                        for k, (p, n) in enumerate(pairs)],
               "best": {"theta_pos": pairs[best - 1][0], "theta_neg": pairs[best - 1][1],
                        "mean": float(means[best])},
               "nearest": float(near)}
        write_text(args.json, json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
