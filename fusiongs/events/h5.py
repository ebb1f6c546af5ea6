"""Native ``events.h5`` read/write (docs/scene-format.md) and the HDF5 helpers other readers share.

Native layout: group ``events`` with 1-D datasets ``t`` (int64 µs), ``x``/``y`` (uint16) and ``p``
(int8 ±1 or uint8 1/0), optional ``events.attrs["t_offset_us"]`` added to every ``t``. DSEC files
(``events/{x,y,t,p}`` plus a root dataset ``t_offset`` and an index ``ms_to_idx``) read the same way,
also when compressed with Blosc/Zstd (their filters come from ``hdf5plugin``, imported on opening).
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np

from fusiongs.atomic import atomic_path
from fusiongs.errors import InputError
from fusiongs.events.stream import EventStream

NATIVE_FIELDS = ("t", "x", "y", "p")


def register_filters() -> None:
    """Register the compression filters of ``hdf5plugin`` (Blosc, Zstd, LZ4, bitshuffle, ...) with
    h5py, as DSEC files need; without the package only h5py's own filters are readable."""
    try:
        import hdf5plugin  # noqa: F401  (importing it registers the filters)
    except ImportError:
        pass  # read_dataset names a missing filter and the package to install


@contextmanager
def open_h5(path: str | Path):
    """Open an HDF5 file read-only, with the ``hdf5plugin`` filters registered (Blosc/Zstd
    compressed DSEC files); a missing, truncated or non-HDF5 file is an :class:`InputError`."""
    import h5py

    register_filters()
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing HDF5 file", "no such file")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise InputError(path, "file", "a readable HDF5 file (truncated or corrupt?)",
                         _h5_reason(e)) from None
    try:
        yield f
    finally:
        f.close()


def _h5_reason(e: OSError) -> str:
    """HDF5's open error in a few words (``truncated: 1000 of 30480 bytes``)."""
    import re

    msg = str(e)
    m = re.search(r"truncated file: eof = (\d+).*stored_eof = (\d+)", msg)
    if m:
        return f"truncated: {m.group(1)} of {m.group(2)} bytes"
    if "signature not found" in msg:
        return "not an HDF5 file (no HDF5 signature)"
    return msg


def read_dataset(f, key: str, path: str | Path) -> np.ndarray:
    """Read the whole dataset ``key`` of an open file into memory, naming failures."""
    import h5py

    obj = f.get(key)
    if not isinstance(obj, h5py.Dataset):
        raise InputError(path, key, "an HDF5 dataset", "missing" if obj is None else "a group")
    try:
        return obj[...]
    except (OSError, ValueError, RuntimeError) as e:
        hint = " (compressed with a filter h5py lacks? try `pip install hdf5plugin`)" \
            if "filter" in str(e).lower() or "plugin" in str(e).lower() else ""
        raise InputError(path, key, "a readable dataset" + hint, str(e)) from None


def require_events(n: int, path: str | Path) -> None:
    """Readers of a file with zero events raise (an empty stream is no scene)."""
    if n == 0:
        raise InputError(path, "events", "at least one event", "0 events")


def stream_from_file(path, t, x, y, p, width, height, cfa, sort: bool, drop_invalid: bool) -> EventStream:
    """:meth:`EventStream.create` for data read from ``path``; a file must yield at least one
    event, also after ``drop_invalid`` removed events outside the sensor."""
    require_events(np.asarray(t).shape[0] if np.ndim(t) else 0, path)
    s = EventStream.create(t, x, y, p, width, height, cfa, source=str(path), sort=sort,
                           drop_invalid=drop_invalid)
    if len(s) == 0:
        raise InputError(path, "events", "at least one event inside the sensor", "all were dropped")
    return s


