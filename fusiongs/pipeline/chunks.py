"""``fusiongs deblur`` of a long recording in overlapping time chunks (``chunk.seconds``).

One Gaussian scene with one budget does not hold a recording whose view keeps changing (a walk down
a corridor): its far bound, its Gaussians and its iterations are spread over everything the camera
ever saw. Past ``chunk.seconds`` the recording is cut into chunks of at most that length that share
``chunk.overlap`` seconds with their neighbours (:func:`plan_chunks`). The thresholds are calibrated
once for the whole recording, on its middle exposures (:func:`calibration_window`); each chunk is
then written as a scene folder of its own (``OUT/chunks/NNN/scene/``: its frames, events, trajectory
piece and truth images) and deblurred into ``OUT/chunks/NNN/run/`` as one piece
(:mod:`fusiongs.pipeline.executor`: in parallel, checkpointed and resumed one by one, as the
recordings of a dataset are), with its own scene extent, far bound, Gaussian budget and iterations.
The results are stitched: every frame, render instant and trajectory sample is taken from the chunk
in whose middle it lies (:func:`owners`), into ``OUT/deblurred/``, ``OUT/deblurred.mp4``,
``OUT/renders/`` and ``OUT/trajectory.txt``; ``OUT/chunks.json`` lists the chunks (spans, frames,
PLY files) and ``OUT/metrics.json`` scores the stitched frames against the truth, where the
recording has it.

Without a given trajectory each chunk poses its own frames, in a frame of its own: each chunk's
path is then brought onto the previous chunk's by the similarity that best maps its camera centres
in the overlap (Umeyama), and ``chunks.json`` holds that transform (``to_first``) for its PLY.
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from fusiongs.atomic import write_text
from fusiongs.camera.tum import PoseSamples, read_tum, write_tum
from fusiongs.errors import ConfigError, FusionGSError, InputError
from fusiongs.io.scene import Scene
from fusiongs.pipeline.pieces import PieceTask, raise_failed, read_piece, run_all

CHUNKS_FILE = "chunks.json"
CHUNKS_DIR = "chunks"
CALIBRATION_FRAMES = 48  # the thresholds of a chunked recording come from its middle 48 exposures


def plan_chunks(t_first: float, t_last: float, seconds: float, overlap: float) -> list[tuple[float, float]]:
    """Spans ``[(t0, t1), ...]`` (s) covering ``[t_first, t_last]``: one when ``seconds`` is 0 or
    the recording is no longer; otherwise the fewest equal spans of at most ``seconds`` whose
    neighbours share ``overlap`` seconds."""
    length = t_last - t_first
    if seconds <= 0 or length <= seconds:
        return [(t_first, t_last)]
    n = math.ceil((length - overlap) / (seconds - overlap))
    step = (length - overlap) / n
    return [(t_first + i * step, t_first + i * step + step + overlap) if i < n - 1
            else (t_first + i * step, t_last) for i in range(n)]


def owners(times: np.ndarray, spans: Sequence[tuple[float, float]]) -> np.ndarray:
    """``[N]`` index of the span in whose middle each instant lies: the span that maximises the
    instant's distance to its nearer end (an instant outside every span goes to the nearest)."""
    t = np.asarray(times, dtype=np.float64)[:, None]
    lo = np.array([s[0] for s in spans])[None]
    hi = np.array([s[1] for s in spans])[None]
    return np.argmax(np.minimum(t - lo, hi - t), axis=1)


def scene_span(scene: Scene) -> tuple[float, float]:
    """First and last instant (s) of what the recording holds: its events and its exposures."""
    ends = []
    if scene.events is not None and len(scene.events):
        ends += [float(scene.events.t[0]) * 1e-6, float(scene.events.t[-1]) * 1e-6]
    if len(scene.frames):
        ends += [float(scene.frames.t_start.min()), float(scene.frames.t_end.max())]
    return min(ends), max(ends)


def check_chunks(scene: Scene, seconds: float, overlap: float) -> None:
    """A chunk must hold two whole exposures (else its blur has nothing to fit)."""
    if seconds <= 0 or not len(scene.frames):
        return
    longest = float((scene.frames.t_end - scene.frames.t_start).max())
    if seconds - overlap < longest or seconds < 2 * longest:
        raise ConfigError("config", "chunk.seconds", f"at least two exposures ({2 * longest:g} s) and "
                          f"more than chunk.overlap plus one exposure ({overlap + longest:g} s)", seconds)


