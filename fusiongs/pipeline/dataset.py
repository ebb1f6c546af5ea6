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
from collections.abc import Callable, Sequence
from pathlib import Path

from fusiongs.atomic import write_text
from fusiongs.errors import InputError
from fusiongs.pipeline.pieces import PieceTask, raise_failed, read_piece, run_all

SUMMARY_FILE = "summary.json"


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


def deblur_recording(scene: str | Path, out: str | Path, **kw) -> dict:
    """One recording of a dataset, as ``fusiongs deblur SCENE -o OUT`` would: in time chunks, one
    after another in this process, when it outlasts ``chunk.seconds``
    (:func:`fusiongs.pipeline.chunks.run_chunked`), else in one piece
    (:func:`fusiongs.pipeline.deblur.run_deblur`); ``kw`` are their common arguments. Returns the
    metrics."""
    if longer_than_a_chunk(scene, kw.get("config"), kw.get("overrides", ())):
        from fusiongs.pipeline.chunks import run_chunked

        return run_chunked(scene, out, jobs=1, executor="serial", **kw).get("metrics", {})
    from fusiongs.pipeline.deblur import run_deblur

    return run_deblur(scene, out, **kw)


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
                               None if holdout is None else str(holdout), resume))
    for row in run_all(tasks, f"{len(scenes)} recording(s) in {root}", jobs=jobs, executor=executor,
                       address=address, log=log, deblur=deblur_recording):
        rows[row["name"]] = row
    ordered = [rows[s.name] for s in scenes]
    write_text(out / SUMMARY_FILE, json.dumps({"root": str(root), "recordings": ordered}, indent=2) + "\n")
    log(format_summary(ordered))
    raise_failed(ordered, "recording", out)
    return ordered
