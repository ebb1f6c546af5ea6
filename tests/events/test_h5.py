"""Native events.h5 read/write, DSEC-style offsets, and bad HDF5 input."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiongs.errors import InputError
from fusiongs.events.h5 import read_events_h5, time_range_h5, write_events_h5
from fusiongs.events.stream import EventStream


def _write_raw(path, **datasets):
    attrs = datasets.pop("attrs", {})
    root = datasets.pop("root", {})
    with h5py.File(path, "w") as f:
        g = f.create_group("events")
        for k, v in datasets.items():
            g.create_dataset(k, data=np.asarray(v))
        for k, v in attrs.items():
            g.attrs[k] = v
        for k, v in root.items():
            f.create_dataset(k, data=v)


@st.composite
def streams(draw):
    w = draw(st.integers(1, 40))
    h = draw(st.integers(1, 30))
    n = draw(st.integers(1, 60))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, 2**40, n))
    cfa = draw(st.sampled_from([None, "RGGB", "BGGR", "GRBG", "GBRG"]))
    return EventStream.create(t, rng.integers(0, w, n), rng.integers(0, h, n),
                              rng.choice([-1, 1], n), w, h, cfa)


@settings(max_examples=25, deadline=None)
@given(s=streams(), compression=st.sampled_from([None, "lzf"]))
def test_write_read_round_trip_is_exact(tmp_path_factory, s, compression):
    path = tmp_path_factory.mktemp("h5") / "events.h5"
    write_events_h5(s, path, compression=compression)
    r = read_events_h5(path, s.width, s.height, s.cfa)
    for k in "txyp":
        assert np.array_equal(getattr(r, k), getattr(s, k)) and getattr(r, k).dtype == getattr(s, k).dtype
    assert (r.width, r.height, r.cfa) == (s.width, s.height, s.cfa)


def test_write_is_atomic_and_leaves_no_temporary(tmp_path):
    s = EventStream.create([0, 1], [0, 1], [0, 0], [1, -1], 2, 1)
    write_events_h5(s, tmp_path / "events.h5")
    assert [p.name for p in tmp_path.iterdir()] == ["events.h5"]


def test_size_defaults_to_the_attributes_the_writer_stores(tmp_path):
    s = EventStream.create([0, 1], [0, 4], [0, 2], [1, -1], 5, 3)
    write_events_h5(s, tmp_path / "e.h5")
    r = read_events_h5(tmp_path / "e.h5")
    assert (r.width, r.height) == (5, 3)


def test_t_offset_attribute_is_added(tmp_path):
    _write_raw(tmp_path / "e.h5", t=np.array([0, 5], np.int64), x=[0, 1], y=[0, 0],
               p=np.array([1, 0], np.uint8), attrs={"t_offset_us": np.int64(1000)})
    r = read_events_h5(tmp_path / "e.h5", 2, 1)
    assert r.t.tolist() == [1000, 1005] and r.p.tolist() == [1, -1]


def test_dsec_style_t_offset_dataset_and_ms_to_idx_are_accepted(tmp_path):
    _write_raw(tmp_path / "e.h5", t=np.array([0, 5], np.uint32), x=[0, 1], y=[0, 0],
               p=np.array([1, 0], np.uint8),
               root={"t_offset": np.int64(7), "ms_to_idx": np.array([0, 2], np.uint64)})
    assert read_events_h5(tmp_path / "e.h5", 2, 1).t.tolist() == [7, 12]


def test_the_time_range_is_the_full_reads_first_and_last_with_either_offset(tmp_path):
    _write_raw(tmp_path / "a.h5", t=np.array([0, 5, 9], np.int64), x=[0, 1, 0], y=[0, 0, 0],
               p=np.array([1, 0, 1], np.uint8), attrs={"t_offset_us": np.int64(1000)})
    _write_raw(tmp_path / "b.h5", t=np.array([0, 5], np.uint32), x=[0, 1], y=[0, 0],
               p=np.array([1, 0], np.uint8), root={"t_offset": np.int64(7)})
    for name in ("a.h5", "b.h5"):
        t = read_events_h5(tmp_path / name, 2, 1).t
        assert time_range_h5(tmp_path / name) == (t[0], t[-1])
    _write_raw(tmp_path / "e.h5", t=np.zeros(0, np.int64), x=np.zeros(0, np.uint16),
               y=np.zeros(0, np.uint16), p=np.zeros(0, np.int8))
    with pytest.raises(InputError, match="events: expected at least one event"):
        time_range_h5(tmp_path / "e.h5")


def test_missing_dataset_is_named(tmp_path):
    _write_raw(tmp_path / "e.h5", t=[0], x=[0], y=[0])
    with pytest.raises(InputError, match=r"e\.h5: events/p: expected datasets"):
        read_events_h5(tmp_path / "e.h5", 2, 2)


def test_missing_group_lists_keys(tmp_path):
    with h5py.File(tmp_path / "e.h5", "w") as f:
        f.create_dataset("x", data=[1])
    with pytest.raises(InputError, match=r"events: expected an HDF5 group.*\['x'\]"):
        read_events_h5(tmp_path / "e.h5", 2, 2)


def test_zero_events_is_an_error(tmp_path):
    _write_raw(tmp_path / "e.h5", t=np.zeros(0, np.int64), x=np.zeros(0, np.uint16),
               y=np.zeros(0, np.uint16), p=np.zeros(0, np.int8))
    with pytest.raises(InputError, match="events: expected at least one event"):
        read_events_h5(tmp_path / "e.h5", 2, 2)


@pytest.mark.parametrize("field, fields, match", [
    ("t", dict(t=[0, 1], x=[0], y=[0, 0], p=[1, 1]), "equal length"),
    ("t", dict(t=[5, 1], x=[0, 0], y=[0, 0], p=[1, 1]), "sorted ascending"),
    ("x", dict(t=[0, 1], x=[0, 9], y=[0, 0], p=[1, 1]), "inside the 2x2 sensor"),
    ("p", dict(t=[0, 1], x=[0, 0], y=[0, 0], p=[3, 1]), "polarity"),
    ("t", dict(t=[0.0, np.nan], x=[0, 0], y=[0, 0], p=[1, 1]), "finite"),
    ("t", dict(t=[-3, 1], x=[0, 0], y=[0, 0], p=[1, 1]), "non-negative"),
])
def test_corrupted_fields_raise_one_named_error(tmp_path, field, fields, match):
    _write_raw(tmp_path / "e.h5", **fields)
    with pytest.raises(InputError, match=match) as e:
        read_events_h5(tmp_path / "e.h5", 2, 2)
    assert str(tmp_path / "e.h5") in str(e.value)


def test_truncated_file_is_an_input_error(tmp_path):
    s = EventStream.create(np.arange(1000), np.zeros(1000), np.zeros(1000), np.ones(1000), 2, 2)
    write_events_h5(s, tmp_path / "e.h5")
    data = (tmp_path / "e.h5").read_bytes()
    (tmp_path / "t.h5").write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError, match="t.h5"):
        read_events_h5(tmp_path / "t.h5", 2, 2)


def test_non_hdf5_and_missing_files_are_input_errors(tmp_path):
    (tmp_path / "x.h5").write_text("not hdf5")
    with pytest.raises(InputError, match="readable HDF5"):
        read_events_h5(tmp_path / "x.h5", 2, 2)
    with pytest.raises(InputError, match="no such file"):
        read_events_h5(tmp_path / "none.h5", 2, 2)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(2, 50), seed=st.integers(0, 2**32 - 1),
       corruption=st.sampled_from(["x", "y", "p", "t_order", "t_negative", "length"]))
def test_any_corrupted_field_raises_an_error_naming_it(tmp_path_factory, n, seed, corruption):
    rng = np.random.default_rng(seed)
    f = {"t": np.sort(rng.integers(1, 10**6, n)), "x": rng.integers(0, 8, n), "y": rng.integers(0, 6, n),
         "p": rng.choice([-1, 1], n)}
    i = int(rng.integers(1, n))
    expected = {"x": "x/y", "y": "x/y", "p": "p", "t_order": "t", "t_negative": "t", "length": "t/x/y/p"}
    if corruption in ("x", "y"):
        f[corruption][i] = 8 if corruption == "x" else 6
    elif corruption == "p":
        f["p"][i] = 2
    elif corruption == "t_order":
        f["t"][i] = f["t"][i - 1] - 1
    elif corruption == "t_negative":
        f["t"][0] = -5
    else:
        f["x"] = f["x"][:-1]
    path = tmp_path_factory.mktemp("bad") / "e.h5"
    _write_raw(path, **f)
    with pytest.raises(InputError) as e:
        read_events_h5(path, 8, 6)
    assert e.value.field == expected[corruption] and e.value.where == str(path)
