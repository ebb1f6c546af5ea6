"""The pose stage on simulated scenes whose trajectory (and optionally intrinsics) is withheld.

The target: "poses within 1 % of the scene extent and 0.5° after similarity alignment,
deblur PSNR within 0.5 dB of the run with the true trajectory". For every scene (simulated here
with the defaults of ``fusiongs simulate``, or given with ``--scenes``), a copy without the
trajectory (and, with ``--withhold-intrinsics``, without fx, fy, cx, cy) goes through the pose
stage of ``fusiongs deblur`` alone (EDI + pycolmap, no training); its ``trajectory_initial.txt`` is
compared with the truth at the frames' mid-exposure instants.

Errors are measured after :func:`fusiongs.sfm.align.align_sim3` (Umeyama on the camera centres,
orientations added to the cross-covariance so the rotation is determined for a straight pan):
position error in percent of the scene extent, rotation error in degrees. The **scene extent** is
the diagonal of the axis-aligned bounding box of the true camera centres and of the surface points
seen at the frames' mid-exposure (one ray per pixel, 2nd to 98th percentile per axis, so a floor
running to the horizon does not dominate); it needs the preset of ``gt/sim.json``. Without it the
extent is the diameter of the true camera path (the largest distance between two centres); the
path diameter is printed as well, for a stricter reading. COLMAP's matching on 2 threads is not
deterministic: ``--repeats N`` runs the pose stage N times per scene and reports the median RMSE
and the worst maximum.

``--deblur`` also trains both the scene with its true trajectory (the reference, measured in the
same run) and the withheld copy, and reports the refined ``trajectory.txt``'s errors and the
deblur-view PSNR of both.

    PYTHONPATH=. python benchmarks/bench_poses.py --presets boxes,wall --seeds 3,4
    PYTHONPATH=. python benchmarks/bench_poses.py --presets boxes --seeds 3 --deblur \\
        --config deblur_fast
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from benchmarks.bench_deblur import run_one  # noqa: E402
from fusiongs.camera.tum import read_tum  # noqa: E402
from fusiongs.io import load_scene  # noqa: E402
from fusiongs.sfm.align import pose_errors  # noqa: E402
from fusiongs.sfm.register import fill_poses  # noqa: E402

INTRINSICS = ("fx", "fy", "cx", "cy")


def simulated_scene(root: Path, preset: str, seed: int, size: str) -> Path:
    """``fusiongs simulate``'s default scene for ``preset`` / ``seed`` (made once, then reused)."""
    from fusiongs.sim.simulate import SimConfig, run_simulation
    from fusiongs.sim.write import write_simulated_scene

    path = root / "scenes" / f"{preset}_s{seed}_{size}"
    if not (path / "scene.json").is_file():
        w, h = (int(v) for v in size.split("x"))
        res = run_simulation(SimConfig(preset=preset, seed=seed, width=w, height=h))
        write_simulated_scene(res.scene, res.gt, path, stats=res.stats, overwrite=True)
    return path


def withheld_copy(scene: Path, dst: Path, intrinsics: bool = False) -> Path:
    """A copy of ``scene`` without its trajectory (and without fx, fy, cx, cy when
    ``intrinsics``); ``gt/`` is kept so a trained run can still be scored."""
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(scene, dst)
    doc = json.loads((dst / "scene.json").read_text())
    traj = doc.pop("trajectory", None)
    if traj:
        (dst / traj).unlink(missing_ok=True)
    if intrinsics:
        for k in INTRINSICS:
            doc["camera"].pop(k, None)
    (dst / "scene.json").write_text(json.dumps(doc, indent=2))
    return dst


def scene_extent(scene: Path, true_c2w: np.ndarray) -> tuple[float, str]:
    """``(extent, how)``: see the module docstring (``true_c2w [N, 4, 4]`` at the frames)."""
    centres = true_c2w[:, :3, 3]
    diameter = float(np.max(np.linalg.norm(centres[:, None] - centres[None], axis=-1)))
    sim = scene / "gt" / "sim.json"
    if not sim.is_file():
        return diameter, "path diameter"
    from fusiongs.sim.presets import get_preset
    from fusiongs.sim.raycast import RayCaster

    s = load_scene(scene, load_events=False)
    caster = RayCaster(get_preset(json.loads(sim.read_text())["preset"]).world, s.camera, 1, 0, "cpu")
    pts = np.concatenate([caster.surface_points(torch.as_tensor(c)).numpy() for c in true_c2w])
    lo, hi = np.percentile(pts, 2, axis=0), np.percentile(pts, 98, axis=0)
    lo, hi = np.minimum(lo, centres.min(0)), np.maximum(hi, centres.max(0))
    return float(np.linalg.norm(hi - lo)), "bounding box of cameras and seen surfaces"


