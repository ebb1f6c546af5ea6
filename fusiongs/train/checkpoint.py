"""Checkpoints: one ``torch.save`` file written atomically, read back with named errors.

A checkpoint holds tensors and plain data only (dicts, lists, tuples, strings, numbers, booleans,
``None``): :func:`save_checkpoint` turns numpy arrays and scalars into tensors and Python numbers
and refuses anything else, and :func:`load_checkpoint` reads with ``torch.load(weights_only=True)``,
so a crafted ``checkpoint.pt`` cannot run code (a plain ``pickle`` load would run whatever its
``__reduce__`` names).
"""

from __future__ import annotations

import contextlib
import pickle
import re
import warnings
from collections import OrderedDict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fusiongs.atomic import atomic_path
from fusiongs.errors import FusionGSError, InputError

FORMAT = "fusiongs-checkpoint"
VERSION = 1
REQUIRED = ("format", "version", "iteration", "config", "camera", "model", "trajectory", "threshold")

_SCALARS = (str, int, float, bool, type(None))


def plain_data(obj: Any, where: str = "payload") -> Any:
    """A copy of ``obj`` made of tensors and plain data only, as ``weights_only`` loading accepts.

    numpy arrays become tensors (same dtype), numpy scalars Python numbers; dicts (``OrderedDict``
    kept, with a ``state_dict``'s ``_metadata``), lists and tuples are copied recursively.

    Raises:
        TypeError: naming the key path of any other object (a programming error: it would not
            load back).
    """
    if isinstance(obj, torch.Tensor):
        return obj.detach()
    if type(obj) in _SCALARS:  # not subclasses (enums): they pickle as their class
        return obj
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biuf":
            raise TypeError(f"{where}: numpy array of dtype {obj.dtype} cannot go into a checkpoint")
        return torch.from_numpy(np.array(obj))
    if isinstance(obj, np.generic) and obj.dtype.kind in "biuf":
        return obj.item()
    if isinstance(obj, dict):
        out = OrderedDict() if isinstance(obj, OrderedDict) else {}  # other subclasses: dict
        for k, v in obj.items():
            if not isinstance(k, str | int):
                raise TypeError(f"{where}: dict key {k!r} is not a string or an integer")
            out[k] = plain_data(v, f"{where}/{k}")
        if hasattr(obj, "_metadata"):
            out._metadata = plain_data(obj._metadata, f"{where}/_metadata")
        return out
    if type(obj) in (list, tuple):
        items = [plain_data(v, f"{where}[{i}]") for i, v in enumerate(obj)]
        return items if isinstance(obj, list) else tuple(items)
    raise TypeError(f"{where}: {type(obj).__qualname__} cannot go into a checkpoint "
                    "(tensors and plain data only)")


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> None:
    """Write ``payload`` (tensors, numpy arrays, dicts, lists, numbers, strings) to ``path``
    atomically, tagged with the format; numpy data is stored as tensors (see :func:`plain_data`)."""
    data = plain_data({"format": FORMAT, "version": VERSION, **payload})
    with atomic_path(path) as tmp:
        torch.save(data, tmp)


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by :func:`save_checkpoint`, tensors on the CPU.

    Only tensors and plain data are unpickled (``weights_only=True``); pose samples come back as
    float64 tensors.

    Raises:
        InputError: when the file is missing, unreadable (truncated, not a ``torch.save`` file),
            holds objects other than tensors and plain data (refused unread), is of another
            format, or lacks a key.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "checkpoint", "an existing checkpoint.pt file", "no such file")
    try:
        with warnings.catch_warnings():  # e.g. "pickle protocol 4": the error below says it all
            warnings.simplefilter("ignore")
            data = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:  # what the weights-only unpickler raises on a global
        raise InputError(path, "checkpoint", "tensors and plain data only (a fusiongs checkpoint)",
                         _refused(e)) from None
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


@contextlib.contextmanager
def checkpoint_errors(path: str | Path) -> Iterator[None]:
    """Turn what a readable but incomplete or foreign checkpoint makes the restoring code raise
    (a missing key, a tensor of another shape, a value of the wrong type) into one
    :class:`InputError` line naming the file."""
    try:
        yield
    except FusionGSError:  # already one line
        raise
    except (KeyError, RuntimeError, TypeError, ValueError, AttributeError) as e:
        raise InputError(path, "checkpoint", "a complete fusiongs checkpoint of this run",
                         f"{type(e).__name__}: {str(e).splitlines()[0][:120] if str(e) else ''}") from None


def _refused(e: Exception) -> str:
    """One line for an unpickling error: the refused global when torch names it."""
    m = re.search(r"Unsupported global: GLOBAL ([\w.]+)", str(e))
    if m:
        return f"a pickled {m.group(1)}, refused unread (crafted, or not a fusiongs checkpoint)"
    if "weights only load failed" in str(e).lower():
        return "pickled objects other than tensors and plain data, refused unread"
    return "unreadable (UnpicklingError)"