def read_events_h5(path: str | Path, width: int | None = None, height: int | None = None,
                   cfa: str | None = None, *, sort: bool = False,
                   drop_invalid: bool = False) -> EventStream:
    """Read a native (or DSEC-style) ``events.h5``.

    Args:
        path: the HDF5 file.
        width, height: sensor size; ``None`` falls back to the ``width``/``height`` attributes that
            :func:`write_events_h5` stores on the ``events`` group.
        cfa: colour filter layout of the event sensor, or ``None``.
        sort, drop_invalid: see :meth:`EventStream.create`.

    Returns:
        The validated stream with ``t`` in µs including ``t_offset_us`` / DSEC ``t_offset``.

    Raises:
        InputError: missing group/datasets, unreadable data, zero events, or any check of
            :meth:`EventStream.create`.
    """
    import h5py

    with open_h5(path) as f:
        g = f.get("events")
        if not isinstance(g, h5py.Group):
            raise InputError(path, "events", "an HDF5 group 'events' with datasets t, x, y, p",
                             f"top-level keys {sorted(f.keys())}")
        missing = [k for k in NATIVE_FIELDS if k not in g]
        if missing:
            raise InputError(path, "events/" + missing[0], "datasets events/t, events/x, events/y, "
                             "events/p", f"keys {sorted(g.keys())}")
        data = {k: read_dataset(g, k, path) for k in NATIVE_FIELDS}
        offset = _t_offset(f, g, path)
        width = width if width is not None else _int_attr(g, "width", path)
        height = height if height is not None else _int_attr(g, "height", path)
    t = data["t"]
    if offset:
        if t.dtype.kind == "f":
            t = t + float(offset)
        else:
            t = t.astype(np.int64) + np.int64(offset)
    return stream_from_file(path, t, data["x"], data["y"], data["p"], width, height, cfa, sort,
                            drop_invalid)


def time_range_h5(path: str | Path) -> tuple[int, int]:
    """First and last timestamp (µs, ``t_offset`` included) of an ``events.h5``, from its first and
    last entries alone (nothing else is read: cheap for any size; the stream is assumed sorted,
    as :func:`read_events_h5` checks on a full read).

    Raises:
        InputError: no ``events/t`` dataset, or zero events.
    """
    import h5py

    with open_h5(path) as f:
        t = f.get("events/t")
        if not isinstance(t, h5py.Dataset):
            raise InputError(path, "events/t", "an HDF5 dataset of timestamps", "missing")
        require_events(int(t.shape[0]) if t.shape else 0, path)
        first, last = t[0], t[-1]
        offset = _t_offset(f, f["events"], path)
    return int(first) + offset, int(last) + offset


def _t_offset(f, g, path) -> int:
    if "t_offset_us" in g.attrs:
        v = np.asarray(g.attrs["t_offset_us"])
        field = "events.attrs['t_offset_us']"
    elif "t_offset" in f:
        v = np.asarray(read_dataset(f, "t_offset", path))
        field = "t_offset"
    else:
        return 0
    if v.size != 1 or v.dtype.kind not in "iu":
        raise InputError(path, field, "one integer (µs)", f"{v.dtype} of shape {v.shape}")
    return int(v.reshape(()))


def _int_attr(g, name: str, path) -> int:
    if name not in g.attrs:
        raise InputError(path, name, "the sensor size: pass --width/--height (native events.h5 "
                         "stores no geometry; scene.json holds it)", "not given")
    return int(np.asarray(g.attrs[name]).reshape(()))


def write_events_h5(stream: EventStream, path: str | Path, *, compression: str | None = None) -> None:
    """Write ``stream`` as a native ``events.h5`` atomically (temporary file, then ``os.replace``).

    Args:
        stream: the events (``t`` in µs, stored without offset).
        path: destination file; its folder must exist.
        compression: ``None`` (contiguous, fastest to read) or ``"lzf"`` (chunked, smaller).
            ``benchmarks/bench_data.py`` measures both.
    """
    import h5py

    path = Path(path)
    kw = {} if compression is None else {"compression": compression, "chunks": (1 << 18,)}
    if compression is not None and len(stream) < (1 << 18):
        kw["chunks"] = True
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        g = f.create_group("events")
        g.create_dataset("t", data=np.asarray(stream.t, np.int64), **kw)
        g.create_dataset("x", data=np.asarray(stream.x, np.uint16), **kw)
        g.create_dataset("y", data=np.asarray(stream.y, np.uint16), **kw)
        g.create_dataset("p", data=np.asarray(stream.p, np.int8), **kw)
        g.attrs["width"] = np.int64(stream.width)
        g.attrs["height"] = np.int64(stream.height)
