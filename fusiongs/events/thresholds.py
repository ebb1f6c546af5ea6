"""Contrast thresholds of an event sensor: the container ``calibration.json`` holds.

A DVS pixel fires an ON event when its log intensity rises by ``theta_pos`` and an OFF event when it
falls by ``theta_neg`` (docs/method.md section 1); real sensors have ``theta_pos != theta_neg`` and, for
colour (CFA) sensors, one pair per colour channel. :class:`SensorThresholds` carries one pair per
channel with its uncertainty; ``fusiongs calibrate`` writes it, and ``fusiongs edi`` / ``deblur``
read it back with ``--calibration FILE``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fusiongs.atomic import json_ready
from fusiongs.errors import InputError, is_finite_number

GREY_CHANNELS = ("grey",)
RGB_CHANNELS = ("R", "G", "B")
FORMAT_NAME = "fusiongs-calibration"


@dataclass(frozen=True, eq=False)
class SensorThresholds:
    """ON / OFF contrast thresholds per colour channel (log-intensity units).

    Attributes:
        channels: ``("grey",)`` for a monochrome sensor, ``("R", "G", "B")`` for a CFA sensor.
        theta_pos, theta_neg: ``[C]`` float64 thresholds of ON and OFF events.
        std_pos, std_neg: ``[C]`` float64 one-sigma uncertainties (NaN when unknown).
        scale_known: False when only the ON/OFF ratio is observable (no frames): the common scale
            of ``theta_pos`` and ``theta_neg`` is then an assumption.
        method: how the values were obtained (``"mEDI consistency"``, ``"event balance"``, ``"given"``).
        details: plain JSON-serialisable diagnostics (pixels used, refractory estimate, ...).
    """

    channels: tuple[str, ...]
    theta_pos: np.ndarray
    theta_neg: np.ndarray
    std_pos: np.ndarray
    std_neg: np.ndarray
    scale_known: bool = True
    method: str = "given"
    details: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        c = len(self.channels)
        if self.channels not in (GREY_CHANNELS, RGB_CHANNELS):
            raise InputError("thresholds", "channels", f"{GREY_CHANNELS} or {RGB_CHANNELS}", self.channels)
        for name in ("theta_pos", "theta_neg", "std_pos", "std_neg"):
            v = np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            if v.shape != (c,):
                raise InputError("thresholds", name, f"{c} value(s), one per channel", v.tolist())
            if name.startswith("theta") and not (np.all(np.isfinite(v)) and np.all(v > 0)):
                raise InputError("thresholds", name, "finite positive thresholds", v.tolist())
            object.__setattr__(self, name, v)

    @staticmethod
    def uniform(theta_pos: float, theta_neg: float | None = None, cfa: str | None = None,
                method: str = "given") -> SensorThresholds:
        """The same pair for every channel of a grey (``cfa=None``) or colour sensor."""
        ch = GREY_CHANNELS if cfa is None else RGB_CHANNELS
        tn = theta_pos if theta_neg is None else theta_neg
        nan = np.full(len(ch), np.nan)
        return SensorThresholds(ch, np.full(len(ch), float(theta_pos)), np.full(len(ch), float(tn)),
                                nan, nan.copy(), True, method)

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    def as_array(self) -> np.ndarray:
        """``[2, C]`` float64: row 0 ON, row 1 OFF (the layout of the learnable threshold)."""
        return np.stack([self.theta_pos, self.theta_neg])

    def pair(self) -> tuple[float, float]:
        """Mean ``(theta_pos, theta_neg)`` over the channels (a scalar summary)."""
        return float(np.mean(self.theta_pos)), float(np.mean(self.theta_neg))

    def for_sensor(self, cfa: str | None, where: str = "calibration") -> SensorThresholds:
        """Check that these thresholds fit a sensor (``cfa`` None = grey) and return them.

        A grey calibration is accepted for a colour sensor (the pair is used for every channel);
        a per-channel calibration is not accepted for a grey sensor.
        """
        if cfa is None and self.channels != GREY_CHANNELS:
            raise InputError(where, "thresholds.channels", "one grey channel for a monochrome sensor",
                             list(self.channels))
        if cfa is not None and self.channels == GREY_CHANNELS:
            return SensorThresholds(RGB_CHANNELS, np.repeat(self.theta_pos, 3), np.repeat(self.theta_neg, 3),
                                    np.repeat(self.std_pos, 3), np.repeat(self.std_neg, 3),
                                    self.scale_known, self.method, dict(self.details))
        return self

    def to_dict(self) -> dict:
        """Plain JSON document (the ``thresholds`` object of ``calibration.json``)."""
        clean = lambda v: [None if not math.isfinite(float(x)) else float(x) for x in v]
        return {"channels": list(self.channels), "theta_pos": clean(self.theta_pos),
                "theta_neg": clean(self.theta_neg), "std_pos": clean(self.std_pos),
                "std_neg": clean(self.std_neg), "scale_known": bool(self.scale_known),
                "method": self.method, "details": json_ready(self.details)}

    @staticmethod
    def from_dict(doc: object, where: str = "calibration.json") -> SensorThresholds:
        """Parse :meth:`to_dict` output; raises :class:`InputError` naming the bad key."""
        if not isinstance(doc, dict):
            raise InputError(where, "thresholds", "an object", type(doc).__name__)
        for key in ("channels", "theta_pos", "theta_neg"):
            if key not in doc:
                raise InputError(where, f"thresholds.{key}", "a list, one entry per channel", "missing")
        ch = doc["channels"]
        if not isinstance(ch, list) or tuple(ch) not in (GREY_CHANNELS, RGB_CHANNELS):
            raise InputError(where, "thresholds.channels", '["grey"] or ["R", "G", "B"]', ch)
        vals = {}
        for key in ("theta_pos", "theta_neg", "std_pos", "std_neg"):
            v = doc.get(key, [None] * len(ch))
            if not isinstance(v, list) or len(v) != len(ch):
                raise InputError(where, f"thresholds.{key}", f"a list of {len(ch)} number(s)", v)
            try:
                vals[key] = np.array([np.nan if x is None else float(x) for x in v])
            except (TypeError, ValueError):
                raise InputError(where, f"thresholds.{key}", "numbers", v) from None
            if key.startswith("theta") and not (np.all(np.isfinite(vals[key])) and np.all(vals[key] > 0)):
                raise InputError(where, f"thresholds.{key}", "finite positive thresholds", v)
        details = doc.get("details", {})
        return SensorThresholds(tuple(ch), vals["theta_pos"], vals["theta_neg"], vals["std_pos"],
                                vals["std_neg"], bool(doc.get("scale_known", True)),
                                str(doc.get("method", "given")), details if isinstance(details, dict) else {})


def read_calibration(path: str | Path) -> tuple[SensorThresholds, dict]:
    """Read ``calibration.json``: ``(thresholds, whole document)``; one-line errors name the file."""
    p = Path(path)
    if p.is_dir():
        p = p / "calibration.json"
    try:
        doc = json.loads(p.read_text())
    except FileNotFoundError:
        raise InputError(p, "file", "an existing calibration.json (from fusiongs calibrate)",
                         "not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(p, "file", "a JSON calibration file", f"{type(e).__name__}: {e}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME:
        raise InputError(p, "format", f'"{FORMAT_NAME}"', doc.get("format") if isinstance(doc, dict) else doc)
    if "thresholds" not in doc:
        raise InputError(p, "thresholds", "an object with channels, theta_pos and theta_neg", "missing")
    th = SensorThresholds.from_dict(doc["thresholds"], str(p))
    reset_model_parameters(th, p)  # a reset calibration's numbers checked here, naming the file
    calibration_warnings(th, p)
    return th, doc


def calibration_document(thresholds: SensorThresholds, **extra) -> dict:
    """The ``calibration.json`` document: format tag, thresholds and any extra top-level keys."""
    return {"format": FORMAT_NAME, "version": 1, "thresholds": thresholds.to_dict(), **extra}


def write_calibration(path: str | Path, thresholds: SensorThresholds, **extra) -> Path:
    """Write ``calibration.json`` atomically; returns its path."""
    from fusiongs.atomic import write_text

    p = Path(path)
    write_text(p, json.dumps(calibration_document(thresholds, **extra), indent=2) + "\n")
    return p


def detail_number(thresholds: SensorThresholds, key: str) -> float | None:
    """``thresholds.details[key]`` as a float when it is a finite number (not a bool), else None
    (a calibration.json may come from elsewhere)."""
    v = thresholds.details.get(key)
    if not is_finite_number(v):
        return None
    return float(v)


def calibration_warnings(thresholds: SensorThresholds, where: str | Path = "calibration") -> list[str]:
    """The estimator's warnings (its details' ``warnings``: a list of sentences; none when absent).

    Raises:
        InputError: naming ``where``, when ``warnings`` is there but not a list of strings (a
            calibration.json may come from elsewhere).
    """
    warnings = thresholds.details.get("warnings", [])
    if not (isinstance(warnings, list) and all(isinstance(w, str) for w in warnings)):
        raise InputError(where, "details.warnings", "a list of strings", repr(warnings))
    return warnings


def reset_model_parameters(thresholds: SensorThresholds, where: str | Path = "calibration"
                           ) -> tuple[float, float, bool] | None:
    """``(dead time µs, weight cap, burst end)`` when the calibration chose the pixel model of a
    pixel held in reset (its details' ``pixel_model``, ``dead_time_us``, ``reset_weight_cap``,
    default cap 4, and ``reset_burst_end``: the weights of :func:`fusiongs.events.dead_time.reset_weights`
    that it was estimated with; a file without it is from before that term, so False), else None.

    Raises:
        InputError: naming ``where`` (the file, when read from one), for a reset calibration whose
            dead time, cap or burst-end flag is not valid.
    """
    model = thresholds.details.get("pixel_model")
    if not (isinstance(model, str) and model.startswith("reset")):
        return None
    dead = detail_number(thresholds, "dead_time_us")
    cap = detail_number(thresholds, "reset_weight_cap") if "reset_weight_cap" in thresholds.details else 4.0
    burst_end = thresholds.details.get("reset_burst_end", False)
    if dead is None or dead < 0:
        raise InputError(where, "details.dead_time_us", "a dead time >= 0 (µs) for the reset pixel model",
                         repr(thresholds.details.get("dead_time_us")))
    if cap is None or cap < 1:
        raise InputError(where, "details.reset_weight_cap", "a number >= 1",
                         repr(thresholds.details.get("reset_weight_cap")))
    if not isinstance(burst_end, bool):
        raise InputError(where, "details.reset_burst_end", "true or false", repr(burst_end))
    return dead, cap, burst_end


def calibration_event_weights(events, thresholds) -> np.ndarray | None:
    """``[E]`` float32 threshold crossings each event of ``events`` stands for, where the
    calibration ``thresholds`` chose the pixel model of a pixel held in reset
    (:func:`reset_model_parameters`; :func:`fusiongs.events.dead_time.reset_weights`); None otherwise
    (the events count once each), also for thresholds that are plain numbers.

    Raises:
        InputError: a reset calibration whose dead time or cap is not a valid number.
    """
    from fusiongs.events.dead_time import reset_weights

    if not isinstance(thresholds, SensorThresholds):
        return None
    params = reset_model_parameters(thresholds)
    if params is None or params[0] == 0:
        return None
    return reset_weights(events, *params)
