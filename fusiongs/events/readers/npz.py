"""EventNeRF event files: one ``.npz`` with arrays ``x, y, t, p`` (Rudnev et al., CVPR 2023).

EventNeRF's loader reads ``events/*.npz`` with exactly these keys, sums ``p`` directly (so ±1)
and uses only relative times; its recordings are 346x260 (Color-DAVIS346, RGGB).
"""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from fusiongs.errors import InputError
from fusiongs.events.h5 import require_events, stream_from_file
from fusiongs.events.readers.units import to_us
from fusiongs.events.stream import EventStream

NPZ_KEYS = ("x", "y", "t", "p")


def read_eventnerf_npz(path: str | Path, width: int | None, height: int | None,
                       cfa: str | None = None, *, time_unit: str | None = None, sort: bool = False,
                       drop_invalid: bool = False) -> EventStream:
    """Read an EventNeRF ``.npz`` event file.

    Args:
        width, height: sensor size (EventNeRF's recordings are 346x260; the file stores none).
        time_unit: unit of ``t`` (``"s"``, ``"ms"``, ``"us"``, ``"ns"``); ``None`` to detect.
        cfa, sort, drop_invalid: see :meth:`EventStream.create`.

    Raises:
        InputError: unreadable archive, missing keys, no size, zero events, or any check of
            :meth:`EventStream.create`.
    """
    path = Path(path)
    if width is None or height is None:
        raise InputError(path, "width/height", "the sensor size (--width/--height; EventNeRF "
                         "recordings are 346x260)", "not given")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in NPZ_KEYS if k not in z.files]
            if missing:
                raise InputError(path, missing[0], "arrays x, y, t, p", f"keys {sorted(z.files)}")
            x, y, t, p = (z[k] for k in NPZ_KEYS)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(path, "file", "a readable .npz archive (truncated or corrupt?)", str(e)) from None
    require_events(np.asarray(t).size, path)
    return stream_from_file(path, to_us(t, time_unit, str(path)), x, y, p, width, height, cfa,
                            sort, drop_invalid)
