"""The synthetic EVT 3.0 writer of ``benchmarks/bench_data.py`` (the 1e8-event memory benchmark)
round-trips through fusiongs' Prophesee reader: same events, across chunks and clock wraps."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_data import evt3_words, synthetic_evt3_chunks, write_evt3
from fusiongs.events.readers.prophesee import read_prophesee_raw

N = 100_000


@pytest.mark.parametrize("mean_dt_us", [1.0, 200.0])  # equal times / 20 s: a 16.8 s wrap of 24 bits
def test_written_evt3_reads_back_the_same_events(tmp_path, mean_dt_us):
    chunks = list(synthetic_evt3_chunks(N, mean_dt_us=mean_dt_us, seed=3, chunk=30_000))
    path = tmp_path / "synthetic.raw"
    info = write_evt3(path, chunks)
    t, x, y, p = (np.concatenate(c) for c in zip(*chunks))
    s = read_prophesee_raw(path)
    assert (s.width, s.height) == (1280, 720) and len(s) == info["events"] == N
    np.testing.assert_array_equal(s.t, t)
    np.testing.assert_array_equal(s.x, x)
    np.testing.assert_array_equal(s.y, y)
    np.testing.assert_array_equal(s.p, 2 * p.astype(np.int8) - 1)
    assert info["sum_t"] == int(s.t.sum()) and info["sum_p"] == int(s.p.sum())
    if mean_dt_us > 100:
        assert t[-1] > 1 << 24  # the clock wrapped at least once


def test_words_follow_the_evt3_layout():
    t = np.array([5, 5, 4097])
    x = np.array([7, 8, 9], np.uint16)
    y = np.array([2, 2, 3], np.uint16)
    p = np.array([1, 0, 1], np.uint8)
    words, prev = evt3_words(t, x, y, p, (-1, -1))
    expected = [0x8000, 0x6005, 0x0002, 0x2800 | 7,  # time high, time low, row, ON event at x=7
                0x2000 | 8,                          # same time and row: one word, OFF at x=8
                0x8001, 0x6001, 0x0003, 0x2800 | 9]
    assert words.tolist() == expected and prev == (4097, 3)
