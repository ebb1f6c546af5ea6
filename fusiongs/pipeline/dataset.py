"""``fusiongs deblur FOLDER -o OUT`` over a dataset: every scene folder below FOLDER, one table.

A dataset is a folder without ``scene.json`` whose subfolders are scene folders (each with its own
``scene.json``). Each recording is one piece (:mod:`fusiongs.pipeline.executor`): deblurred into
``OUT/<name>/`` exactly as ``fusiongs deblur <name> -o OUT/<name>`` would (a recording longer than
``chunk.seconds`` in time chunks, :mod:`fusiongs.pipeline.chunks`, one after another), its log in
``OUT/<name>/log.txt`` and, once it has finished, its summary row in ``OUT/<name>/piece.json``
(written last, atomically). A piece that fails leaves a row saying why and the others go on; the
summary of all of them is ``OUT/summary.json``. With ``--resume`` the pieces whose ``piece.json``
says done are not run again, and the others resume from their own checkpoints.
"""

from __future__ import annotations

import json
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from fusiongs.atomic import write_text
from fusiongs.errors import FusionGSError, InputError
from fusiongs.pipeline.executor import default_jobs, run_pieces

PIECE_FILE = "piece.json"
SUMMARY_FILE = "summary.json"
LOG_FILE = "log.txt"


def dataset_scenes(root: str | Path, check: bool = True) -> list[Path]:
    """The scene folders directly below ``root`` (those holding a ``scene.json``), sorted by name.

    Raises:
        InputError: with ``check``, when there is none.
    """
    root = Path(root)
    found = sorted(p for p in root.iterdir() if p.is_dir() and (p / "scene.json").is_file()) \
        if root.is_dir() else []
    if check and not found:
        raise InputError(root, "scene folders", "a scene folder (scene.json) or a folder of scene folders",
                         "no scene.json in it or in its subfolders")
    return found


@dataclass(frozen=True)
class PieceTask:
    """One recording of a dataset: what :func:`run_piece` needs (plain values, so it pickles)."""

    name: str
    scene: str
    out: str
    config: str | None
    overrides: tuple[str, ...]
    calibration: str | None
    holdout: str | None
    resume: bool
    whole: bool = False              # a whole recording (of a dataset): cut into time chunks, one after
                                     # another in this piece's process, when it outlasts chunk.seconds


def read_piece(out: str | Path) -> dict | None:
    """The finished row in ``out/piece.json``, or None when the piece has not finished."""
    path = Path(out) / PIECE_FILE
    try:
        row = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return row if isinstance(row, dict) and row.get("status") == "done" else None


def summary_row(name: str, metrics: dict, wall_seconds: float) -> dict:
    """The table's row of a finished run from its metrics (``metrics.json``'s content)."""
    deblur = metrics.get("mean", {}).get("deblur", {})
    held = metrics.get("heldout", {}).get("mean", {})
    return {"name": name, "status": "done", "wall_seconds": round(wall_seconds, 1),
            "iterations": metrics.get("iterations"),
            "psnr": {m: v["psnr"] for m, v in deblur.items()},
            "heldout_psnr": {m: v["psnr"] for m, v in held.items()}}


def longer_than_a_chunk(scene: str | Path, config: str | Path | None, overrides: Sequence[str]) -> bool:
    """Whether the recording ``scene`` outlasts ``chunk.seconds`` of its config (read from
    ``scene.json`` and the event file's ends alone); one that does not is deblurred in one piece,
    as with ``chunk.seconds=0``."""
    from fusiongs.io.scene_io import recording_span
    from fusiongs.pipeline.deblur import resolve_config

    seconds = resolve_config(config, overrides).chunk.seconds
    if seconds <= 0:
        return False
    t0, t1 = recording_span(scene)
    return t1 - t0 > seconds


