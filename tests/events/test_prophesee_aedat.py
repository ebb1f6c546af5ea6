"""Prophesee EVT 2.0 / 3.0 decoders on encoded streams, and AEDAT4 bad input."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.events.readers import read_aedat4, read_events, read_prophesee_raw


def encode_evt2(t, x, y, on) -> bytes:
    """Reference EVT 2.0 encoder following the published word layout."""
    words, last = [], None
    for ti, xi, yi, oi in zip(t, x, y, on):
        if ti >> 6 != last:
            last = ti >> 6
            words.append((0x8 << 28) | last)
        words.append((int(oi) << 28) | ((ti & 0x3F) << 22) | (xi << 11) | yi)
    return np.asarray(words, "<u4").tobytes()


def encode_evt3(t, x, y, on) -> bytes:
    """Reference EVT 3.0 encoder (single-event words only; 24-bit time wraps)."""
    words, th_last, tl_last, y_last = [], None, None, None
    for ti, xi, yi, oi in zip(t, x, y, on):
        th, tl = (ti >> 12) & 0xFFF, ti & 0xFFF
        if th != th_last:
            words.append((0x8 << 12) | th)
            th_last, tl_last = th, None
        if tl != tl_last:
            words.append((0x6 << 12) | tl)
            tl_last = tl
        if yi != y_last:
            words.append(yi)
            y_last = yi
        words.append((0x2 << 12) | (int(oi) << 11) | xi)
    return np.asarray(words, "<u2").tobytes()


def _events(n=500, seed=0, t0=0, span=3_000_000):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(t0, t0 + span, n))
    return t, rng.integers(0, 1280, n), rng.integers(0, 720, n), rng.random(n) < 0.5


@pytest.mark.parametrize("version, encode, header", [
    ("2.0", encode_evt2, b"% evt 2.0\n% geometry 1280x720\n"),
    ("3.0", encode_evt3, b"% evt 3.0\n% format EVT3;height=720;width=1280\n% end\n"),
])
def test_decoders_recover_every_encoded_event(tmp_path, version, encode, header):
    t, x, y, on = _events()
    (tmp_path / "e.raw").write_bytes(header + encode(t, x, y, on))
    s = read_events(tmp_path / "e.raw")
    assert (s.width, s.height) == (1280, 720)
    assert s.t.tolist() == t.tolist() and s.x.tolist() == x.tolist() and s.y.tolist() == y.tolist()
    assert (s.p > 0).tolist() == on.tolist()


def test_evt3_time_wraps_after_24_bits(tmp_path):
    t, x, y, on = _events(200, t0=2**24 - 50_000, span=100_000)
    (tmp_path / "e.raw").write_bytes(b"% evt 3.0\n% geometry 1280x720\n" + encode_evt3(t, x, y, on))
    assert read_prophesee_raw(tmp_path / "e.raw").t.tolist() == (t % 2**24 + (t >= 2**24) * 2**24).tolist()


def test_evt3_vector_words_expand_from_the_base(tmp_path):
    words = [0x8001, 0x6005, 0x0007,           # time high 1, time low 5, row 7
             0x3000 | 0x800 | 100,             # VECT_BASE_X, ON, x = 100
             0x4000 | 0b100000000001,          # VECT_12: x = 100 and 111; base -> 112
             0x5000 | 0x200 | 0b11,            # VECT_8: x = 112, 113 (bit 9 is not a valid bit)
             0x7000, 0xA000, 0xE000, 0xF000,   # continued / trigger / others: no CD events
             0x2000 | 3]                       # single OFF event at x = 3
    (tmp_path / "e.raw").write_bytes(b"% evt 3.0\n% geometry 200x10\n" + np.asarray(words, "<u2").tobytes())
    s = read_prophesee_raw(tmp_path / "e.raw")
    assert s.x.tolist() == [100, 111, 112, 113, 3] and s.y.tolist() == [7] * 5
    assert s.t.tolist() == [(1 << 12) | 5] * 5 and s.p.tolist() == [1, 1, 1, 1, -1]


def test_events_before_the_first_time_word_are_skipped(tmp_path):
    words = [(1 << 28) | (5 << 11) | 6, (0x8 << 28) | 2, (1 << 28) | (3 << 22) | (1 << 11) | 2]
    (tmp_path / "e.raw").write_bytes(b"% evt 2.0\n" + np.asarray(words, "<u4").tobytes())
    s = read_prophesee_raw(tmp_path / "e.raw", 10, 10)
    assert s.t.tolist() == [(2 << 6) | 3] and s.x.tolist() == [1]


@pytest.mark.parametrize("content, match", [
    (b"% evt 3.0\n% geometry 10x10\n\x00\x80\x01", "whole number of 2-byte"),
    (b"% evt 2.0\n% geometry 10x10\n\x00\x00\x00\x80\x00", "whole number of 4-byte"),
    (b"% evt 2.1\n% geometry 10x10\n", "EVT 2.1 is not supported"),
    (b"\x00\x80\x01\x00", "header"),
    (b"% evt 2.0\n", "geometry"),
    (b"% evt 2.0\n% geometry 10x10\n" + np.asarray([0x80000001], "<u4").tobytes(), "at least one event"),
    (b"% evt 2.0\n% geometry 4x4\n" + encode_evt2([1], [9], [0], [True]), "inside the 4x4 sensor"),
])
def test_bad_raw_files_raise_named_errors(tmp_path, content, match):
    (tmp_path / "e.raw").write_bytes(content)
    with pytest.raises(InputError, match=match) as e:
        read_prophesee_raw(tmp_path / "e.raw")
    assert "e.raw" in str(e.value)


def test_corrupt_aedat4_is_an_input_error(tmp_path):
    (tmp_path / "e.aedat4").write_bytes(b"#!AER-DAT4.0\r\n" + b"\x07" * 64)
    with pytest.raises(InputError, match="e.aedat4"):
        read_aedat4(tmp_path / "e.aedat4")
    with pytest.raises(InputError, match="no such file"):
        read_aedat4(tmp_path / "missing.aedat4")