def calibration_window(scene: Scene, frames: int | None = None) -> Scene:
    """The middle ``frames`` (default :data:`CALIBRATION_FRAMES`) whole exposures of ``scene`` with
    their events, or the whole scene when it has no more: what the thresholds of a chunked
    recording are estimated on. The estimate's cost grows with the frames (every frame pair at
    every candidate threshold: 240 frames of a 20 s walk take minutes), and 12-96 frames is the
    range its accuracy was measured on."""
    frames = CALIBRATION_FRAMES if frames is None else frames
    fs = scene.frames
    if len(fs) <= frames:
        return scene
    first = (len(fs) - frames) // 2
    return chunk_scene(scene, float(fs.t_start[first:first + frames].min()),
                       float(fs.t_end[first:first + frames].max()))


def chunk_scene(scene: Scene, t0: float, t1: float) -> Scene:
    """The part of ``scene`` inside ``[t0, t1]`` (s): whole exposures, events, render instants, and
    the pose samples that span it (one beyond each end, so the path can be interpolated)."""
    import dataclasses

    from fusiongs.frames.frameset import FrameSet

    fs = scene.frames
    keep = np.flatnonzero((fs.t_start >= t0) & (fs.t_end <= t1))
    frames = FrameSet(fs.images[keep], fs.t_start[keep], fs.t_end[keep],
                      tuple(fs.names[i] for i in keep), fs.response)
    events = None if scene.events is None else scene.events.slice_time(int(math.floor(t0 * 1e6)),
                                                                      int(math.ceil(t1 * 1e6)) + 1)
    poses = scene.poses
    if poses is not None:
        i0 = max(0, int(np.searchsorted(poses.t, t0, side="right")) - 1)
        i1 = min(len(poses.t), int(np.searchsorted(poses.t, t1, side="left")) + 1)
        poses = PoseSamples(poses.t[i0:i1], poses.c2w[i0:i1])
    renders = tuple(r for r in scene.renders if t0 <= r.t <= t1)
    return dataclasses.replace(scene, frames=frames, events=events, poses=poses, renders=renders, root=None)


def _frame_bits(scene: Scene) -> int:
    """8 or 16: the bit depth of the scene's frame files (a chunk stores its frames as they were)."""
    import cv2

    from fusiongs.io.scene_io import read_scene_spec

    if scene.root is None or not len(scene.frames):
        return 8
    spec = read_scene_spec(scene.root)
    img = cv2.imread(str(scene.root / spec.frames[0].path), cv2.IMREAD_UNCHANGED)
    return 16 if img is not None and img.dtype == np.uint16 else 8


def write_chunk(scene: Scene, t0: float, t1: float, folder: Path, bits: int) -> Scene:
    """Write the chunk ``[t0, t1]`` of ``scene`` as a scene folder (with the truth images of its
    frames and instants, and ``gt/sim.json``, where the recording has them); returns the chunk."""
    from fusiongs.io.scene_io import save_scene

    part = chunk_scene(scene, t0, t1)
    save_scene(part, folder, images_bits=bits)
    gt = scene.root / "gt" if scene.root is not None else None
    if gt is not None and gt.is_dir():
        names = [f"deblur_{n}.png" for n in part.frames.names] + [f"{r.name}.png" for r in part.renders]
        (folder / "gt").mkdir(exist_ok=True)
        for name in [*names, "sim.json"]:
            if (gt / name).is_file():
                shutil.copyfile(gt / name, folder / "gt" / name)
    return part


def _aligned(paths: list[PoseSamples], spans: Sequence[tuple[float, float]]) -> list[np.ndarray]:
    """Similarity ``[4, 4]`` taking each chunk's path onto the first chunk's frame, chained through
    the overlaps (identity for the first, and where an overlap has too few samples to fit one)."""
    from fusiongs.sfm.align import umeyama

    out = [np.eye(4)]
    for k in range(1, len(paths)):
        lo, hi = spans[k][0], spans[k - 1][1]
        prev, cur = paths[k - 1], paths[k]
        t = cur.t[(cur.t >= lo) & (cur.t <= hi) & (cur.t >= prev.t[0]) & (cur.t <= prev.t[-1])]
        sim = np.eye(4)
        if len(t) >= 3:
            src = np.stack([np.interp(t, cur.t, cur.c2w[:, i, 3]) for i in range(3)], axis=1)
            dst = np.stack([np.interp(t, prev.t, prev.c2w[:, i, 3]) for i in range(3)], axis=1)
            try:
                s, rot, shift = umeyama(src, dst)
                sim[:3, :3], sim[:3, 3] = s * rot, shift
            except (FusionGSError, np.linalg.LinAlgError):
                pass
        out.append(out[-1] @ sim)
    return out


