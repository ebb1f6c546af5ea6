"""Pieces of work that checkpoint, fail and resume on their own: the recordings of a dataset
(:mod:`fusiongs.pipeline.dataset`) and the time chunks of a long recording
(:mod:`fusiongs.pipeline.chunks`).

A piece is deblurred into its own folder (its log in ``log.txt``) and, once it has finished, writes
its summary row to ``piece.json`` (last, atomically); ``--resume`` skips the pieces whose
``piece.json`` says done, and the others resume from their own checkpoints. A piece that fails
returns a row saying why, and the others go on (:func:`raise_failed` then names the failed ones).
The pieces run side by side through :mod:`fusiongs.pipeline.executor`.
"""

from __future__ import annotations

import functools
import json
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from fusiongs.atomic import write_text
from fusiongs.errors import FusionGSError
from fusiongs.pipeline.executor import default_jobs, run_pieces

PIECE_FILE = "piece.json"
LOG_FILE = "log.txt"


@dataclass(frozen=True)
class PieceTask:
    """One piece (a recording of a dataset, a chunk of one): what :func:`run_piece` needs (plain
    values, so it pickles)."""

    name: str
    scene: str
    out: str
    config: str | None
    overrides: tuple[str, ...]
    calibration: str | None
    holdout: str | None
    resume: bool


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


def run_piece(task: PieceTask, deblur: Callable[..., dict] | None = None) -> dict:
    """Deblur one piece into ``task.out`` with ``deblur`` (a top-level function with the arguments
    of :func:`fusiongs.pipeline.deblur.run_deblur`, which it defaults to; it returns the metrics);
    returns its summary row, ``status`` "done" or "failed" (with ``error``: the one line
    ``fusiongs deblur`` would have printed)."""
    if deblur is None:
        from fusiongs.pipeline.deblur import run_deblur as deblur

    out = Path(task.out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with open(out / LOG_FILE, "a", encoding="utf-8") as log_file:
        def log(*parts) -> None:
            print(*parts, file=log_file, flush=True)

        try:
            metrics = deblur(task.scene, out, config=task.config, overrides=task.overrides,
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


def run_all(tasks: Sequence[PieceTask], intro: str, *, jobs: int | None, executor: str,
            address: str | None, log: Callable[..., None], label: str = "",
            deblur: Callable[..., dict] | None = None) -> list[dict]:
    """Run the pieces ``tasks`` (:func:`run_piece` with ``deblur``), ``jobs`` at a time (None or 0:
    one per core),
    logging ``intro`` with the plan first and one line per finished piece (``label`` before its
    name); returns their rows in the order of ``tasks``."""
    jobs = default_jobs(len(tasks)) if jobs in (None, 0) else jobs
    log(f"{intro}: {len(tasks)} to run, {jobs} at a time ({executor})")

    def done(row: dict) -> None:
        what = row.get("error") or f"{row['wall_seconds'] / 60:.1f} min"
        log(f"{label}{row['name']}: {row['status']} ({what})")

    fn = run_piece if deblur is None else functools.partial(run_piece, deblur=deblur)
    return run_pieces(fn, tasks, jobs=jobs, executor=executor, on_done=done, address=address)


def raise_failed(rows: Sequence[dict], what: str, out: Path) -> None:
    """After every piece ran: one :class:`FusionGSError` line naming the failed ones, if any."""
    failed = [r for r in rows if r["status"] != "done"]
    if failed:
        names = "; ".join(f"{r['name']}: {r.get('error', 'failed')}" for r in failed)
        raise FusionGSError(f"{len(failed)} of {len(rows)} {what}(s) failed ({names}); the others are "
                            f"finished in {out}; fix them and run again with --resume")
