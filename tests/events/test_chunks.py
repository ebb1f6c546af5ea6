"""Event columns filled chunk by chunk from decoder packets."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from fusiongs.events.readers.chunks import columns_from_chunks

DTYPE = [("t", "<u8"), ("x", "<u2"), ("y", "<u2"), ("on", "?")]


def _chunks(sizes, seed=0):
    rng = np.random.default_rng(seed)
    out, t0 = [], 0
    for n in sizes:
        c = np.zeros(n, DTYPE)
        c["t"] = t0 + np.arange(n)
        c["x"], c["y"] = rng.integers(0, 1000, n), rng.integers(0, 700, n)
        c["on"] = rng.random(n) < 0.5
        out.append(c)
        t0 += n
    return out


@pytest.mark.parametrize("capacity", [1, 7, 100, 10_000])
def test_columns_equal_the_concatenated_chunks_whatever_the_capacity(capacity):
    chunks = _chunks([5, 0, 13, 1, 40])
    ref = np.concatenate(chunks)
    t, x, y, p = columns_from_chunks(iter(chunks), capacity=capacity)
    assert (t.dtype, x.dtype, y.dtype, p.dtype) == (np.int64, np.uint16, np.uint16, np.int8)
    assert t.tolist() == ref["t"].tolist() and x.tolist() == ref["x"].tolist()
    assert y.tolist() == ref["y"].tolist() and p.tolist() == np.where(ref["on"], 1, -1).tolist()


def test_skip_drops_leading_events_across_chunks():
    chunks = _chunks([2, 3, 4])
    t, *_ = columns_from_chunks(chunks, capacity=4, skip=4)
    assert t.tolist() == [4, 5, 6, 7, 8]


def test_no_chunks_give_empty_columns():
    t, x, y, p = columns_from_chunks([], capacity=10)
    assert [len(a) for a in (t, x, y, p)] == [0, 0, 0, 0]


def test_memory_beyond_the_output_is_about_one_chunk():
    n_chunks, size = 50, 20_000
    out_bytes = n_chunks * size * (8 + 2 + 2 + 1)

    def packets():  # made lazily, as a decoder does
        for i in range(n_chunks):
            yield _chunks([size], seed=i)[0]

    tracemalloc.start()
    try:
        cols = columns_from_chunks(packets(), capacity=n_chunks * size)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert sum(c.nbytes for c in cols) == out_bytes
    assert peak < out_bytes + 20 * size * 13  # a concatenation would need twice the output