def _apply(sim: np.ndarray, poses: PoseSamples) -> PoseSamples:
    """A similarity applied to camera-to-world poses (rotation kept orthonormal)."""
    c2w = poses.c2w.copy()
    scale = np.cbrt(np.linalg.det(sim[:3, :3]))
    c2w[:, :3, :3] = (sim[:3, :3] / scale) @ c2w[:, :3, :3]
    c2w[:, :3, 3] = c2w[:, :3, 3] @ sim[:3, :3].T + sim[:3, 3]
    return PoseSamples(poses.t, c2w)


def stitch(scene: Scene, spans: Sequence[tuple[float, float]], runs: Sequence[Path], out: Path,
           fps: float) -> dict:
    """Stitch the chunks' outputs into ``out`` (see the module docstring); returns ``chunks.json``."""
    from fusiongs.frames.image_io import read_image
    from fusiongs.outputs.video import write_mp4

    fs = scene.frames
    frame_owner = owners(fs.mid_times(), spans) if len(fs) else np.zeros(0, int)
    stitched = []
    for j, name in enumerate(fs.names):
        src = runs[frame_owner[j]] / "deblurred" / f"{name}.png"
        dst = out / "deblurred" / f"{name}.png"
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst)
        stitched.append(read_image(dst))
    if stitched:
        write_mp4(out / "deblurred.mp4", stitched, fps)
    if scene.renders:
        render_owner = owners(np.array([r.t for r in scene.renders]), spans)
        for r, k in zip(scene.renders, render_owner):
            (out / "renders").mkdir(exist_ok=True)
            shutil.copyfile(runs[k] / "renders" / f"{r.name}.png", out / "renders" / f"{r.name}.png")
    paths = [read_tum(run / "trajectory.txt") for run in runs]
    sims = _aligned(paths, spans) if scene.poses is None else [np.eye(4)] * len(runs)
    pieces = []
    for k, path in enumerate(paths):
        mine = owners(path.t, spans) == k
        pieces.append(_apply(sims[k], PoseSamples(path.t[mine], path.c2w[mine])))
    t = np.concatenate([p.t for p in pieces])
    order = np.argsort(t, kind="stable")
    write_tum(out / "trajectory.txt", PoseSamples(t[order], np.concatenate([p.c2w for p in pieces])[order]))
    index = {"chunks": [
        {"index": k, "t0": spans[k][0], "t1": spans[k][1], "run": str(runs[k].relative_to(out)),
         "ply": str((runs[k] / "model.ply").relative_to(out)), "to_first": sims[k].tolist(),
         "frames": [n for n, o in zip(fs.names, frame_owner) if o == k]} for k in range(len(runs))]}
    write_text(out / CHUNKS_FILE, json.dumps(index, indent=2) + "\n")
    return index


def score(scene: Scene, out: Path, thresholds) -> dict | None:
    """Metrics of the stitched frames against the recording's truth (None without ``gt/``): per
    frame and mean, beside the blurry input and EDI (at ``thresholds`` and, for a simulated
    recording, at the true thresholds), as ``metrics.json`` of a single run has them."""
    from fusiongs.eval.evaluate import compare_methods
    from fusiongs.frames.image_io import read_image
    from fusiongs.pipeline.deblur import baseline_images
    from fusiongs.train.render_io import read_gt

    if scene.root is None or not (scene.root / "gt").is_dir() or not len(scene.frames):
        return None
    names = [f"deblur_{n}" for n in scene.frames.names]
    gt = read_gt(scene.root / "gt", names)
    if not gt:
        return None
    methods = baseline_images(scene, thresholds)
    methods["fusiongs"] = {f"deblur_{n}": read_image(out / "deblurred" / f"{n}.png")
                           for n in scene.frames.names}
    return compare_methods(methods, gt)


