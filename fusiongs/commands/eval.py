"""``fusiongs eval OUT --gt DIR``: PSNR / SSIM of a run's images against truth images."""

from __future__ import annotations

import argparse

HELP = "evaluate a run's renders and deblurred frames against a folder of truth PNGs"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="output folder of `fusiongs deblur`")
    p.add_argument("--gt", required=True, help="folder of truth images <name>.png (8-bit sRGB)")
    p.add_argument("--affine", action="store_true",
                   help="per-channel affine fit before the metrics (event-only results)")
    p.add_argument("--json", action="store_true", help="print the metrics as JSON")


def run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from fusiongs.errors import InputError
    from fusiongs.eval.evaluate import compare_methods, format_table
    from fusiongs.frames.image_io import read_image
    from fusiongs.train.render_io import read_gt

    run_dir, gt_dir = Path(args.run), Path(args.gt)
    for p, what in ((run_dir, "run folder"), (gt_dir, "truth folder")):
        if not p.is_dir():
            raise InputError(p, what, "an existing folder", "not found")
    ours = {p.stem: read_image(p) for p in sorted((run_dir / "renders").glob("*.png"))}
    for p in sorted((run_dir / "deblurred").glob("*.png")):
        ours.setdefault(f"deblur_{p.stem}", read_image(p))
    gt = read_gt(gt_dir, ours.keys())
    if not gt:
        raise InputError(gt_dir, "<name>.png", f"truth images named like the run's images "
                         f"({', '.join(sorted(ours)[:3])}, ...)", "no match")
    result = compare_methods({"fusiongs": ours}, gt, affine=args.affine)
    print(json.dumps(result, indent=2) if args.json else format_table(result))
    return 0
