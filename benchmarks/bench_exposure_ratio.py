"""The deblurred frames' exposure-ratio correction, per pixel against carried by the fitted motion.

For finished ``fusiongs deblur`` runs of scenes with truth (``SCENE/gt/deblur_<stem>.png``), the
deblurred frames are corrected again from each run's ``checkpoint.pt``, without training, with
``output.ratio_iterations`` set to each value of ``--iterations``
(:func:`fusiongs.train.exposure_ratio.corrected_renders`), and scored as ``metrics.json`` scores them
(deblur-view PSNR of the 8-bit sRGB images). The reference, measured in the same run, is 0: the
per-pixel ratio (session 10). Prints one row per run, the mean, and the gain of each count over 0.

    PYTHONPATH=. python benchmarks/bench_exposure_ratio.py RUN SCENE [RUN SCENE ...] \
        [--iterations 0,1,2,3,5] [--json F]

With ``--novel`` the scene's requested renders outside every exposure (``novel_*``, scored against
``gt/novel_*.png``) are rescored instead, as rendered (the reference) and with both neighbouring
frames' factors carried to them (``output.ratio_between``, the run's ``ratio_iterations``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402

from fusiongs.atomic import write_text  # noqa: E402
from fusiongs.errors import FusionGSError, InputError  # noqa: E402
from fusiongs.eval.metrics import psnr  # noqa: E402
from fusiongs.io.scene_io import load_scene  # noqa: E402
from fusiongs.train.exposure_ratio import corrected_renders, frame_log_gains  # noqa: E402
from fusiongs.train.render_io import exposed_srgb, read_gt  # noqa: E402
from fusiongs.train.restore import restore_state  # noqa: E402

WHERE = "bench_exposure_ratio"


def parse_iterations(text: str) -> list[int]:
    """``"0,1,3"`` -> ``[0, 1, 3]``; each an integer >= 0, 0 (the reference) included."""
    try:
        its = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        its = []
    if not its or min(its) < 0:
        raise InputError(WHERE, "--iterations", "comma-separated integers >= 0, e.g. 0,1,3", repr(text))
    return sorted(set(its) | {0})


def rescore(run: Path, scene_path: Path, iterations: list[int]) -> dict:
    """``{"psnr": {it: mean deblur PSNR}, "seconds": {it: s}}`` of one run at each iteration count."""
    scene = load_scene(scene_path)
    fs = scene.frames
    gt = read_gt(scene_path / "gt", [f"deblur_{n}" for n in fs.names])
    if len(fs) == 0 or len(gt) != len(fs):
        raise InputError(scene_path / "gt", "deblur_<stem>.png", f"a truth image for each of the {len(fs)} "
                         "frames (a simulated scene)", f"{len(gt)} found")
    state, _, cfg = restore_state(run / "checkpoint.pt")
    gains = frame_log_gains(state, len(fs))
    out: dict = {"psnr": {}, "seconds": {}}
    for it in iterations:
        t0 = time.perf_counter()
        _, fixed, _ = corrected_renders(state, scene, fs.mid_times(), gains, int(cfg["blur"]["n_samples"]),
                                        float(cfg["output"]["ratio_eps"]),
                                        tuple(cfg["events"]["grey_weights"]),
                                        str(cfg.get("backend", "auto")), None, it)
        srgb = exposed_srgb(fixed)
        out["psnr"][it] = float(np.mean([psnr(srgb[j], gt[f"deblur_{n}"]) for j, n in enumerate(fs.names)]))
        out["seconds"][it] = time.perf_counter() - t0
    return out


def rescore_novel(run: Path, scene_path: Path) -> dict:
    """``{"render": mean PSNR, "between": mean PSNR, "n": instants}`` of the requested renders with
    a truth image that lie outside every exposure, without and with ``output.ratio_between``."""
    from fusiongs.train.exposure_ratio import containing_frame

    scene = load_scene(scene_path)
    fs = scene.frames
    reqs = [r for r in scene.renders if (scene_path / "gt" / f"{r.name}.png").is_file()]
    times = np.array([r.t for r in reqs], np.float64)
    outside = [r for r, f in zip(reqs, containing_frame(fs.t_start, fs.t_end, times)) if f < 0]
    if len(fs) < 2 or not outside:
        raise InputError(scene_path / "gt", "<render name>.png", "truth images of requested renders "
                         "outside every exposure, in a scene with two frames or more",
                         f"{len(outside)} such render(s), {len(fs)} frame(s)")
    state, _, cfg = restore_state(run / "checkpoint.pt")
    gt = read_gt(scene_path / "gt", [r.name for r in outside])
    out: dict = {"n": len(outside)}
    for key, between in (("render", False), ("between", True)):
        _, fixed, _ = corrected_renders(state, scene, [r.t for r in outside], frame_log_gains(state, len(fs)),
                                        int(cfg["blur"]["n_samples"]), float(cfg["output"]["ratio_eps"]),
                                        tuple(cfg["events"]["grey_weights"]), str(cfg.get("backend", "auto")),
                                        None, int(cfg["output"].get("ratio_iterations", 3)), between)
        srgb = exposed_srgb(fixed)
        out[key] = float(np.mean([psnr(srgb[j], gt[r.name]) for j, r in enumerate(outside)]))
    return out


def format_novel(rows: dict[str, dict]) -> str:
    """Rows ``run | instants | render | between | gain``, the mean and the smallest gain."""
    lines = ["run".ljust(28) + f"{'n':>4}{'render':>10}{'between':>10}{'gain':>8}"]
    for name, r in rows.items():
        lines.append(name[-28:].ljust(28) + f"{r['n']:4d}{r['render']:10.2f}{r['between']:10.2f}"
                     f"{r['between'] - r['render']:+8.2f}")
    gains = [r["between"] - r["render"] for r in rows.values()]
    lines.append("mean".ljust(32) + f"{np.mean([r['render'] for r in rows.values()]):10.2f}"
                 f"{np.mean([r['between'] for r in rows.values()]):10.2f}{np.mean(gains):+8.2f}")
    lines.append("smallest gain".ljust(52) + f"{min(gains):+8.2f}")
    return "\n".join(lines)


def format_table(rows: dict[str, dict], iterations: list[int]) -> str:
    """Rows ``run | PSNR at each count | seconds``, the mean, and each count's gain over 0."""
    head = "run".ljust(28) + "".join(f"{f'{it} it.':>10}" for it in iterations) + f"{'s (max)':>9}"
    lines = [head]
    for name, r in rows.items():
        lines.append(name[-28:].ljust(28) + "".join(f"{r['psnr'][it]:10.2f}" for it in iterations)
                     + f"{max(r['seconds'].values()):9.1f}")
    mean = {it: float(np.mean([r["psnr"][it] for r in rows.values()])) for it in iterations}
    lines.append("mean".ljust(28) + "".join(f"{mean[it]:10.2f}" for it in iterations))
    gains = {it: [r["psnr"][it] - r["psnr"][0] for r in rows.values()] for it in iterations}
    lines.append("gain over 0: mean".ljust(28) + "".join(f"{np.mean(gains[it]):+10.2f}" for it in iterations))
    lines.append("gain over 0: smallest".ljust(28) + "".join(f"{min(gains[it]):+10.2f}" for it in iterations))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("pairs", nargs="+", metavar="RUN SCENE", help="run folder and its scene folder, repeated")
    ap.add_argument("--iterations", default="0,1,2,3,5", help="counts to compare (0, the reference, always)")
    ap.add_argument("--json", default=None, help="write every row to this file")
    ap.add_argument("--novel", action="store_true",
                    help="rescore the renders between exposures (output.ratio_between) instead")
    args = ap.parse_args(argv)
    try:
        if len(args.pairs) % 2:
            raise InputError(WHERE, "RUN SCENE", "pairs of a run folder and its scene folder",
                             f"{len(args.pairs)} paths")
        its = parse_iterations(args.iterations)
        rows = {}
        for run, scene in zip(args.pairs[::2], args.pairs[1::2]):
            rows[run] = (rescore_novel(Path(run), Path(scene)) if args.novel
                         else rescore(Path(run), Path(scene), its))
    except FusionGSError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(format_novel(rows) if args.novel else format_table(rows, its))
    if args.json:
        doc = {"novel": True, "runs": rows} if args.novel else {"iterations": its, "runs": rows}
        write_text(Path(args.json), json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