def run_piece(task: PieceTask) -> dict:
    """Deblur one recording into ``task.out``; returns its summary row, ``status`` "done" or
    "failed" (with ``error``: the one line ``fusiongs deblur`` would have printed)."""
    from fusiongs.pipeline.deblur import run_deblur

    out = Path(task.out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with open(out / LOG_FILE, "a", encoding="utf-8") as log_file:
        def log(*parts) -> None:
            print(*parts, file=log_file, flush=True)

        try:
            if task.whole and longer_than_a_chunk(task.scene, task.config, task.overrides):
                from fusiongs.pipeline.chunks import run_chunked

                metrics = run_chunked(task.scene, out, config=task.config, overrides=task.overrides,
                                      resume=task.resume, log=log, calibration=task.calibration,
                                      holdout=task.holdout, jobs=1, executor="serial").get("metrics", {})
            else:
                metrics = run_deblur(task.scene, out, config=task.config, overrides=task.overrides,
                                     resume=task.resume, log=log, calibration=task.calibration,
                                     holdout=task.holdout)
        except Exception as e:  # noqa: BLE001 (a piece reports its failure; the others go on)
            if not isinstance(e, FusionGSError):
                log(traceback.format_exc())
            error = str(e) if isinstance(e, FusionGSError) else f"{type(e).__name__}: {e} (see {LOG_FILE})"
            log(f"error: {error}")
            return {"name": task.name, "status": "failed", "error": error,
                    "wall_seconds": round(time.perf_counter() - start, 1)}
    row = summary_row(task.name, metrics, time.perf_counter() - start)
    write_text(out / PIECE_FILE, json.dumps(row, indent=2) + "\n")
    return row


def format_summary(rows: Sequence[dict]) -> str:
    """The dataset's table: one line per recording (deblur-view PSNR against truth where the scene
    has it, held-out PSNR where ``--holdout`` was given)."""
    def cell(d: dict, key: str) -> str:
        v = d.get(key)
        return f"{v:>10.2f}" if isinstance(v, int | float) else f"{'-':>10}"

    w = max([10] + [len(r["name"]) + 2 for r in rows])
    lines = [f"{'recording':<{w}}{'status':<10}{'minutes':>8}{'fusiongs':>10}{'EDI':>10}{'EDI true θ':>12}"
             f"{'blurry':>10}{'held-out':>10}{'held EDI':>10}"]
    for r in rows:
        p, h = r.get("psnr", {}), r.get("heldout_psnr", {})
        lines.append(f"{r['name']:<{w}}{r['status']:<10}{r.get('wall_seconds', 0) / 60:>8.1f}"
                     f"{cell(p, 'fusiongs')}{cell(p, 'edi')}{cell(p, 'edi_true_theta'):>12}"
                     f"{cell(p, 'blurry')}{cell(h, 'fusiongs')}{cell(h, 'edi_carried')}")
    return "\n".join(lines)


def run_all(tasks: Sequence[PieceTask], intro: str, *, jobs: int | None, executor: str,
            address: str | None, log: Callable[..., None], label: str = "") -> list[dict]:
    """Run the pieces ``tasks`` (:func:`run_piece`), ``jobs`` at a time (None or 0: one per core),
    logging ``intro`` with the plan first and one line per finished piece (``label`` before its
    name); returns their rows in the order of ``tasks``."""
    jobs = default_jobs(len(tasks)) if jobs in (None, 0) else jobs
    log(f"{intro}: {len(tasks)} to run, {jobs} at a time ({executor})")

    def done(row: dict) -> None:
        what = row.get("error") or f"{row['wall_seconds'] / 60:.1f} min"
        log(f"{label}{row['name']}: {row['status']} ({what})")

    return run_pieces(run_piece, tasks, jobs=jobs, executor=executor, on_done=done, address=address)


def raise_failed(rows: Sequence[dict], what: str, out: Path) -> None:
    """After every piece ran: one :class:`FusionGSError` line naming the failed ones, if any."""
    failed = [r for r in rows if r["status"] != "done"]
    if failed:
        names = "; ".join(f"{r['name']}: {r.get('error', 'failed')}" for r in failed)
        raise FusionGSError(f"{len(failed)} of {len(rows)} {what}(s) failed ({names}); the others are "
                            f"finished in {out}; fix them and run again with --resume")


def run_dataset(root: str | Path, out: str | Path, *, config: str | Path | None = None,
                overrides: Sequence[str] = (), calibration: str | Path | None = None,
                holdout: int | str | None = None, resume: bool = False, jobs: int | None = None,
                executor: str = "local", address: str | None = None,
                log: Callable[..., None] = print) -> list[dict]:
    """Deblur every recording of a dataset folder (see the module docstring); returns the rows.

    Raises:
        InputError: no scene folder, or a bad configuration (checked before any piece runs).
        FusionGSError: after every piece ran, when some failed (one line naming them); the
            finished ones and ``summary.json`` are written first.
    """
    from fusiongs.eval.holdout import parse_holdout
    from fusiongs.pipeline.deblur import resolve_config

    scenes = dataset_scenes(root)
    resolve_config(config, overrides)  # a bad key stops here, not once per recording
    parse_holdout(holdout)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict] = {}
    tasks = []
    for scene in scenes:
        finished = read_piece(out / scene.name) if resume else None
        if finished is not None:
            rows[scene.name] = finished | {"status": "done", "resumed": True}
            log(f"{scene.name}: finished earlier (kept)")
            continue
        tasks.append(PieceTask(scene.name, str(scene), str(out / scene.name),
                               None if config is None else str(config), tuple(overrides),
                               None if calibration is None else str(calibration),
                               None if holdout is None else str(holdout), resume, whole=True))
    for row in run_all(tasks, f"{len(scenes)} recording(s) in {root}", jobs=jobs, executor=executor,
                       address=address, log=log):
        rows[row["name"]] = row
    ordered = [rows[s.name] for s in scenes]
    write_text(out / SUMMARY_FILE, json.dumps({"root": str(root), "recordings": ordered}, indent=2) + "\n")
    log(format_summary(ordered))
    raise_failed(ordered, "recording", out)
    return ordered
