"""Event columns filled chunk by chunk from a decoder's packets (``faery``, ``aedat``).

The maintained decoders yield numpy structured arrays with fields ``t`` (µs), ``x``, ``y`` and
``on``, a few thousand events each. :func:`columns_from_chunks` copies each chunk straight into the
dtypes of :class:`~fusiongs.events.stream.EventStream` (int64 / uint16 / uint16 / int8 ±1), so the
memory beyond the output is one chunk, not a second copy of the recording.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

GROWTH = 1.5  # capacity factor when a chunk does not fit


def columns_from_chunks(chunks: Iterable[np.ndarray], capacity: int = 1 << 20,
                        skip: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate decoder chunks into the columns of an event stream.

    Args:
        chunks: structured arrays with fields ``t``, ``x``, ``y``, ``on`` (``[E_i]`` each).
        capacity: expected number of events. Arrays of this length are allocated up front (pages
            never written are never resident); a larger total grows them by ``GROWTH``, and they
            are trimmed to the total at the end. An upper bound avoids any regrowth.
        skip: drop the first ``skip`` events (those a decoder emits before its state is defined).

    Returns:
        ``(t, x, y, p)``: ``[E]`` int64 µs, uint16 column, uint16 row, int8 polarity ±1, in stream
        order (not validated: pass them to :meth:`EventStream.create`).
    """
    cols = [np.empty(max(int(capacity), 1), dt) for dt in (np.int64, np.uint16, np.uint16, np.int8)]
    n = 0
    for chunk in chunks:
        if skip:
            dropped = min(skip, len(chunk))
            chunk, skip = chunk[dropped:], skip - dropped
        m = len(chunk)
        if m == 0:
            continue
        if n + m > cols[0].size:
            size = max(n + m, int(cols[0].size * GROWTH))
            for c in cols:
                c.resize(size, refcheck=False)  # realloc: no second copy held
        t, x, y, p = (c[n:n + m] for c in cols)
        t[...] = chunk["t"]
        x[...] = chunk["x"]
        y[...] = chunk["y"]
        p[...] = chunk["on"]
        p *= 2
        p -= 1
        n += m
    for c in cols:
        c.resize(n, refcheck=False)
    return cols[0], cols[1], cols[2], cols[3]
