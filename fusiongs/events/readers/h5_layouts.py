"""Third-party HDF5 event layouts: event_utils (``events/xs,ys,ts,ps``) and root-level ``x,y,t,p``
(EvDeblurNeRF). The native/DSEC layout is :func:`fusiongs.events.h5.read_events_h5`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fusiongs.errors import InputError
from fusiongs.events.h5 import open_h5, read_dataset, require_events, stream_from_file
from fusiongs.events.readers.units import to_us
from fusiongs.events.stream import EventStream

EVENT_UTILS_FIELDS = ("events/xs", "events/ys", "events/ts", "events/ps")
ROOT_FIELDS = ("x", "y", "t", "p")


def read_event_utils_h5(path: str | Path, width: int | None = None, height: int | None = None,
                        cfa: str | None = None, *, sort: bool = False,
                        drop_invalid: bool = False) -> EventStream:
    """Read an event_utils HDF5 file (Stoffregen et al.): ``events/xs, ys, ts (s), ps``.

    Args:
        width, height: sensor size; default from the root attribute ``sensor_resolution``,
            stored as ``[height, width]``.
        cfa, sort, drop_invalid: see :meth:`EventStream.create`.

    Raises:
        InputError: missing datasets or size, zero events, or any check of ``EventStream.create``.
    """
    with open_h5(path) as f:
        x, y, t, p = (read_dataset(f, k, path) for k in EVENT_UTILS_FIELDS)
        res = f.attrs.get("sensor_resolution")
    if width is None or height is None:
        res = None if res is None else np.asarray(res).ravel()
        if res is None or res.size < 2:
            raise InputError(path, "sensor_resolution", "a root attribute [height, width] or "
                             "--width/--height", "absent")
        height, width = (int(height or res[0]), int(width or res[1]))
    require_events(np.asarray(t).size, path)
    return stream_from_file(path, to_us(t, "s", str(path), "events/ts"), x, y, p, width, height,
                            cfa, sort, drop_invalid)


def read_root_xytp_h5(path: str | Path, width: int | None, height: int | None,
                      cfa: str | None = None, *, time_unit: str | None = None, sort: bool = False,
                      drop_invalid: bool = False) -> EventStream:
    """Read an HDF5 file with root-level datasets ``x, y, t, p`` (EvDeblurNeRF's ``events.h5``).

    EvDeblurNeRF stores integer timestamps "in us or ns" (its README; the unit is a training
    option), so ``time_unit`` is required unless :func:`~fusiongs.events.readers.units.
    detect_time_unit` finds the magnitude unambiguous.

    Args:
        width, height: sensor size (the file stores none).
        time_unit: ``"s"``, ``"ms"``, ``"us"`` or ``"ns"``; ``None`` to detect.
        cfa, sort, drop_invalid: see :meth:`EventStream.create`.
    """
    if width is None or height is None:
        raise InputError(path, "width/height", "the sensor size (--width/--height); this layout "
                         "stores none", "not given")
    with open_h5(path) as f:
        x, y, t, p = (read_dataset(f, k, path) for k in ROOT_FIELDS)
    require_events(np.asarray(t).size, path)
    return stream_from_file(path, to_us(t, time_unit, str(path)), x, y, p, width, height, cfa,
                            sort, drop_invalid)
