"""Checkpoints: one ``torch.save`` file written atomically, read back with named errors."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from fusiongs.atomic import atomic_path
from fusiongs.errors import InputError

FORMAT = "fusiongs-checkpoint"
VERSION = 1
REQUIRED = ("format", "version", "iteration", "config", "camera", "model", "trajectory", "threshold")


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> None:
    """Write ``payload`` (tensors, dicts, numbers) to ``path`` atomically, tagged with the format."""
    data = {"format": FORMAT, "version": VERSION, **payload}
    with atomic_path(path) as tmp:
        torch.save(data, tmp)


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by :func:`save_checkpoint`.

    Raises:
        InputError: when the file is missing, unreadable, of another format, or lacks a key.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "checkpoint", "an existing checkpoint.pt file", "no such file")
    try:
        data = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # torch raises many types for truncated or foreign files
        raise InputError(path, "checkpoint", "a fusiongs checkpoint (torch.save file)",
                         f"unreadable ({type(e).__name__})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        found = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise InputError(path, "format", f"'{FORMAT}'", repr(found))
    if data.get("version") != VERSION:
        raise InputError(path, "version", str(VERSION), repr(data.get("version")))
    for key in REQUIRED:
        if key not in data:
            raise InputError(path, key, "present in the checkpoint", "missing")
    return data
