"""HDF5 event files compressed with hdf5plugin filters (Blosc/Zstd, as DSEC ships them) read."""

from __future__ import annotations

import json
import subprocess
import sys

import h5py
import hdf5plugin
import numpy as np

from fusiongs.events.readers import detect_format, read_event_utils_h5

BLOSC_ID, ZSTD_ID = 32001, 32015  # registered HDF5 filter ids


def _events(n=500, seed=0):
    rng = np.random.default_rng(seed)
    return (np.sort(rng.integers(0, 50_000, n)).astype(np.uint32), rng.integers(0, 8, n).astype(np.uint16),
            rng.integers(0, 6, n).astype(np.uint16), rng.integers(0, 2, n).astype(np.uint8))


def _write_dsec(path, t, x, y, p, offset):
    """DSEC's events.h5: events/{p,t,x,y} (t in µs, uint32), root t_offset and ms_to_idx, Blosc+Zstd."""
    blosc = hdf5plugin.Blosc(cname="zstd", clevel=5, shuffle=hdf5plugin.Blosc.SHUFFLE)
    with h5py.File(path, "w") as f:
        for name, data in (("p", p), ("t", t), ("x", x), ("y", y)):
            f.create_dataset(f"events/{name}", data=data, chunks=(128,), **blosc)
        f.create_dataset("t_offset", data=np.int64(offset))
        f.create_dataset("ms_to_idx", data=np.searchsorted(t, np.arange(0, 51_000, 1000)).astype(np.uint64),
                         **blosc)
        assert str(BLOSC_ID) in f["events/t"]._filters  # really compressed with the plugin filter


def test_blosc_zstd_dsec_file_reads_in_a_fresh_process(tmp_path):
    """The reader imports hdf5plugin itself: the reading process never imported it before."""
    t, x, y, p = _events()
    path = tmp_path / "events.h5"
    _write_dsec(path, t, x, y, p, offset=1_000_000)
    code = (
        "import json, sys\n"
        "from fusiongs.events.readers import detect_format, read_events\n"
        f"path = {str(path)!r}\n"
        "before = 'hdf5plugin' in sys.modules\n"
        "s = read_events(path, width=8, height=6)\n"
        "print(json.dumps({'before': before, 'after': 'hdf5plugin' in sys.modules,\n"
        "                  'format': detect_format(path), 't': s.t.tolist(), 'x': s.x.tolist(),\n"
        "                  'y': s.y.tolist(), 'p': s.p.tolist()}))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["before"] is False and got["after"] is True
    assert got["format"] == "dsec"
    assert got["t"] == (t.astype(np.int64) + 1_000_000).tolist()
    assert got["x"] == x.tolist() and got["y"] == y.tolist()
    assert got["p"] == np.where(p == 1, 1, -1).tolist()


def test_zstd_event_utils_file_reads(tmp_path):
    t, x, y, p = _events(seed=1)
    path = tmp_path / "eu.h5"
    with h5py.File(path, "w") as f:
        for name, data in (("ts", t / 1e6), ("xs", x), ("ys", y), ("ps", p)):
            f.create_dataset(f"events/{name}", data=data, chunks=(100,), **hdf5plugin.Zstd(clevel=3))
        f.attrs["sensor_resolution"] = [6, 8]
        assert str(ZSTD_ID) in f["events/ts"]._filters
    assert detect_format(path) == "event_utils"
    s = read_event_utils_h5(path)
    assert (s.width, s.height) == (8, 6) and len(s) == len(t)
    assert np.array_equal(s.x, x) and np.array_equal(s.y, y)
    assert np.abs(s.t - t.astype(np.int64)).max() <= 1  # seconds as float64 -> µs
