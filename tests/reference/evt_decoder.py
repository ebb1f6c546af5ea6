"""Reference EVT 2.0 / 3.0 decoders in numpy, written from Prophesee's format description.

fusiongs read ``.raw`` files with these before it used ``faery``; they stay as an independent
reference: the tests compare the reader with them event by event, and ``benchmarks/bench_data.py``
measures both (decode time, peak memory). Not used at run time: they hold the whole word stream and
several word-sized temporaries in memory.

Formats as published by Prophesee (docs.prophesee.ai, "EVT 2.0 Format" / "EVT 3.0 Format"); all
words little-endian, the word type in the 4 most significant bits.

EVT 2.0, 32-bit words: CD_OFF 0x0 / CD_ON 0x1 carry ``ts[27:22]`` (6 time LSBs), ``x[21:11]``,
``y[10:0]``; EV_TIME_HIGH 0x8 carries the 28 time MSBs in ``[27:0]``, so ``t = high << 6 | lsb``;
EXT_TRIGGER 0xA, OTHERS 0xE and CONTINUED 0xF carry no CD events.

EVT 3.0, 16-bit words (decoding keeps a state): EVT_ADDR_Y 0x0 sets ``y = w[10:0]``; EVT_ADDR_X
0x2 emits one event at ``x = w[10:0]`` with polarity ``w[11]``; VECT_BASE_X 0x3 sets a base ``x``
and polarity; VECT_12 0x4 / VECT_8 0x5 emit an event at ``base + i`` for every set bit ``i`` of
their 12/8 valid bits, then advance the base by 12/8; EVT_TIME_LOW 0x6 and EVT_TIME_HIGH 0x8 set
the low and high 12 bits of a 24-bit µs time that wraps (every 16.8 s; a decreasing high part
marks a wrap); EXT_TRIGGER 0xA, OTHERS 0xE, CONTINUED_4 0x7 and CONTINUED_12 0xF carry no CD events.
Events before the first EVT_TIME_HIGH (EVT 2.0) or before the first time and row words (EVT 3.0)
have no defined time/row and are skipped, as Prophesee's decoders do.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fusiongs.events.h5 import stream_from_file
from fusiongs.events.readers.prophesee import raw_version_and_size, read_prophesee_header
from fusiongs.events.stream import EventStream


def read_prophesee_raw_numpy(path: str | Path, width: int | None = None,
                             height: int | None = None) -> EventStream:
    """The former ``read_prophesee_raw``: the whole file in memory, decoded here, validated as
    :func:`~fusiongs.events.readers.prophesee.read_prophesee_raw` does (bad-input checks omitted)."""
    fields, offset = read_prophesee_header(path)
    version, hw, hh = raw_version_and_size(fields, path)
    data = np.fromfile(path, dtype=np.uint8, offset=offset)
    if version == "2.0":
        t, x, y, on = decode_evt2(data[: data.size // 4 * 4].view("<u4"))
    else:
        t, x, y, on = decode_evt3(data[: data.size // 2 * 2].view("<u2"))
    return stream_from_file(path, t, x, y, on, width or hw, height or hh, None, False, False)


def decode_evt2(words: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Decode EVT 2.0 words.

    Args:
        words: ``[N]`` uint32 words.

    Returns:
        ``(t, x, y, on)``: ``[E]`` int64 µs, int64 column, int64 row and bool ON.
    """
    kind = words >> 28
    is_high = kind == 0x8
    seen_high = np.cumsum(is_high) > 0
    hi_idx = np.where(is_high, np.arange(words.size), -1)
    np.maximum.accumulate(hi_idx, out=hi_idx)
    cd = ((kind == 0x0) | (kind == 0x1)) & seen_high
    w = words[cd].astype(np.int64)
    high = (words[hi_idx[cd]].astype(np.int64) & 0x0FFFFFFF)
    t = (high << 6) | ((w >> 22) & 0x3F)
    return t, (w >> 11) & 0x7FF, w & 0x7FF, (w >> 28) == 1


def _ffill_index(mask: np.ndarray) -> np.ndarray:
    """For every position, the index of the last position ``<=`` it where ``mask`` holds (-1: none)."""
    idx = np.where(mask, np.arange(mask.size), -1)
    np.maximum.accumulate(idx, out=idx)
    return idx


def decode_evt3(words: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Decode EVT 3.0 words (see the module docstring for the state machine).

    Args:
        words: ``[N]`` uint16 words.

    Returns:
        ``(t, x, y, on)``: ``[E]`` int64 µs, int64 column, int64 row and bool ON, in stream order.
    """
    w = words.astype(np.int64)
    kind = w >> 12
    n = w.size
    # time: high part with wrap-around count, low part; both held until replaced
    is_hi, is_lo = kind == 0x8, kind == 0x6
    hi_vals = w[is_hi] & 0xFFF
    wraps = np.concatenate([[0], np.cumsum(np.diff(hi_vals) < 0)]) if hi_vals.size else hi_vals
    hi_full = np.zeros(n, np.int64)
    hi_full[is_hi] = ((wraps << 12) + hi_vals) << 12
    hi_at = _ffill_index(is_hi)
    lo_at = _ffill_index(is_lo)
    y_at = _ffill_index(kind == 0x0)
    valid_state = (hi_at >= 0) & (lo_at >= 0) & (y_at >= 0)
    time = hi_full[np.maximum(hi_at, 0)] + (w[np.maximum(lo_at, 0)] & 0xFFF)
    row = w[np.maximum(y_at, 0)] & 0x7FF
    # single events
    single = (kind == 0x2) & valid_state
    # vector events: base x and polarity from the last VECT_BASE_X, advanced by 12/8 per vector word
    is_base = kind == 0x3
    step = np.where(kind == 0x4, 12, np.where(kind == 0x5, 8, 0))
    cum = np.cumsum(step) - step  # steps of vector words strictly before each position
    base_at = _ffill_index(is_base)
    vec = ((kind == 0x4) | (kind == 0x5)) & valid_state & (base_at >= 0)
    vi = np.flatnonzero(vec)
    vbase = w[base_at[vi]]
    vx0 = (vbase & 0x7FF) + cum[vi] - cum[base_at[vi]]
    nbits = np.where(kind[vi] == 0x4, 12, 8)
    bits = (w[vi, None] >> np.arange(12)) & 1
    bits[nbits == 8, 8:] = 0
    # place events in stream order: per-word counts, then scatter
    si = np.flatnonzero(single)
    counts = np.zeros(n, np.int64)
    counts[si] = 1
    counts[vi] = bits.sum(axis=1)
    start = np.cumsum(counts) - counts
    total = int(counts.sum())
    t = np.empty(total, np.int64)
    x = np.empty(total, np.int64)
    y = np.empty(total, np.int64)
    on = np.empty(total, bool)
    pos = start[si]
    t[pos], y[pos], x[pos], on[pos] = time[si], row[si], w[si] & 0x7FF, ((w[si] >> 11) & 1) == 1
    r, c = np.nonzero(bits)
    rank = np.cumsum(bits, axis=1)[r, c] - 1
    pos = start[vi[r]] + rank
    t[pos], y[pos] = time[vi[r]], row[vi[r]]
    x[pos] = vx0[r] + c
    on[pos] = ((vbase[r] >> 11) & 1) == 1
    return t, x, y, on
