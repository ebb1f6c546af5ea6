"""Third-party layouts: event_utils / EvDeblurNeRF HDF5, rpg text, EventNeRF npz, the dispatcher."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiongs.errors import InputError
from fusiongs.events.readers import (
    detect_format,
    read_event_utils_h5,
    read_eventnerf_npz,
    read_events,
    read_events_txt,
    read_root_xytp_h5,
    write_events_txt,
)
from fusiongs.events.readers.text import parse_events_text_reference
from fusiongs.events.readers.units import detect_time_unit
from fusiongs.events.stream import EventStream

T_US = np.array([1_000, 2_500, 2_500, 9_000], np.int64)
X, Y, P01 = np.array([0, 3, 1, 2]), np.array([0, 1, 2, 1]), np.array([1, 0, 0, 1])


def test_event_utils_h5_seconds_and_resolution_attribute(tmp_path):
    with h5py.File(tmp_path / "e.h5", "w") as f:
        f.attrs["sensor_resolution"] = np.array([3, 4])  # [height, width]
        f["events/xs"], f["events/ys"] = X.astype(np.int16), Y.astype(np.int16)
        f["events/ts"], f["events/ps"] = T_US * 1e-6, P01.astype(bool)
    assert detect_format(tmp_path / "e.h5") == "event_utils"
    s = read_events(tmp_path / "e.h5")
    assert (s.width, s.height) == (4, 3) and s.t.tolist() == T_US.tolist()
    assert s.p.tolist() == [1, -1, -1, 1]


def test_event_utils_without_resolution_needs_a_size(tmp_path):
    with h5py.File(tmp_path / "e.h5", "w") as f:
        f["events/xs"], f["events/ys"], f["events/ts"], f["events/ps"] = X, Y, T_US * 1e-6, P01
    with pytest.raises(InputError, match="sensor_resolution"):
        read_event_utils_h5(tmp_path / "e.h5")
    assert len(read_event_utils_h5(tmp_path / "e.h5", 4, 3)) == 4


@pytest.mark.parametrize("unit, scale", [("us", 1), ("ns", 1000)])
def test_evdeblurnerf_root_datasets_with_explicit_unit(tmp_path, unit, scale):
    with h5py.File(tmp_path / "e.h5", "w") as f:
        f["x"], f["y"], f["t"], f["p"] = X, Y, T_US * scale, np.where(P01 > 0, 1, -1)
    assert detect_format(tmp_path / "e.h5") == "evdeblurnerf"
    s = read_events(tmp_path / "e.h5", width=4, height=3, time_unit=unit)
    assert s.t.tolist() == T_US.tolist()


def test_evdeblurnerf_ambiguous_unit_raises_and_asks_for_it(tmp_path):
    with h5py.File(tmp_path / "e.h5", "w") as f:
        f["x"], f["y"], f["t"], f["p"] = X, Y, T_US, P01
    with pytest.raises(InputError, match="explicit time unit"):
        read_root_xytp_h5(tmp_path / "e.h5", 4, 3)


def test_time_unit_detection_only_when_unambiguous():
    assert detect_time_unit(np.array([0.1, 0.25, 3.5]), "f") == "s"
    assert detect_time_unit(np.array([0, 2 * 10**11]), "f") == "ns"
    with pytest.raises(InputError):
        detect_time_unit(np.array([0, 10**6]), "f")


def test_unknown_h5_layout_lists_what_was_looked_for(tmp_path):
    with h5py.File(tmp_path / "e.h5", "w") as f:
        f["foo"] = [1]
    with pytest.raises(InputError, match=r"events/\{t,x,y,p\}.*events/\{xs,ys,ts,ps\}.*root x,y,t,p"):
        read_events(tmp_path / "e.h5")


def test_unknown_extension_is_named(tmp_path):
    (tmp_path / "e.bin").write_bytes(b"0")
    with pytest.raises(InputError, match="known extension"):
        read_events(tmp_path / "e.bin")


def test_eventnerf_npz(tmp_path):
    np.savez(tmp_path / "e.npz", x=X, y=Y, t=T_US * 1e-6 + 0.5, p=np.where(P01 > 0, 1, -1))
    s = read_events(tmp_path / "e.npz", width=4, height=3, cfa="RGGB")
    assert s.t.tolist() == (T_US + 500_000).tolist() and s.cfa == "RGGB"


def test_eventnerf_npz_errors(tmp_path):
    np.savez(tmp_path / "e.npz", x=X, y=Y, t=T_US)
    with pytest.raises(InputError, match=r"p: expected arrays x, y, t, p"):
        read_eventnerf_npz(tmp_path / "e.npz", 4, 3, time_unit="us")
    with pytest.raises(InputError, match="346x260"):
        read_eventnerf_npz(tmp_path / "e.npz", None, None)
    (tmp_path / "bad.npz").write_bytes(b"PK\x03\x04garbage")
    with pytest.raises(InputError, match="bad.npz: file"):
        read_eventnerf_npz(tmp_path / "bad.npz", 4, 3)


@st.composite
def streams(draw):
    n = draw(st.integers(1, 80))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    t = np.sort(rng.integers(0, 10**13, n))
    w, h = draw(st.integers(1, 2000)), draw(st.integers(1, 2000))
    return EventStream.create(t, rng.integers(0, w, n), rng.integers(0, h, n), rng.choice([-1, 1], n), w, h)


@settings(max_examples=30, deadline=None)
@given(s=streams(), header=st.booleans())
def test_text_round_trip_is_exact(tmp_path_factory, s, header):
    path = tmp_path_factory.mktemp("txt") / "events.txt"
    write_events_txt(s, path, header=header)
    r = read_events_txt(path) if header else read_events_txt(path, s.width, s.height)
    for k in "txyp":
        assert np.array_equal(getattr(r, k), getattr(s, k))
    assert (r.width, r.height) == (s.width, s.height)


def test_text_parser_matches_the_reference_on_varied_number_forms(tmp_path):
    text = ("# comment\n1.5 1 2 1\n\n  2.0000004 3 4 0\r\n2.0000005\t5 6 0\n3e-1 0 0 1\n"
            "1468940145.2466139 7 8 1\n12 9 9 +1\n")
    (tmp_path / "e.txt").write_text(text)
    s = read_events_txt(tmp_path / "e.txt", 10, 10, sort=True)
    ref = parse_events_text_reference(text)
    ref = ref[np.argsort(ref[:, 0], kind="stable")]
    assert s.t.tolist() == ref[:, 0].tolist() and s.x.tolist() == ref[:, 1].tolist()
    assert s.p.tolist() == np.where(ref[:, 3] > 0, 1, -1).tolist()


@pytest.mark.parametrize("body, line, match", [
    ("0.1 1 2 1\n0.2 1 2\n", 3, "4 numbers"),
    ("0.1 1 2 1\n0.2 1 x 1\n", 3, "4 numbers"),
    ("0.1 1 2 1 7\n", 2, "4 numbers"),
    ("-0.1 1 2 1\n", 2, "a non-negative time"),
    ("abc 1 2 1\n", 2, "4 numbers"),
])
def test_text_errors_name_the_line(tmp_path, body, line, match):
    (tmp_path / "e.txt").write_text("4 3\n" + body)
    with pytest.raises(InputError, match=f"e.txt: line {line}: expected {match}"):
        read_events_txt(tmp_path / "e.txt")


def test_text_field_checks_and_missing_size(tmp_path):
    (tmp_path / "a.txt").write_text("4 3\n0.2 1 1 1\n0.1 1 1 1\n")
    with pytest.raises(InputError, match="sorted ascending"):
        read_events_txt(tmp_path / "a.txt")
    (tmp_path / "b.txt").write_text("0.1 9 1 1\n")
    with pytest.raises(InputError, match="inside the 4x3 sensor"):
        read_events_txt(tmp_path / "b.txt", 4, 3)
    with pytest.raises(InputError, match="width height"):
        read_events_txt(tmp_path / "b.txt")
    (tmp_path / "c.txt").write_text("0.1 1 1 2\n")
    with pytest.raises(InputError, match="polarity"):
        read_events_txt(tmp_path / "c.txt", 4, 3)
    (tmp_path / "d.txt").write_text("4 3\n# nothing\n")
    with pytest.raises(InputError, match="at least one event"):
        read_events_txt(tmp_path / "d.txt")
