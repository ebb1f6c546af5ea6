"""EventStream.create validation and the stream's queries."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.events.stream import EventStream, polarity_to_pm1


def _stream(n=200, seed=0, w=16, h=12):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, 10_000, n))
    return EventStream.create(t, rng.integers(0, w, n), rng.integers(0, h, n),
                              rng.integers(0, 2, n), w, h)


def test_create_converts_dtypes_and_polarity():
    s = EventStream.create([0, 1, 2], np.array([1, 2, 3], np.int32), [0, 1, 0], [1, 0, 1], 4, 2)
    assert s.t.dtype == np.int64 and s.x.dtype == np.uint16 and s.y.dtype == np.uint16
    assert s.p.dtype == np.int8 and s.p.tolist() == [1, -1, 1]


@pytest.mark.parametrize("p, expected", [([True, False], [1, -1]), ([1, -1], [1, -1]),
                                         ([1.0, 0.0], [1, -1]), ([0, 0], [-1, -1]), ([-1, -1], [-1, -1])])
def test_polarity_encodings_map_to_pm1(p, expected):
    assert polarity_to_pm1(np.asarray(p)).tolist() == expected


@pytest.mark.parametrize("p", [[1, 0, -1], [2, 1], [0.5, 1.0]])
def test_unknown_polarity_values_are_named(p):
    with pytest.raises(InputError, match="src: p: expected polarity"):
        EventStream.create(np.arange(len(p)), np.zeros(len(p)), np.zeros(len(p)), p, 4, 4, source="src")


def test_unequal_lengths_name_every_field():
    with pytest.raises(InputError, match="t=3, x=2"):
        EventStream.create([0, 1, 2], [0, 1], [0, 1, 2], [1, 1, 1], 4, 4)


def test_unsorted_times_raise_unless_sort_is_asked_and_sort_is_stable():
    t, x = [5, 3, 3, 9], [0, 1, 2, 3]
    with pytest.raises(InputError, match="sorted ascending"):
        EventStream.create(t, x, [0] * 4, [1] * 4, 4, 4)
    s = EventStream.create(t, x, [0] * 4, [1] * 4, 4, 4, sort=True)
    assert s.t.tolist() == [3, 3, 5, 9] and s.x.tolist() == [1, 2, 0, 3]


def test_coordinates_outside_raise_unless_dropped():
    with pytest.raises(InputError, match=r"x/y: expected coordinates inside the 4x3 sensor.*\(4, 0\)"):
        EventStream.create([0, 1, 2], [0, 4, 1], [0, 0, 3], [1, 1, 1], 4, 3)
    s = EventStream.create([0, 1, 2], [0, 4, 1], [0, 0, 2], [1, 1, 1], 4, 3, drop_invalid=True)
    assert s.x.tolist() == [0, 1] and s.t.tolist() == [0, 2]


def test_negative_coordinates_are_outside():
    with pytest.raises(InputError, match="x/y"):
        EventStream.create([0], [-1], [0], [1], 4, 3)


@pytest.mark.parametrize("t, msg", [([0.0, np.nan], "finite"), ([-1, 2], "non-negative"),
                                    (["a", "b"], "numeric")])
def test_bad_times_are_named(t, msg):
    with pytest.raises(InputError, match=f"t: expected {msg}"):
        EventStream.create(t, [0, 0], [0, 0], [1, 1], 4, 4)


def test_unknown_cfa_and_bad_size_are_errors():
    with pytest.raises(InputError, match="cfa"):
        EventStream.create([0], [0], [0], [1], 4, 4, cfa="RGBG")
    with pytest.raises(InputError, match="width"):
        EventStream.create([0], [0], [0], [1], 0, 4)


def test_non_integer_coordinates_are_rejected():
    with pytest.raises(InputError, match="integer pixel coordinates"):
        EventStream.create([0], [1.5], [0], [1], 4, 4)


def test_empty_stream_is_a_valid_container():
    s = EventStream.create([], [], [], [], 4, 3)
    assert len(s) == 0 and s.duration_us == 0 and s.rate == 0.0 and np.isnan(s.polarity_balance)
    assert s.count_maps().shape == (2, 3, 4)


def test_slice_time_is_half_open_and_tiles_time():
    s = EventStream.create([0, 10, 10, 20, 30], [0] * 5, [0] * 5, [1] * 5, 2, 2)
    assert s.slice_time(10, 20).t.tolist() == [10, 10]
    a, b, whole = s.slice_time(0, 20), s.slice_time(20, 40), s.slice_time(0, 40)
    assert len(a) + len(b) == len(whole) == 5


def test_count_maps_match_a_loop_reference():
    s = _stream()
    ref = np.zeros((2, s.height, s.width), np.int32)
    t0, t1 = 2000, 7000
    for t, x, y, p in zip(s.t, s.x, s.y, s.p):
        if t0 <= t < t1:
            ref[0 if p > 0 else 1, y, x] += 1
    got = s.count_maps(t0, t1)
    assert got.dtype == np.int32 and np.array_equal(got, ref)
    assert np.array_equal(s.signed_count_map(t0, t1), ref[0] - ref[1])
    assert s.count_maps().sum() == len(s)


def test_summary_properties():
    s = EventStream.create([0, 500_000, 1_000_000], [0, 1, 2], [0, 0, 0], [1, 1, 0], 3, 1)
    assert s.duration_us == 1_000_000 and s.rate == pytest.approx(3.0)
    assert s.polarity_balance == pytest.approx(2 / 3)
    assert s.pixel_counts().tolist() == [[1, 1, 1]]


def test_to_torch_returns_tensors_on_the_given_device():
    import torch

    d = _stream(10).to_torch(torch.device("cpu"))
    assert d["t"].dtype == torch.int64 and d["p"].dtype == torch.float32 and d["x"].shape == (10,)


def test_create_does_not_modify_inputs():
    t = np.array([3, 1, 2])
    x = np.array([0, 9, 1])
    EventStream.create(t, x, np.zeros(3, int), np.ones(3, int), 4, 4, sort=True, drop_invalid=True)
    assert t.tolist() == [3, 1, 2] and x.tolist() == [0, 9, 1]
