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


def test_evt3_events_before_time_and_row_words_are_skipped(tmp_path):
    words = [0x2000 | 3,                       # no time, no row yet
             0x8001, 0x3000 | 20, 0x4000 | 0b101,  # time high only: a vector of 2 events, skipped
             0x6005, 0x2000 | 4,               # time low too, still no row: skipped
             0x0007, 0x2000 | 5, 0x2800 | 6]   # row 7: these two are decoded
    (tmp_path / "e.raw").write_bytes(b"% evt 3.0\n% geometry 200x10\n" + np.asarray(words, "<u2").tobytes())
    s = read_prophesee_raw(tmp_path / "e.raw")
    assert s.x.tolist() == [5, 6] and s.y.tolist() == [7, 7] and s.p.tolist() == [-1, 1]
    assert s.t.tolist() == [(1 << 12) | 5] * 2


def _random_evt3(rng, n_packets=400) -> tuple[bytes, int]:
    """A valid EVT 3.0 stream mixing single and vector words, with time wraps; and its event count."""
    words, n, t, base_t = [], 0, 0, 2**24 - 30_000
    for _ in range(n_packets):
        t += int(rng.integers(0, 400))
        tt = (base_t + t) % 2**24
        words += [0x8000 | (tt >> 12), 0x6000 | (tt & 0xFFF), int(rng.integers(0, 720))]
        if rng.random() < 0.5:
            xs = rng.choice(1280, int(rng.integers(1, 5)), replace=False)
            words += [0x2000 | (int(rng.random() < 0.5) << 11) | int(x) for x in xs]
            n += xs.size
        else:
            words.append(0x3000 | (int(rng.random() < 0.5) << 11) | int(rng.integers(0, 1200)))
            for _ in range(int(rng.integers(1, 4))):
                bits = int(rng.integers(1, 4096))
                words.append((0x4000 if rng.random() < 0.5 else 0x5000) | bits)
                n += bin(bits if words[-1] >> 12 == 4 else bits & 0xFF).count("1")
    return np.asarray(words, "<u2").tobytes(), n


def test_evt3_reader_matches_the_numpy_reference_on_mixed_words(tmp_path):
    from tests.reference.evt_decoder import read_prophesee_raw_numpy

    data, n = _random_evt3(np.random.default_rng(3))
    (tmp_path / "e.raw").write_bytes(b"% evt 3.0\n% geometry 2048x720\n" + data)
    ours, ref = read_prophesee_raw(tmp_path / "e.raw"), read_prophesee_raw_numpy(tmp_path / "e.raw")
    assert len(ours) == len(ref) == n
    assert ours.t[-1] > 2**24  # the 24-bit time wrapped and was unwrapped
    for k in ("t", "x", "y", "p"):
        assert np.array_equal(getattr(ours, k), getattr(ref, k)), k


def test_raw_without_geometry_checks_the_given_size_and_honours_drop_invalid(tmp_path):
    t, x, y, on = np.arange(4), np.array([1, 900, 2, 3]), np.array([0, 1, 2, 3]), np.ones(4, bool)
    (tmp_path / "e.raw").write_bytes(b"% evt 2.0\n" + encode_evt2(t, x, y, on))
    with pytest.raises(InputError, match="inside the 640x480 sensor"):
        read_prophesee_raw(tmp_path / "e.raw", 640, 480)
    s = read_prophesee_raw(tmp_path / "e.raw", 640, 480, drop_invalid=True)
    assert s.x.tolist() == [1, 2, 3] and s.t.tolist() == [0, 2, 3]


def test_reader_columns_have_the_stream_dtypes_without_a_copy(tmp_path):
    t, x, y, on = _events(3000)
    (tmp_path / "e.raw").write_bytes(b"% evt 2.0\n% geometry 1280x720\n" + encode_evt2(t, x, y, on))
    s = read_prophesee_raw(tmp_path / "e.raw")
    assert (s.t.dtype, s.x.dtype, s.y.dtype, s.p.dtype) == (np.int64, np.uint16, np.uint16, np.int8)
    assert all(a.flags.owndata and a.base is None for a in (s.t, s.x, s.y, s.p))
