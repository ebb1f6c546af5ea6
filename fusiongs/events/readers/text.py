"""rpg-style event text files: one event per line ``t x y p`` (t in seconds by default, p 1/0
or ±1), optional first line ``width height`` (the Event Camera Dataset of Mueggler et al. 2017).

The parser is a small numba kernel over the raw bytes (``np.loadtxt`` is ~20x slower); timestamps
are parsed as exact decimals straight to integer µs. :func:`parse_events_text_reference` is the
slow, obviously-correct specification the tests compare it with.
"""

from __future__ import annotations

from decimal import Decimal, InvalidOperation
from pathlib import Path

import numba
import numpy as np

from fusiongs.atomic import write_bytes
from fusiongs.errors import InputError
from fusiongs.events.h5 import stream_from_file
from fusiongs.events.stream import EventStream

_SHIFT = {"s": 6, "ms": 3, "us": 0, "ns": -3}  # decimal exponent from the file unit to µs
_BAD_LINE, _NEG_TIME = 1, 2
_POW10 = np.array([10 ** k for k in range(19)], np.int64)
_MAX_MANT = np.array([(2 ** 62) // 10 ** k for k in range(19)], np.int64)


@numba.njit(cache=True, nogil=True)
def _skip_blank(buf, i, n):
    while i < n and (buf[i] == 32 or buf[i] == 9):
        i += 1
    return i


@numba.njit(cache=True, nogil=True)
def _parse_int(buf, i, n):
    """Parse ``[+-]digits`` at ``i``; returns (value, next index, ok)."""
    sign = 1
    if i < n and (buf[i] == 45 or buf[i] == 43):
        sign = -1 if buf[i] == 45 else 1
        i += 1
    v = 0
    j = i
    while j < n and 48 <= buf[j] <= 57 and j - i < 18:
        v = v * 10 + (buf[j] - 48)
        j += 1
    return sign * v, j, j > i


@numba.njit(cache=True, nogil=True)
def _parse_time(buf, i, n, shift):
    """Parse a non-negative decimal (optional fraction and exponent) as integer µs."""
    if i < n and buf[i] == 45:
        return 0, i, _NEG_TIME
    if i < n and buf[i] == 43:
        i += 1
    mant, exp10, digits, big = 0, 0, 0, 10 ** 17
    while i < n and 48 <= buf[i] <= 57:
        if mant < big:
            mant = mant * 10 + (buf[i] - 48)
        else:
            exp10 += 1
        i += 1
        digits += 1
    if i < n and buf[i] == 46:
        i += 1
        while i < n and 48 <= buf[i] <= 57:
            if mant < big:
                mant = mant * 10 + (buf[i] - 48)
                exp10 -= 1
            i += 1
            digits += 1
    if digits == 0:
        return 0, i, _BAD_LINE
    if i < n and (buf[i] == 101 or buf[i] == 69):
        e, i, ok = _parse_int(buf, i + 1, n)
        if not ok:
            return 0, i, _BAD_LINE
        exp10 += e
    s = exp10 + shift
    if s == 0:
        return mant, i, 0
    if s > 0:
        if s > 18 or mant > _MAX_MANT[s]:
            return 0, i, _BAD_LINE
        return mant * _POW10[s], i, 0
    if -s > 18:
        return 0, i, 0
    div = _POW10[-s]
    return (mant + div // 2) // div, i, 0


@numba.njit(cache=True, nogil=True)
def _parse_lines(buf, start, first_line, shift, n_max):
    n = buf.size
    t = np.empty(n_max, np.int64)
    xyp = np.empty((3, n_max), np.int64)
    k, i, line = 0, start, first_line
    while i < n:
        i = _skip_blank(buf, i, n)
        if i >= n:
            break
        c = buf[i]
        if c == 10 or c == 13 or c == 35:  # blank line, or a '#' comment
            while i < n and buf[i] != 10:
                i += 1
            i += 1
            line += 1
            continue
        tv, i, err = _parse_time(buf, i, n, shift)
        if err != 0:
            return t[:k], xyp[:, :k], line, err
        for f in range(3):
            j = _skip_blank(buf, i, n)
            if j == i:
                return t[:k], xyp[:, :k], line, _BAD_LINE
            v, i, ok = _parse_int(buf, j, n)
            if not ok:
                return t[:k], xyp[:, :k], line, _BAD_LINE
            xyp[f, k] = v
        i = _skip_blank(buf, i, n)
        if i < n and buf[i] == 13:
            i += 1
        if i < n and buf[i] != 10:
            return t[:k], xyp[:, :k], line, _BAD_LINE
        t[k] = tv
        k += 1
        i += 1
        line += 1
    return t[:k], xyp[:, :k], line, 0


def _header_size(buf: np.ndarray) -> tuple[tuple[int, int] | None, int]:
    """``((width, height) or None, byte offset of the first event line)``."""
    nl = np.flatnonzero(buf[:4096] == 10)
    end = int(nl[0]) if nl.size else min(buf.size, 4096)
    first = bytes(buf[:end]).decode("ascii", "replace").split()
    if len(first) == 2 and all(s.isdigit() for s in first):
        return (int(first[0]), int(first[1])), min(end + 1, buf.size)
    return None, 0


def read_events_txt(path: str | Path, width: int | None = None, height: int | None = None,
                    cfa: str | None = None, *, time_unit: str = "s", sort: bool = False,
                    drop_invalid: bool = False) -> EventStream:
    """Read an rpg-style event text file.

    Args:
        path: text file with lines ``t x y p``; ``#`` comments and blank lines are skipped.
        width, height: sensor size; default from a first line ``width height``.
        time_unit: unit of ``t`` in the file (``"s"`` for rpg files; ``"ms"``, ``"us"``, ``"ns"``).
        cfa, sort, drop_invalid: see :meth:`EventStream.create`.

    Raises:
        InputError: naming the line of a malformed entry or negative time; no size; zero events.
    """
    path = Path(path)
    if time_unit not in _SHIFT:
        raise InputError(path, "time_unit", f"one of {', '.join(_SHIFT)}", repr(time_unit))
    try:
        buf = np.fromfile(path, dtype=np.uint8)
    except OSError as e:
        raise InputError(path, "file", "a readable text file", e.strerror) from None
    size, start = _header_size(buf)
    if width is None or height is None:
        if size is None:
            raise InputError(path, "line 1", "a first line 'width height' or --width/--height",
                             "no sensor size")
        width, height = width or size[0], height or size[1]
    n_max = int(np.count_nonzero(buf[start:] == 10)) + 1
    t, xyp, line, err = _parse_lines(buf, start, 2 if start else 1, _SHIFT[time_unit], n_max)
    if err:
        text = _line_text(buf, line - (2 if start else 1), start)
        what = "a non-negative time" if err == _NEG_TIME else "4 numbers 't x y p'"
        raise InputError(path, f"line {line}", what, repr(text))
    return stream_from_file(path, t, xyp[0], xyp[1], xyp[2], width, height, cfa, sort, drop_invalid)


def _line_text(buf: np.ndarray, index: int, start: int) -> str:
    lines = bytes(buf[start:start + (1 << 20)]).split(b"\n") if index < 10000 else []
    return lines[index].decode("ascii", "replace")[:80] if index < len(lines) else "?"


def parse_events_text_reference(text: str, time_unit: str = "s") -> np.ndarray:
    """Slow reference parser: ``[E, 4]`` int64 rows ``(t_us, x, y, p)`` (no header handling)."""
    rows = []
    for line in text.splitlines():
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        try:
            t = Decimal(parts[0]).scaleb(_SHIFT[time_unit])
            t_us = int(t.to_integral_value(rounding="ROUND_HALF_UP"))
            rows.append((t_us, int(parts[1]), int(parts[2]), int(parts[3])))
        except (InvalidOperation, ValueError, IndexError):
            raise ValueError(f"bad line {line!r}") from None
    return np.asarray(rows, dtype=np.int64).reshape(-1, 4)


@numba.njit(cache=True, nogil=True)
def _format_lines(t, x, y, p):
    out = np.empty(t.size * 48, np.uint8)
    k = 0
    tmp = np.empty(24, np.uint8)
    for i in range(t.size):
        sec, frac = t[i] // 1000000, t[i] % 1000000
        for f in range(4):
            v = sec if f == 0 else (x[i] if f == 1 else (y[i] if f == 2 else (1 if p[i] > 0 else 0)))
            m = 0
            while True:
                tmp[m] = 48 + v % 10
                v //= 10
                m += 1
                if v == 0:
                    break
            for j in range(m - 1, -1, -1):
                out[k] = tmp[j]
                k += 1
            if f == 0:
                out[k] = 46
                k += 1
                for j in range(5, -1, -1):
                    out[k + j] = 48 + frac % 10
                    frac //= 10
                k += 6
            out[k] = 32 if f < 3 else 10
            k += 1
    return out[:k]


def write_events_txt(stream: EventStream, path: str | Path, *, header: bool = True) -> None:
    """Write ``stream`` as rpg text (``t`` in seconds with 6 decimals, ``p`` as 1/0), atomically.

    Args:
        header: write the first line ``width height``.
    """
    path = Path(path)
    body = _format_lines(np.asarray(stream.t, np.int64), np.asarray(stream.x, np.int64),
                         np.asarray(stream.y, np.int64), np.asarray(stream.p, np.int64))
    head = f"{stream.width} {stream.height}\n".encode() if header else b""
    write_bytes(path, head + body.tobytes())
