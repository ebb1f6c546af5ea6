"""Timestamp units of third-party layouts: conversion to µs and cautious detection."""

from __future__ import annotations

import numpy as np

from fusiongs.errors import InputError

TIME_UNITS = ("s", "ms", "us", "ns")
_SCALE_TO_US = {"s": 1e6, "ms": 1e3, "us": 1.0, "ns": 1e-3}


def detect_time_unit(t: np.ndarray, source: str, field: str = "t") -> str:
    """Guess the unit of ``t`` only where the magnitude leaves no doubt, else raise.

    Rules: float values with a fractional part spanning less than 1e5 are seconds (event_utils
    style; as µs they would span under 0.1 s with sub-µs stamps); integer-valued times spanning
    at least 1e11 are nanoseconds (as µs they would span more than 27 hours). Anything else (for
    example EvDeblurNeRF's integer files, which hold µs or ns) is ambiguous.

    Raises:
        InputError: when the unit is ambiguous; the message asks for ``time_unit``.
    """
    t = np.asarray(t)
    if t.size == 0:
        raise InputError(source, field, "at least one event", "0 events")
    span = float(t.max()) - float(t.min())
    if t.dtype.kind == "f" and np.isfinite(span):
        if span < 1e5 and np.any(t != np.round(t)):
            return "s"
    if t.dtype.kind in "iuf" and span >= 1e11:
        return "ns"
    raise InputError(source, field, "an explicit time unit (time_unit / --time-unit: one of "
                     f"{', '.join(TIME_UNITS)}): the values are ambiguous",
                     f"{t.dtype} values spanning {span:.6g}")


def to_us(t: np.ndarray, unit: str | None, source: str, field: str = "t") -> np.ndarray:
    """Convert timestamps to µs (int64 for integer input in µs/ns, else float rounded later).

    Args:
        t: ``[E]`` timestamps in ``unit``.
        unit: one of ``TIME_UNITS``, or ``None`` to use :func:`detect_time_unit`.

    Returns:
        ``[E]`` µs: int64 when exact, float64 otherwise (``EventStream.create`` rounds it).
    """
    t = np.asarray(t)
    if unit is None:
        unit = detect_time_unit(t, source, field)
    if unit not in _SCALE_TO_US:
        raise InputError(source, "time_unit", f"one of {', '.join(TIME_UNITS)}", repr(unit))
    if t.dtype.kind not in "iuf":
        raise InputError(source, field, "numeric timestamps", f"dtype {t.dtype}")
    if unit == "us":
        return t
    if t.dtype.kind in "iu" and unit == "ns":
        return (t.astype(np.int64) + 500) // 1000
    if t.dtype.kind in "iu":
        return t.astype(np.int64) * int(_SCALE_TO_US[unit])
    return t.astype(np.float64) * _SCALE_TO_US[unit]
