"""model.ply's display fit on a finished run: how close 3DGS viewers come to the run's renders.

PSNR (dB, peak 1) of the Gaussians composited as viewers do (stored display colours, every SH band)
against the run's own sharp renders (sRGB, its exposure gain and colour anchor applied) at its
fitted poses, full resolution, 12 evenly spaced instants among the frames' mid-exposures and the
render instants: before (each Gaussian's colour sRGB-encoded: what runs before the fit wrote)
and after fusiongs' display fit (fusiongs/outputs/display_ply.py). With ``-o`` the fitted file is
written (what ``fusiongs deblur`` now writes as ``model.ply``).

The instants come from RUN/frames.json, or, for a run written before it, from SCENE/scene.json.

    PYTHONPATH=. python benchmarks/bench_display_ply.py RUN [--scene SCENE] [--steps 100] \\
        [-o fitted.ply] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from fusiongs.outputs.colour_anchor import apply_anchor
from fusiongs.outputs.display_ply import DisplayFitOptions, fit_run_display
from fusiongs.scene.ply import save_ply
from fusiongs.view.run import load_run


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", help="a finished fusiongs deblur run folder")
    ap.add_argument("--scene", default=None, help="its scene folder (a run without frames.json)")
    ap.add_argument("--steps", type=int, default=DisplayFitOptions.steps, help="Adam steps of the fit")
    ap.add_argument("--views", type=int, default=DisplayFitOptions.views, help="poses fitted on")
    ap.add_argument("--max-width", type=int, default=DisplayFitOptions.max_width, help="fit resolution (px)")
    ap.add_argument("-o", "--output", default=None, help="write the fitted PLY here")
    ap.add_argument("--json", default=None, help="write the figures here as JSON")
    args = ap.parse_args(argv)

    run = load_run(Path(args.run), Path(args.scene) if args.scene else None)
    for note in run.frames.notes:
        print(f"note: {note}")
    times = [f.t_mid for f in run.frames.frames] + [t for _, t in run.frames.renders]
    adjust = (lambda img: apply_anchor(run.anchor, img)) if run.anchor.applied else None
    options = DisplayFitOptions(steps=args.steps, views=args.views, max_width=args.max_width)
    fit = fit_run_display(run.state, run.camera, np.asarray(times), run.gain, adjust, run.backend, options)
    doc = {"run": str(Path(args.run).resolve()), "n_gaussians": run.state.model.n,
           "camera": [run.camera.width, run.camera.height], "instants": len(set(times)), **fit.as_dict()}
    print(f"{args.run}: {doc['n_gaussians']} Gaussians, camera {run.camera.width}x{run.camera.height}, "
          f"{doc['instants']} instants")
    print(f"viewers against the run's renders ({fit.eval_views} views): {fit.psnr_before:.2f} dB "
          f"per-Gaussian sRGB -> {fit.psnr_after:.2f} dB fitted ({fit.steps} steps on {fit.views} views at "
          f"{fit.width}x{fit.height}, {fit.seconds:.1f} s)")
    if args.output:
        save_ply(fit.model, args.output, colours="display",
                 comment=f"display fit: {fit.psnr_after:.2f} dB ({fit.psnr_before:.2f} dB unfitted)")
        print(f"wrote {args.output}")
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