def at_times(samples, t: np.ndarray) -> np.ndarray:
    """Poses of a :class:`PoseSamples` at times ``t`` (slerp / linear between samples)."""
    return fill_poses(samples.t, np.ones(len(samples.t), bool), samples.c2w, t)


def score(est_samples, true_samples, t: np.ndarray, extent: float) -> dict:
    """Errors of an estimated path at instants ``t`` after Sim(3) alignment."""
    pos, rot = pose_errors(at_times(est_samples, t), at_times(true_samples, t))
    return {"pos_rmse_pct": 100 * float(np.sqrt(np.mean(pos ** 2))) / extent,
            "pos_max_pct": 100 * float(pos.max()) / extent,
            "rot_rmse_deg": float(np.sqrt(np.mean(rot ** 2))), "rot_max_deg": float(rot.max())}


def aggregate(runs: list[dict]) -> dict:
    """Repeated runs: the median of the RMSEs and the worst of the maxima."""
    return {k: float(np.max([r[k] for r in runs]) if "max" in k else np.median([r[k] for r in runs]))
            for k in runs[0]} | {"runs": runs}


def run_pose_stage_only(scene: Path, out: Path, config: str, overrides: list[str]) -> dict:
    """The pose stage exactly as ``fusiongs deblur`` runs it (thresholds estimated, EDI,
    pycolmap), without training; writes ``out/trajectory_initial.txt`` and ``out/camera.json``."""
    from fusiongs.pipeline.deblur import resolve_config
    from fusiongs.pipeline.poses import CAMERA_FILE, run_pose_stage

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    lines = []
    run_pose_stage(load_scene(scene), resolve_config(config, overrides), out, log=lines.append)
    doc = json.loads((out / CAMERA_FILE).read_text())
    doc["wall_seconds"], doc["log"] = time.perf_counter() - t0, lines
    return doc


def bench_scene(scene: Path, root: Path, args) -> dict:
    """Pose stage (and with ``--deblur`` both trainings) on one scene; the row's figures."""
    s = load_scene(scene, load_events=False)
    if s.poses is None:
        raise SystemExit(f"{scene}: needs its true trajectory to be scored")
    mids = s.frames.mid_times()
    true_at = at_times(s.poses, mids)
    extent, how = scene_extent(scene, true_at)
    centres = true_at[:, :3, 3]
    diameter = float(np.max(np.linalg.norm(centres[:, None] - centres[None], axis=-1)))
    held = withheld_copy(scene, root / "withheld" / scene.name, args.withhold_intrinsics)
    runs = []
    for _ in range(max(args.repeats, 1)):  # COLMAP on 2 threads is not deterministic
        stage = run_pose_stage_only(held, root / "poses" / scene.name, args.config, args.overrides)
        runs.append(score(read_tum(root / "poses" / scene.name / "trajectory_initial.txt"), s.poses,
                          mids, extent))
    init = aggregate(runs)
    rep = stage["report"]
    row = {"scene": scene.name, "frames": len(mids), "registered": rep["registered"],
           "extent": extent, "extent_how": how, "path_diameter": diameter, "initial": init,
           "focal": rep["focal"][0], "focal_true": getattr(s.camera, "fx", None),
           "focal_observable": rep["focal_observable"], "reprojection_px": rep["reprojection_error_px"],
           "points": rep["n_points"], "pose_seconds": stage["wall_seconds"]}
    if args.deblur:
        ref = run_one(scene, root / "runs" / f"{scene.name}_true", args.config, args.overrides, args.reuse)
        run = run_one(held, root / "runs" / f"{scene.name}_withheld", args.config, args.overrides,
                     args.reuse)
        refined = read_tum(root / "runs" / f"{scene.name}_withheld" / "trajectory.txt")
        row.update(refined=score(refined, s.poses, mids, extent),
                   psnr_true=ref["mean"]["deblur"]["fusiongs"]["psnr"],
                   psnr_withheld=run["mean"]["deblur"]["fusiongs"]["psnr"],
                   train_minutes=(ref["wall_seconds"] + run["wall_seconds"]) / 60)
    return row


