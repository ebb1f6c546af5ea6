"""Atomic file writes: write beside the target, then ``os.replace`` (nothing half-written is left).

A process killed while writing (``kill -9``) leaves the target as it was and, beside it, its
temporary: a hidden file named ``.<stem>.<8 random characters>.tmp<suffix>``
(:func:`is_temporary`), which :func:`remove_temporaries` clears away.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path

# mkstemp's names: prefix + 8 characters of [a-z0-9_] + suffix
_TEMPORARY = re.compile(r"\..+\.[a-z0-9_]{8}\.tmp(\.[^.]*)?")


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; on success it replaces ``path`` atomically.

    The temporary file keeps the target's suffix so that writers choosing a format by extension
    (OpenCV, h5py) behave as for the target. On error the temporary file is removed and the
    target is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def is_temporary(path: str | Path) -> bool:
    """Whether ``path`` is named like a temporary of :func:`atomic_path`
    (``.<stem>.XXXXXXXX.tmp<suffix>``)."""
    return _TEMPORARY.fullmatch(Path(path).name) is not None


def remove_temporaries(folder: str | Path, depth: int = 1) -> list[Path]:
    """Delete the temporaries that interrupted :func:`atomic_path` writes left in ``folder`` and in
    its subfolders down to ``depth`` levels (a run killed while writing its outputs).

    Only files named as :func:`is_temporary` says are touched; call it only when no other process
    writes into ``folder``. Returns the removed paths.
    """
    folder = Path(folder)
    removed = []
    if not folder.is_dir():
        return removed
    for entry in sorted(folder.iterdir()):
        if entry.is_dir() and not entry.is_symlink():
            if depth > 0:
                removed += remove_temporaries(entry, depth - 1)
        elif is_temporary(entry) and entry.is_file():
            entry.unlink(missing_ok=True)
            removed.append(entry)
    return removed


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def json_ready(obj):
    """``obj`` with every non-finite float (NaN, inf; numpy's too) replaced by ``None``, through
    dicts, lists and tuples: ``json.dumps`` would write ``NaN`` / ``Infinity``, which strict JSON
    readers (a browser's ``JSON.parse``, ``jq``) refuse."""
    if isinstance(obj, dict):
        return {k: json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
