"""Prophesee ``.raw`` recordings (EVT 2.0 and EVT 3.0), decoded by the maintained ``faery`` package.

``faery`` (Rust) streams the file in packets of a few thousand events; each packet is copied into
the output columns as it comes (:func:`~fusiongs.events.readers.chunks.columns_from_chunks`), so
the memory beyond the returned stream is one packet. fusiongs parses the ``%`` header itself (size,
version, clear errors) and checks the word stream's length.

Formats as published by Prophesee (docs.prophesee.ai, "EVT 2.0 Format" / "EVT 3.0 Format"); all
words little-endian, the word type in the 4 most significant bits. EVT 2.0: 32-bit words, CD_OFF
0x0 / CD_ON 0x1 one event each, EV_TIME_HIGH 0x8 the 28 time MSBs. EVT 3.0: 16-bit words with a
decoder state: EVT_ADDR_Y 0x0 (row), EVT_ADDR_X 0x2 (one event), VECT_BASE_X 0x3, VECT_12 0x4 /
VECT_8 0x5 (one event per set bit), EVT_TIME_LOW 0x6 / EVT_TIME_HIGH 0x8 (a 24-bit µs time that
wraps every 16.8 s; ``faery`` unwraps it).
Events before the first EVT_TIME_HIGH (EVT 2.0) or before the first time-high, time-low and row
words (EVT 3.0) have no defined time/row: ``faery`` emits them at time 0 / row 0, fusiongs skips
them, as Prophesee's decoders do (:func:`undefined_prefix_events`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fusiongs.errors import InputError, MissingDependencyError
from fusiongs.events.h5 import stream_from_file
from fusiongs.events.readers.chunks import columns_from_chunks
from fusiongs.events.stream import EventStream


def read_prophesee_header(path: str | Path) -> tuple[dict[str, str], int]:
    """Parse the ``%`` header lines of a ``.raw`` file.

    Returns:
        ``(fields, n_bytes)``: header keys to values (``{"evt": "3.0", "geometry": "1280x720"}``),
        and the byte offset where the event words begin.
    """
    fields: dict[str, str] = {}
    with open(path, "rb") as fh:
        pos = 0
        while True:
            line = fh.readline()
            if not line.startswith(b"%"):
                break
            pos += len(line)
            text = line[1:].decode("ascii", "replace").strip()
            if text == "end":
                break
            key, _, value = text.partition(" ")
            fields[key.strip()] = value.strip()
    return fields, pos


def raw_version_and_size(fields: dict[str, str], path) -> tuple[str, int | None, int | None]:
    """``("2.0" | "3.0" | other, width, height)`` from parsed header fields (sizes may be None)."""
    width = height = None
    fmt = fields.get("format", "")
    parts = [s.strip() for s in fmt.split(";")]
    for s in parts[1:]:
        k, _, v = s.partition("=")
        if k == "width" and v.isdigit():
            width = int(v)
        elif k == "height" and v.isdigit():
            height = int(v)
    geom = fields.get("geometry", "")
    if "x" in geom and width is None:
        w, _, h = geom.partition("x")
        if w.strip().isdigit() and h.strip().isdigit():
            width, height = int(w), int(h)
    names = {"EVT2": "2.0", "EVT3": "3.0", "EVT21": "2.1"}
    version = names.get(parts[0].upper(), fields.get("evt", ""))
    if not version:
        raise InputError(path, "header", "a '% evt 2.0|3.0' or '% format EVT2|EVT3' header line",
                         f"keys {sorted(fields)}")
    return version, width, height


WORD_BYTES = {"2.0": 4, "3.0": 2}
MAX_COORD = 2048  # EVT 2.0 / 3.0 addresses are 11 bits
_SCAN_WORDS = 1 << 16


def undefined_prefix_events(path: str | Path, offset: int, version: str) -> int:
    """Count the events encoded before the decoder state is defined.

    That is before the first EV_TIME_HIGH word (EVT 2.0), or before the first EVT_TIME_HIGH,
    EVT_TIME_LOW and EVT_ADDR_Y words have all been seen (EVT 3.0; a vector word counts its set
    valid bits). Reads the file in blocks of ``_SCAN_WORDS`` words until the state is defined
    (usually the first word).

    Args:
        path: the ``.raw`` file; ``offset``: byte offset of the first word; ``version``: ``"2.0"``
            or ``"3.0"``.

    Returns:
        The number of leading events a stateless decoder emits with undefined time or row.
    """
    dtype = "<u4" if version == "2.0" else "<u2"
    shift = 28 if version == "2.0" else 12
    needed = {0x8} if version == "2.0" else {0x8, 0x6, 0x0}
    count = 0
    with open(path, "rb") as fh:
        fh.seek(offset)
        while needed:
            words = np.fromfile(fh, dtype=dtype, count=_SCAN_WORDS)
            if words.size == 0:
                break
            kind = words >> shift
            firsts = {k: np.flatnonzero(kind == k) for k in needed}
            end = words.size if any(f.size == 0 for f in firsts.values()) else \
                max(int(f[0]) for f in firsts.values())
            needed = {k for k, f in firsts.items() if f.size == 0}
            count += _events_in(words[:end], kind[:end], version)
    return count


def _events_in(words: np.ndarray, kind: np.ndarray, version: str) -> int:
    """Number of CD events the words encode (EVT 3.0 vectors: their set valid bits)."""
    if version == "2.0":
        return int(np.count_nonzero(kind <= 0x1))
    n = int(np.count_nonzero(kind == 0x2))
    for k, nbits in ((0x4, 12), (0x5, 8)):
        bits = (words[kind == k, None].astype(np.int64) >> np.arange(nbits)) & 1
        n += int(bits.sum())
    return n


def _faery_chunks(path: Path, version: str, header_size: tuple[int, int] | None):
    """Event packets of ``path`` from faery's EVT decoder; its errors become :class:`InputError`.

    ``header_size``: ``(width, height)`` of the header, which faery checks every address against;
    ``None`` when the header has none (faery then checks the 11-bit range only, and fusiongs the
    user's size in :meth:`EventStream.create`, honouring ``drop_invalid``).
    """
    try:
        from faery.extension import evt
    except ImportError:
        raise MissingDependencyError("faery", "reading Prophesee .raw files") from None
    fallback = header_size or (MAX_COORD, MAX_COORD)
    try:
        with evt.Decoder(str(path), fallback, "evt2" if version == "2.0" else "evt3") as decoder:
            for packet in decoder:
                if "events" in packet:
                    yield packet["events"]
    except RuntimeError as e:  # the Rust decoder raises plain RuntimeError on bad input
        msg = str(e)
        if "overflow" in msg and header_size is not None:
            w, h = header_size
            raise InputError(path, "x/y", f"coordinates inside the {w}x{h} sensor of the header",
                             msg) from None
        raise InputError(path, "data", f"a valid EVT {version} word stream", msg) from None


def read_prophesee_raw(path: str | Path, width: int | None = None, height: int | None = None,
                       cfa: str | None = None, *, sort: bool = False,
                       drop_invalid: bool = False) -> EventStream:
    """Read a Prophesee EVT 2.0 / EVT 3.0 ``.raw`` file.

    Args:
        path: the ``.raw`` file.
        width, height: sensor size; default from the header (``% geometry WxH`` or
            ``% format EVT3;width=W;height=H``); required when the header has none.
        cfa, sort, drop_invalid: see :meth:`EventStream.create`.

    Returns:
        The stream; ``t`` in µs on the camera clock.

    Raises:
        InputError: unknown/unsupported format, truncated word stream, no size, zero events.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing Prophesee .raw file", "no such file")
    fields, offset = read_prophesee_header(path)
    version, hw, hh = raw_version_and_size(fields, path)
    width = width if width is not None else hw
    height = height if height is not None else hh
    if width is None or height is None:
        raise InputError(path, "geometry", "the sensor size in the header or --width/--height",
                         "no '% geometry' header line")
    size = WORD_BYTES.get(version)
    if size is None:
        raise InputError(path, "evt", "EVT 2.0 or EVT 3.0 (EVT 2.1 is not supported)", version)
    n_bytes = path.stat().st_size - offset
    if n_bytes % size:
        raise InputError(path, "data", f"a whole number of {size}-byte EVT {version} words "
                         "(truncated file?)", f"{n_bytes} bytes")
    skip = undefined_prefix_events(path, offset, version)
    # every EVT 2.0 CD word is one event: the word count bounds the output; EVT 3.0 usually spends
    # more than one word per event (columns grow when vector words pack more)
    chunks = _faery_chunks(path, version, (hw, hh) if hw is not None and hh is not None else None)
    t, x, y, p = columns_from_chunks(chunks, capacity=n_bytes // size, skip=skip)
    return stream_from_file(path, t, x, y, p, width, height, cfa, sort, drop_invalid)