def table(rows: list[dict], deblur_cols: bool) -> str:
    head = ("| scene | registered | extent / path diameter | pos RMSE / max (% extent) | "
            "rot RMSE / max (deg) | focal est / true (px) | pose stage s |")
    sep = "|---|---|---|---|---|---|---|"
    if deblur_cols:
        head += (" refined pos RMSE / max (%) | refined rot RMSE / max (deg) | PSNR true traj | "
                 "PSNR withheld | Δ |")
        sep += "---|---|---|---|---|"
    lines = [head, sep]
    for r in rows:
        i = r["initial"]
        focal_true = f"{r['focal_true']:.1f}" if r["focal_true"] is not None else "?"
        line = (f"| {r['scene']} | {r['registered']}/{r['frames']} | {r['extent']:.2f} / "
                f"{r['path_diameter']:.2f} | {i['pos_rmse_pct']:.2f} / {i['pos_max_pct']:.2f} | "
                f"{i['rot_rmse_deg']:.2f} / {i['rot_max_deg']:.2f} | {r['focal']:.1f} / {focal_true} | "
                f"{r['pose_seconds']:.0f} |")
        if deblur_cols and "refined" in r:
            f = r["refined"]
            line += (f" {f['pos_rmse_pct']:.2f} / {f['pos_max_pct']:.2f} | {f['rot_rmse_deg']:.2f} / "
                     f"{f['rot_max_deg']:.2f} | {r['psnr_true']:.2f} | {r['psnr_withheld']:.2f} | "
                     f"{r['psnr_withheld'] - r['psnr_true']:+.2f} |")
        lines.append(line)
    return "\n".join(lines)


def checks(rows: list[dict]) -> list[str]:
    """The targets, checked on the worst scene."""
    pos = max(r["initial"]["pos_max_pct"] for r in rows)
    rot = max(r["initial"]["rot_max_deg"] for r in rows)
    out = [f"initial poses, worst max position error {pos:.2f} % of extent (target 1 %): "
           f"{'met' if pos <= 1 else 'NOT met'}",
           f"initial poses, worst max rotation error {rot:.2f} deg (target 0.5): "
           f"{'met' if rot <= 0.5 else 'NOT met'}"]
    deb = [r for r in rows if "psnr_true" in r]
    if deb:
        gap = min(r["psnr_withheld"] - r["psnr_true"] for r in deb)
        out.append(f"deblur PSNR withheld - true trajectory, worst {gap:+.2f} dB (target >= -0.5): "
                   f"{'met' if gap >= -0.5 else 'NOT met'}")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="bench_out/poses")
    p.add_argument("--presets", default="boxes,wall,corridor")
    p.add_argument("--seeds", default="3")
    p.add_argument("--size", default="173x130")
    p.add_argument("--scenes", nargs="*", default=None, help="scene folders to use instead of simulating")
    p.add_argument("--withhold-intrinsics", action="store_true", help="also remove fx, fy, cx, cy")
    p.add_argument("--deblur", action="store_true", help="also train with the true and the estimated path")
    p.add_argument("--config", default="configs/deblur.yaml")
    p.add_argument("--repeats", type=int, default=1,
                   help="pose stage runs per scene: RMSE is their median, max the worst of them")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--reuse", action="store_true", help="read back finished trainings")
    p.add_argument("overrides", nargs="*", help="config overrides (pose stage and training)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    root = Path(args.out)
    if args.scenes:
        scenes = [Path(s) for s in args.scenes]
    else:
        scenes = [simulated_scene(root, pr, int(sd), args.size)
                  for pr in args.presets.split(",") for sd in args.seeds.split(",")]
    print(f"pose stage, config {args.config} {' '.join(args.overrides)}; withheld: trajectory"
          f"{' and intrinsics' if args.withhold_intrinsics else ''}; {args.repeats} run(s) per scene; "
          f"torch threads {torch.get_num_threads()}")
    rows = []
    for scene in scenes:
        rows.append(bench_scene(scene, root, args))
        print(table(rows[-1:], args.deblur).splitlines()[-1], flush=True)
    print(f"\nextent: {rows[0]['extent_how']}\n")
    print(table(rows, args.deblur))
    print("\n".join(checks(rows)))
    name = "results_intrinsics.json" if args.withhold_intrinsics else "results.json"
    (root / name).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
