"""The event stream container and its validated constructor.

``EventStream(...)`` builds the container without checks (for code that already holds valid arrays);
:meth:`EventStream.create` is the boundary for user data: it converts dtypes, maps polarity
encodings and raises :class:`~fusiongs.errors.InputError` naming the source and the field.
Per-channel CFA masks of a stream's sensor live in :mod:`fusiongs.events.cfa`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusiongs.errors import InputError

CFA_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")


@dataclass(frozen=True, eq=False)
class EventStream:
    """A time-sorted stream of events from one sensor.

    Attributes:
        t: ``[E]`` int64 timestamps in microseconds, sorted ascending (non-decreasing).
        x: ``[E]`` uint16 column, ``0 <= x < width``.
        y: ``[E]`` uint16 row, ``0 <= y < height``.
        p: ``[E]`` int8 polarity, +1 (brightness increase) or -1.
        width, height: sensor size in pixels.
        cfa: ``None`` for a monochrome sensor, else one of ``CFA_PATTERNS`` (2x2 layout named by
            its top-left cells in row-major order; ``"RGGB"`` = R at even row and even column).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    width: int
    height: int
    cfa: str | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])

    # ------------------------------------------------------------------ construction
    @classmethod
    def create(cls, t, x, y, p, width: int, height: int, cfa: str | None = None, *,
               source: str = "events", sort: bool = False, drop_invalid: bool = False) -> EventStream:
        """Validate user arrays and build a stream (the boundary for data read from files).

        Args:
            t: ``[E]`` timestamps in microseconds (integer, or float rounded to the nearest µs).
            x, y: ``[E]`` integer pixel column / row.
            p: ``[E]`` polarity as +1/-1, 1/0 (1 = brightness increase) or True/False.
            width, height: sensor size in pixels.
            cfa: ``None`` or one of ``CFA_PATTERNS``.
            source: the file or description named in error messages.
            sort: stably sort by time instead of raising on unsorted timestamps.
            drop_invalid: drop events outside the sensor instead of raising.

        Raises:
            InputError: unequal lengths, NaN/negative/unsorted times, coordinates outside the
                sensor, unknown polarity values, non-integer coordinates or an unknown CFA name.
        """
        src = str(source)
        for name, v in (("width", width), ("height", height)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0 or v > 65536:
                raise InputError(src, name, "a positive integer sensor size (at most 65536)", repr(v))
        if cfa is not None and cfa not in CFA_PATTERNS:
            raise InputError(src, "cfa", f"None or one of {', '.join(CFA_PATTERNS)}", repr(cfa))
        arrays = {k: np.asarray(v) for k, v in (("t", t), ("x", x), ("y", y), ("p", p))}
        for k, a in arrays.items():
            if a.ndim != 1:
                raise InputError(src, k, "a 1-D array", f"shape {a.shape}")
        lengths = {k: a.shape[0] for k, a in arrays.items()}
        if len(set(lengths.values())) > 1:
            raise InputError(src, "t/x/y/p", "arrays of equal length",
                             ", ".join(f"{k}={n}" for k, n in lengths.items()))
        tt = _times_us(arrays["t"], src)
        xx = _coords(arrays["x"], src, "x")
        yy = _coords(arrays["y"], src, "y")
        pp = polarity_to_pm1(arrays["p"], src)
        bad = (xx >= width) | (yy >= height)
        if xx.dtype.kind == "i" or yy.dtype.kind == "i":
            bad |= (xx < 0) | (yy < 0)
        if bad.any():
            if not drop_invalid:
                i = int(np.flatnonzero(bad)[0])
                raise InputError(src, "x/y", f"coordinates inside the {width}x{height} sensor "
                                 "(or pass drop_invalid / --drop-invalid)",
                                 f"({int(xx[i])}, {int(yy[i])}) at event {i}; {int(bad.sum())} outside")
            keep = ~bad
            tt, xx, yy, pp = tt[keep], xx[keep], yy[keep], pp[keep]
        if tt.shape[0] > 1:
            dec = tt[1:] < tt[:-1]
            if dec.any():
                if not sort:
                    i = int(np.argmax(dec)) + 1
                    raise InputError(src, "t", "timestamps sorted ascending (or pass sort / --sort)",
                                     f"{int(tt[i])} after {int(tt[i - 1])} at event {i}")
                order = np.argsort(tt, kind="stable")
                tt, xx, yy, pp = tt[order], xx[order], yy[order], pp[order]
        return cls(t=tt, x=xx.astype(np.uint16, copy=False), y=yy.astype(np.uint16, copy=False),
                   p=pp, width=int(width), height=int(height), cfa=cfa)

    @classmethod
    def empty(cls, width: int, height: int, cfa: str | None = None) -> EventStream:
        """A stream with no events (a valid container; readers reject event-less files)."""
        return cls(np.zeros(0, np.int64), np.zeros(0, np.uint16), np.zeros(0, np.uint16),
                   np.zeros(0, np.int8), int(width), int(height), cfa)

    # ------------------------------------------------------------------ queries
    def index_range(self, t0_us: int, t1_us: int) -> tuple[int, int]:
        """Indices ``[i0, i1)`` of the events with ``t0_us <= t < t1_us`` (binary search)."""
        i0 = int(np.searchsorted(self.t, t0_us, side="left"))
        i1 = int(np.searchsorted(self.t, t1_us, side="left"))
        return i0, max(i0, i1)

    def slice_time(self, t0_us: int, t1_us: int) -> EventStream:
        """Events in the half-open window ``[t0_us, t1_us)`` (µs), as views of this stream's arrays.

        Half-open windows tile time without double counting: ``slice_time(a, b)`` and
        ``slice_time(b, c)`` together hold exactly the events of ``slice_time(a, c)``.
        """
        i0, i1 = self.index_range(t0_us, t1_us)
        return EventStream(self.t[i0:i1], self.x[i0:i1], self.y[i0:i1], self.p[i0:i1],
                           self.width, self.height, self.cfa)

    def count_maps(self, t0_us: int | None = None, t1_us: int | None = None,
                   weights: np.ndarray | None = None) -> np.ndarray:
        """Per-pixel event counts ``[2, H, W]`` int32: channel 0 = ON (+1), 1 = OFF (-1) events.

        Counts the events in ``[t0_us, t1_us)`` (the whole stream when both are ``None``). With
        ``weights`` (``[E]``, one per event of the stream) the float64 sums of the weights instead.
        """
        lo = np.iinfo(np.int64).min if t0_us is None else t0_us
        hi = np.iinfo(np.int64).max if t1_us is None else t1_us
        i0, i1 = self.index_range(lo, hi)
        if weights is not None:
            if len(weights) != len(self):
                raise InputError("count_maps", "weights", f"{len(self)} weights, one per event", len(weights))
            w = np.asarray(weights)[i0:i1]  # a view: no per-event copy
            return self._counts(i0, i1, w).reshape(2, self.height, self.width)
        return self._counts(i0, i1).astype(np.int32).reshape(2, self.height, self.width)

    def _counts(self, i0: int, i1: int, weights: np.ndarray | None = None) -> np.ndarray:
        """``[2 * H * W]`` int64 ON then OFF counts of the events ``[i0, i1)``, or float64 sums of
        their ``weights`` (one pass, no per-event temporaries:
        :func:`fusiongs.events._kernels.count_events`)."""
        from fusiongs.events._kernels import count_events

        hw = self.height * self.width
        out = np.zeros(2 * hw, np.int64 if weights is None else np.float64)
        w = np.ones(1, np.int64) if weights is None else weights
        if i1 > i0:
            count_events(self.x[i0:i1], self.y[i0:i1], self.p[i0:i1], w, self.width, hw, out)
        return out

    def signed_count_map(self, t0_us: int | None = None, t1_us: int | None = None) -> np.ndarray:
        """``[H, W]`` int32 sum of polarities (ON minus OFF counts) in ``[t0_us, t1_us)``."""
        c = self.count_maps(t0_us, t1_us)
        return c[0] - c[1]

    def pixel_counts(self) -> np.ndarray:
        """``[H, W]`` int64 number of events per pixel over the whole stream."""
        c = self._counts(0, len(self)).reshape(2, self.height, self.width)
        return c[0] + c[1]

    @property
    def duration_us(self) -> int:
        """Time between the first and the last event in µs (0 for fewer than two events)."""
        return int(self.t[-1] - self.t[0]) if len(self) > 1 else 0

    @property
    def rate(self) -> float:
        """Mean event rate in events per second (0.0 when the duration is zero)."""
        d = self.duration_us
        return len(self) / (d * 1e-6) if d > 0 else 0.0

    @property
    def polarity_balance(self) -> float:
        """Fraction of ON (+1) events in [0, 1] (NaN for an empty stream)."""
        return float(np.count_nonzero(self.p > 0) / len(self)) if len(self) else float("nan")

    def to_torch(self, device=None) -> dict:
        """Tensors ``{"t": int64 µs, "x": int64, "y": int64, "p": float32 ±1}``, each ``[E]``."""
        import torch

        return {"t": torch.as_tensor(self.t, device=device),
                "x": torch.as_tensor(self.x.astype(np.int64), device=device),
                "y": torch.as_tensor(self.y.astype(np.int64), device=device),
                "p": torch.as_tensor(self.p.astype(np.float32), device=device)}


# ---------------------------------------------------------------------- field converters
def _times_us(t: np.ndarray, src: str) -> np.ndarray:
    """``[E]`` int64 µs from integer or float microseconds; NaN and negative times are errors."""
    if t.dtype.kind == "f":
        if t.size and not np.isfinite(t).all():
            i = int(np.flatnonzero(~np.isfinite(t))[0])
            raise InputError(src, "t", "finite timestamps", f"{t[i]} at event {i}")
        t = np.rint(t).astype(np.int64)
    elif t.dtype.kind in "iu":
        if t.dtype == np.uint64 and t.size and t.max() > np.iinfo(np.int64).max:
            raise InputError(src, "t", "timestamps below 2**63 µs", int(t.max()))
        t = t.astype(np.int64, copy=False)
    else:
        raise InputError(src, "t", "numeric timestamps", f"dtype {t.dtype}")
    if t.size and t.min() < 0:
        i = int(np.argmax(t < 0))
        raise InputError(src, "t", "non-negative timestamps", f"{int(t[i])} at event {i}")
    return t


def _coords(a: np.ndarray, src: str, name: str) -> np.ndarray:
    """Integer pixel coordinates as int64 (floats must hold whole numbers)."""
    if a.dtype.kind in "iu":
        return a.astype(np.int64, copy=False) if a.dtype.kind == "i" or a.dtype.itemsize > 4 else a
    if a.dtype.kind == "f":
        if a.size and not (np.isfinite(a).all() and (a == np.round(a)).all()):
            raise InputError(src, name, "integer pixel coordinates (rectified float coordinates "
                             "are not supported)", "non-integer values")
        return a.astype(np.int64)
    if a.dtype == bool:
        return a.astype(np.int64)
    raise InputError(src, name, "integer pixel coordinates", f"dtype {a.dtype}")


def polarity_to_pm1(p: np.ndarray, source: str = "events") -> np.ndarray:
    """Map a polarity encoding to int8 ±1.

    Args:
        p: ``[E]`` polarities: bool (True = ON), +1/-1, or 1/0 (1 = ON); integer or float dtype.
        source: named in the error message.

    Returns:
        ``[E]`` int8 with +1 for brightness increase and -1 for decrease.

    Raises:
        InputError: when the values are not one of those encodings (for example {-1, 0, 1}).
    """
    p = np.asarray(p)
    if p.dtype == bool:
        return np.where(p, np.int8(1), np.int8(-1))
    if p.dtype.kind not in "iuf":
        raise InputError(source, "p", "polarity as +1/-1, 1/0 or True/False", f"dtype {p.dtype}")
    if p.size == 0:
        return np.zeros(0, np.int8)
    lo, hi = p.min(), p.max()
    if lo == -1 and hi == 1:
        n_bad = p.size - np.count_nonzero(p == 1) - np.count_nonzero(p == -1)
        if n_bad == 0:
            return p.astype(np.int8, copy=False)
    elif lo >= 0 and hi <= 1:
        on = p == 1
        if np.count_nonzero(on) + np.count_nonzero(p == 0) == p.size:
            return np.where(on, np.int8(1), np.int8(-1))
    elif lo == hi == -1:
        return p.astype(np.int8, copy=False)
    vals = np.unique(p[: min(p.size, 1_000_000)])[:6]
    raise InputError(source, "p", "polarity as +1/-1, 1/0 or True/False",
                     "values " + ", ".join(str(v) for v in vals.tolist()))
