"""Readers of event layouts into :class:`~fusiongs.events.stream.EventStream`, and a dispatcher.

| format        | files                                   | reader                      |
|---------------|-----------------------------------------|-----------------------------|
| native / dsec | ``.h5``: ``events/{t,x,y,p}``           | ``read_events_h5``          |
| event_utils   | ``.h5``: ``events/{xs,ys,ts,ps}``       | ``read_event_utils_h5``     |
| evdeblurnerf  | ``.h5``: root ``x, y, t, p``            | ``read_root_xytp_h5``       |
| txt           | ``.txt``: ``t x y p`` lines (rpg)       | ``read_events_txt``         |
| eventnerf     | ``.npz``: ``x, y, t, p``                | ``read_eventnerf_npz``      |
| aedat4        | ``.aedat4`` (events + APS frames)       | ``read_aedat4``             |
| evt2 / evt3   | ``.raw`` (Prophesee)                    | ``read_prophesee_raw``      |
"""

from __future__ import annotations

from pathlib import Path

from fusiongs.errors import InputError
from fusiongs.events.h5 import open_h5, read_events_h5
from fusiongs.events.readers.aedat4 import ApsFrames, read_aedat4
from fusiongs.events.readers.h5_layouts import read_event_utils_h5, read_root_xytp_h5
from fusiongs.events.readers.npz import read_eventnerf_npz
from fusiongs.events.readers.prophesee import read_prophesee_raw
from fusiongs.events.readers.text import read_events_txt, write_events_txt
from fusiongs.events.stream import EventStream

FORMATS = ("native", "dsec", "event_utils", "evdeblurnerf", "txt", "eventnerf", "aedat4", "evt2",
           "evt3")
_BY_SUFFIX = {".txt": "txt", ".npz": "eventnerf", ".aedat4": "aedat4", ".raw": "evt"}
_H5_SUFFIXES = (".h5", ".hdf5", ".hdf")

__all__ = ["FORMATS", "ApsFrames", "detect_format", "read_aedat4", "read_event_utils_h5",
           "read_eventnerf_npz", "read_events", "read_events_h5", "read_events_txt",
           "read_prophesee_raw", "read_root_xytp_h5", "write_events_txt"]


def detect_format(path: str | Path) -> str:
    """Name the layout of ``path`` from its extension and, for HDF5, its datasets.

    Raises:
        InputError: listing what was looked for when no layout matches.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing event file", "no such file")
    suffix = path.suffix.lower()
    if suffix in _BY_SUFFIX:
        return _BY_SUFFIX[suffix]
    if suffix not in _H5_SUFFIXES:
        raise InputError(path, "format", "a known extension (.h5/.hdf5, .txt, .npz, .aedat4, .raw) "
                         "or --format " + "|".join(FORMATS), repr(suffix or "none"))
    with open_h5(path) as f:
        g = f.get("events")
        keys = set(g.keys()) if g is not None and hasattr(g, "keys") else set()
        if {"t", "x", "y", "p"} <= keys:
            return "dsec" if "t_offset" in f or "ms_to_idx" in f else "native"
        if {"xs", "ys", "ts", "ps"} <= keys:
            return "event_utils"
        if {"x", "y", "t", "p"} <= set(f.keys()):
            return "evdeblurnerf"
        found = sorted(f.keys()) + sorted(f"events/{k}" for k in keys)
    raise InputError(path, "datasets", "one of: events/{t,x,y,p} (native/DSEC), events/{xs,ys,ts,ps} "
                     "(event_utils), root x,y,t,p (EvDeblurNeRF)", f"keys {found}")


def read_events(path: str | Path, *, format: str | None = None, width: int | None = None,
                height: int | None = None, cfa: str | None = None, sort: bool = False,
                drop_invalid: bool = False, time_unit: str | None = None) -> EventStream:
    """Read any supported event layout (see the table in this module's docstring).

    Args:
        path: the event file.
        format: one of ``FORMATS``; ``None`` detects it (:func:`detect_format`).
        width, height: sensor size where the file has none (or to override it).
        cfa: colour filter layout of the event sensor, or ``None`` (monochrome).
        sort, drop_invalid: see :meth:`EventStream.create`.
        time_unit: unit of ``t`` for layouts that do not fix it (EvDeblurNeRF, EventNeRF, text).

    Returns:
        The stream (AEDAT4 frames are dropped: use :func:`read_aedat4` to get them).
    """
    fmt = format or detect_format(path)
    common = {"sort": sort, "drop_invalid": drop_invalid}
    if fmt in ("native", "dsec"):
        return read_events_h5(path, width, height, cfa, **common)
    if fmt == "event_utils":
        return read_event_utils_h5(path, width, height, cfa, **common)
    if fmt == "evdeblurnerf":
        return read_root_xytp_h5(path, width, height, cfa, time_unit=time_unit, **common)
    if fmt == "txt":
        return read_events_txt(path, width, height, cfa, time_unit=time_unit or "s", **common)
    if fmt == "eventnerf":
        return read_eventnerf_npz(path, width, height, cfa, time_unit=time_unit, **common)
    if fmt == "aedat4":
        return read_aedat4(path, width, height, cfa, **common)[0]
    if fmt in ("evt", "evt2", "evt3"):
        return read_prophesee_raw(path, width, height, cfa, **common)
    raise InputError(path, "format", f"one of {', '.join(FORMATS)}", repr(fmt))