def run_chunked(scene_path: str | Path, out: str | Path, *, config: str | Path | None = None,
                overrides: Sequence[str] = (), calibration: str | Path | None = None,
                holdout: int | str | None = None, resume: bool = False, jobs: int | None = None,
                executor: str = "local", address: str | None = None,
                log: Callable[..., None] = print) -> dict:
    """Deblur a long recording chunk by chunk and stitch the results (see the module docstring).

    Returns ``chunks.json``'s content, with ``"metrics"`` (the stitched frames' scores) when the
    recording has truth images; a recording no longer than one chunk is deblurred in one piece
    (:func:`fusiongs.pipeline.deblur.run_deblur`, whose metrics are returned).

    Raises:
        ConfigError: ``chunk.seconds`` shorter than two exposures (or than the overlap plus one).
        FusionGSError: after every chunk ran, when some failed (one line naming them); the
            finished chunks stay in ``OUT/chunks/`` for ``--resume``.
    """
    from fusiongs.calibrate.estimate import estimate_thresholds
    from fusiongs.calibrate.options import CalibrateOptions
    from fusiongs.eval.evaluate import format_table
    from fusiongs.events.thresholds import read_calibration, write_calibration
    from fusiongs.io.scene_io import load_scene
    from fusiongs.pipeline.deblur import resolve_config

    cfg = resolve_config(config, overrides)
    scene = load_scene(scene_path)
    check_chunks(scene, cfg.chunk.seconds, cfg.chunk.overlap)
    spans = plan_chunks(*scene_span(scene), cfg.chunk.seconds, cfg.chunk.overlap)
    if len(spans) == 1:  # no longer than one chunk: one piece, as without chunk.seconds
        from fusiongs.pipeline.deblur import run_deblur

        return run_deblur(scene_path, out, config=config, overrides=overrides, resume=resume, log=log,
                          calibration=calibration, holdout=holdout)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    calib_file = out / "calibration.json"
    if calibration is not None:
        thresholds = read_calibration(calibration)[0]
        write_calibration(calib_file, thresholds, scene=str(scene_path))
    elif resume and calib_file.is_file():
        thresholds = read_calibration(calib_file)[0]
    elif cfg.threshold.estimate and scene.events is not None and len(scene.events):
        try:  # once, on the whole recording, as a single run would estimate them
            part = calibration_window(scene)
            thresholds = estimate_thresholds(part.frames, part.events,
                                             CalibrateOptions(unknown_scale=cfg.threshold.init))
            write_calibration(calib_file, thresholds, scene=str(scene_path))
        except InputError as e:  # too little data: each chunk starts from threshold.init
            log(f"thresholds not estimated ({e}); each chunk starts from threshold.init")
            thresholds = None
    else:
        thresholds = None
    bits = _frame_bits(scene)
    tasks, runs = [], []
    for k, (t0, t1) in enumerate(spans):
        folder = out / CHUNKS_DIR / f"{k:03d}"
        runs.append(folder / "run")
        if not (resume and (folder / "scene" / "scene.json").is_file()):
            write_chunk(scene, t0, t1, folder / "scene", bits)
        if resume and read_piece(folder / "run") is not None:
            log(f"chunk {k:03d}: finished earlier (kept)")
            continue
        tasks.append(PieceTask(f"{k:03d}", str(folder / "scene"), str(folder / "run"),
                               None if config is None else str(config), tuple(overrides),
                               None if thresholds is None else str(calib_file),
                               None if holdout is None else str(holdout), resume))
    intro = (f"{len(spans)} chunk(s) of at most {cfg.chunk.seconds:g} s (overlap {cfg.chunk.overlap:g} s) "
             f"over {spans[0][0]:.2f}-{spans[-1][1]:.2f} s")
    raise_failed(run_all(tasks, intro, jobs=jobs, executor=executor, address=address, log=log,
                         label="chunk "), "chunk", out / CHUNKS_DIR)
    index = stitch(scene, spans, runs, out, cfg.output.video_fps)
    metrics = score(scene, out, thresholds)
    if metrics is not None:
        write_text(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
        log(format_table(metrics))
        index["metrics"] = metrics
    log(f"outputs in {out}")
    return index
