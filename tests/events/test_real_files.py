"""Readers on the real recordings of ``conftest.real_data_dir()`` (skipped when absent).

The README there lists counts, durations and ON fractions; the Prophesee reader (``faery``) is also
compared event by event with an independent decoder (the numpy reference of ``_evt_reference``).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.events.readers import read_aedat4, read_events, read_prophesee_raw
from tests.conftest import real_data_dir, real_file
from tests.reference.evt_decoder import read_prophesee_raw_numpy

# file, size override, events, duration (µs, rounded as in the README), ON fraction (3 decimals)
CASES = [
    ("davis346_mono.aedat4", {}, 78_830, 2.36e6, 0.523),
    ("dvxplorer_320x240.aedat4", {}, 111_954, 0.59e6, 0.491),
    ("prophesee_evt2_640x480.raw", {"width": 640, "height": 480}, 521_252, 96e3, None),
    ("prophesee_evt3_1280x720.raw", {}, 1_218_618, 10.77e6, None),
]


@pytest.mark.parametrize("name, kw, count, duration_us, on", CASES)
def test_real_recordings_match_the_readme(name, kw, count, duration_us, on):
    s = read_events(real_file(name), **kw)
    assert len(s) == count
    assert s.duration_us == pytest.approx(duration_us, rel=5e-3)
    if on is not None:
        assert round(s.polarity_balance, 3) == on
    assert np.all(np.diff(s.t) >= 0)


def test_davis_aps_frames_and_exposures():
    _, frames = read_aedat4(real_file("davis346_mono.aedat4"))
    assert len(frames) == 59 and frames.images.shape == (59, 260, 346)
    assert np.all(frames.exposure_end - frames.exposure_start == 500)
    assert np.median(np.diff(frames.t)) == pytest.approx(40_000, rel=0.01)  # 25 fps


def test_evt2_without_geometry_header_needs_a_size():
    with pytest.raises(InputError, match="geometry"):
        read_prophesee_raw(real_file("prophesee_evt2_640x480.raw"))


def test_counts_in_this_file_are_the_readmes():
    readme = real_data_dir() / "README.md"
    if not readme.is_file():
        pytest.skip(f"no README.md in {real_data_dir()}")
    rows = {}
    for line in readme.read_text().splitlines():
        m = re.match(r"\|\s*(\S+)\s*\|[^|]*?([\d,]+) events", line)
        if m:
            rows[m.group(1)] = int(m.group(2).replace(",", ""))
    assert {name: count for name, _, count, _, _ in CASES} == {name: rows.get(name) for name, *_ in CASES}


@pytest.mark.parametrize("name, kw", [("prophesee_evt2_640x480.raw", {"width": 640, "height": 480}),
                                      ("prophesee_evt3_1280x720.raw", {})])
def test_prophesee_reader_agrees_with_the_numpy_reference_on_every_event(name, kw):
    path = real_file(name)
    ours = read_prophesee_raw(path, **kw)
    ref = read_prophesee_raw_numpy(path, **kw)
    assert len(ours) == len(ref)
    for k in ("t", "x", "y", "p"):
        assert np.array_equal(getattr(ours, k), getattr(ref, k)), k
        assert getattr(ours, k).dtype == getattr(ref, k).dtype


def test_truncated_real_files_are_input_errors(tmp_path):
    for name, cut in [("davis346_mono.aedat4", 3_000_000), ("prophesee_evt3_1280x720.raw", 1_000_000)]:
        data = real_file(name).read_bytes()[:cut]
        (tmp_path / name).write_bytes(data)
        with pytest.raises(InputError, match=name):
            read_events(tmp_path / name)
