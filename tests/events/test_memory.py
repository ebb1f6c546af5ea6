"""Whole-stream passes keep their temporaries O(pixels), not O(events): what lets every verb read a
1e8-event stream in 4 GB (benchmarks/bench_verbs_memory.py). numpy reports its allocations to
tracemalloc; a pass that built an int64 index or an argsort of the stream (8 bytes an event, as
these functions did before) fails the bound below (half a byte an event, plus a fixed allowance)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import torch

from fusiongs.edi import event_count_samples
from fusiongs.events import dead_time, stats
from fusiongs.events.stream import EventStream
from fusiongs.train.data import event_indices

N = 4_000_000
FIXED = 12 * 2**20  # per-pixel arrays, the median's interval histogram, chunk buffers


@pytest.fixture(scope="module")
def stream() -> EventStream:
    rng = np.random.default_rng(0)
    w, h = 64, 48
    t = np.sort(rng.integers(0, 2_000_000, N)).astype(np.int64)
    return EventStream(t, rng.integers(0, w, N).astype(np.uint16), rng.integers(0, h, N).astype(np.uint16),
                       rng.choice(np.array([-1, 1], np.int8), N), w, h)


def _extra_bytes(fn) -> int:
    """Peak traced bytes of ``fn()`` beyond the size of what it returns (after a first call that
    loads the numba kernels, whose compilation is Python objects too)."""
    fn()
    tracemalloc.start()
    try:
        out = fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    kept = sum(a.nbytes for a in (out if isinstance(out, tuple) else (out,))
               if isinstance(a, np.ndarray))
    if isinstance(out, torch.Tensor):
        kept = out.numel() * out.element_size()
    return peak - kept


@pytest.mark.parametrize("name", ["count_maps", "window_counts", "pixel_counts", "dead_time",
                                  "fast_mask", "fast_counts", "time_gaps", "exposure_counts",
                                  "event_indices"])
def test_whole_stream_passes_have_no_per_event_temporaries(stream, name, monkeypatch):
    monkeypatch.setattr(stats, "CHUNK", 1 << 18, raising=False)
    cases = {
        "count_maps": lambda: stream.count_maps(),
        "window_counts": lambda: stream.count_maps(100_000, 1_900_000),
        "pixel_counts": lambda: stream.pixel_counts(),
        "dead_time": lambda: np.asarray(dead_time.dead_time_us(stream)),
        "fast_mask": lambda: stats.fast_event_mask(stream, 50.0),
        "fast_counts": lambda: dead_time.fast_event_counts(stream, 50.0, np.arange(0, 2_000_001, 250_000)),
        "time_gaps": lambda: stats.time_gaps(stream.t),
        "exposure_counts": lambda: event_count_samples(stream, 0.1, 1.9, 12),
        "event_indices": lambda: event_indices(stream, torch.device("cpu")),
    }
    assert _extra_bytes(cases[name]) < N // 2 + FIXED
