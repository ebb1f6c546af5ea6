"""Event-based double integral (EDI): deblur a frame with its events (Pan et al., CVPR 2019).

In linear light a blurry frame is the mean of the sharp images over its exposure ``[s, e]``, and
events relate every instant to the mid-exposure image: ``L(t) = L(t_mid) exp(theta E(t))`` with
``E(t)`` the signed event integral from ``t_mid`` to ``t``. Hence (Pan et al., Eq. 6)

    ``L(t_mid) = B / mean_{t in [s, e]} exp(theta E(t))``

with the mean taken at ``M`` instants ``t_k = s + (k + 0.5)/M (e - s)``. ``E`` uses the half-open
convention of :meth:`EventStream.count_maps` (an event at ``t_e`` counts for ``t > t_e``), with
``theta_+`` for ON and ``theta_-`` for OFF events: ``theta E = theta_+ dN_+ - theta_- dN_-``.

Grey events scale every colour channel by the same ratio. Colour (CFA) events give each raw
pixel the ratio of its own channel (with that channel's thresholds when they are given per
channel); the ratio map is demosaiced (bilinear, float) to three channels before dividing. Unknown
thresholds come from :mod:`fusiongs.calibrate.estimate` (ON and OFF per channel); :func:`estimate_theta`
is the single-frame sharpness estimate of one symmetric threshold.
"""

from __future__ import annotations

import numpy as np

from fusiongs.errors import InputError
from fusiongs.events._kernels import exposure_counts
from fusiongs.events.cfa import cfa_channel_index, demosaic
from fusiongs.events.stream import EventStream
from fusiongs.events.thresholds import SensorThresholds, calibration_event_weights

THETA_GRID = tuple(np.round(np.geomspace(0.02, 0.8, 33), 4))
EDI_SAMPLES = 32  # default instants per exposure of edi_deblur and edi_scene


def _thetas(theta) -> tuple[float, float]:
    if isinstance(theta, (tuple, list, np.ndarray)):
        if len(theta) != 2:
            raise InputError("edi", "theta", "a threshold or a (theta_pos, theta_neg) pair", theta)
        tp, tn = float(theta[0]), float(theta[1])
    else:
        tp = tn = float(theta)
    if not (np.isfinite(tp) and np.isfinite(tn) and tp > 0 and tn > 0):
        raise InputError("edi", "theta", "positive contrast thresholds", (tp, tn))
    return tp, tn


def threshold_maps(theta, cfa: str | None, height: int, width: int):
    """``(theta_pos, theta_neg)`` per pixel: floats, or ``[H, W]`` maps for per-channel CFA thresholds.

    Args:
        theta: a threshold, a ``(theta_pos, theta_neg)`` pair, or :class:`SensorThresholds` (one pair
            per channel of a CFA sensor is looked up at every pixel's own channel).
        cfa: the event sensor's CFA (None = grey).
    """
    if not isinstance(theta, SensorThresholds):
        return _thetas(theta)
    th = theta.for_sensor(cfa, "edi")
    if th.n_channels == 1:
        return float(th.theta_pos[0]), float(th.theta_neg[0])
    ch = cfa_channel_index(cfa, height, width).astype(np.int64)
    return th.theta_pos[ch], th.theta_neg[ch]


def event_count_samples(events: EventStream, t_start: float, t_end: float, n_samples: int,
                        weights: np.ndarray | None = None) -> np.ndarray:
    """ON/OFF event counts from mid-exposure to each sample instant.

    Args:
        events: time-sorted stream (µs).
        t_start, t_end: exposure window in seconds.
        n_samples: number of instants ``M``.
        weights: optional ``[E]`` per-event weights (the crossings each event stands for,
            :func:`fusiongs.events.dead_time.reset_weights`): the counts are then their float32 sums.

    Returns:
        ``[M, 2, H, W]`` int32 ``N_pm(t_k) - N_pm(t_mid)`` (channel 0 ON, 1 OFF): negative before
        mid-exposure, positive after. One sort-free pass over the exposure's events
        (:func:`fusiongs.events._kernels.exposure_counts`; the bincount form is
        :func:`tests.reference.event_kernels.exposure_counts`).
    """
    if not (np.isfinite(t_start) and np.isfinite(t_end) and t_end > t_start):
        raise InputError("edi", "t_start/t_end", "an exposure window with t_end > t_start",
                         (t_start, t_end))
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise InputError("edi", "n_samples", "a positive integer", n_samples)
    s_us, e_us = t_start * 1e6, t_end * 1e6
    ts = s_us + (np.arange(n_samples) + 0.5) / n_samples * (e_us - s_us)
    mid = 0.5 * (s_us + e_us)
    i0, i1 = events.index_range(int(np.floor(s_us)), int(np.ceil(e_us)) + 1)
    hw = events.height * events.width
    if weights is None:
        out, w = np.zeros((n_samples, 2 * hw), np.int32), np.ones(1, np.int32)
    else:
        out, w = np.zeros((n_samples, 2 * hw), np.float32), np.asarray(weights)[i0:i1]
    exposure_counts(events.t[i0:i1], events.x[i0:i1], events.y[i0:i1], events.p[i0:i1], w,
                    events.width, hw, ts, mid, out)
    return out.reshape(n_samples, 2, events.height, events.width)


def edi_ratio(counts: np.ndarray, theta, cfa: str | None) -> np.ndarray:
    """``mean_k exp(theta E(t_k))`` per pixel from :func:`event_count_samples` output.

    Returns:
        ``[H, W, 1]`` float64 for grey events, ``[H, W, 3]`` (bilinear-demosaiced) for a CFA.
    """
    tp, tn = threshold_maps(theta, cfa, counts.shape[-2], counts.shape[-1])
    r = np.zeros(counts.shape[-2:], np.float64)
    for c in counts:  # one sample at a time: [H, W] temporaries, not [M, H, W]
        r += np.exp(tp * c[0] - tn * c[1])
    r /= counts.shape[0]
    if cfa is None:
        return r[..., None]
    return np.asarray(demosaic(r, cfa, "bilinear"), dtype=np.float64)


def _check_frame(frame: np.ndarray, events: EventStream) -> np.ndarray:
    f = np.asarray(frame)
    if f.ndim != 3 or f.shape[:2] != (events.height, events.width) or f.shape[2] not in (1, 3):
        raise InputError("edi", "frame", f"a linear image [{events.height}, {events.width}, C], "
                         "C = 1 or 3, matching the event sensor", f.shape)
    if events.cfa is not None and f.shape[2] != 3:
        raise InputError("edi", "frame", "an RGB frame for colour (CFA) events", f.shape)
    return f.astype(np.float64)


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    den = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / den) if den > 0 else 0.0


def _event_edges(events: EventStream, t_start: float, t_end: float) -> np.ndarray:
    """``[H, W]`` events per pixel in the middle eighth of the exposure (demosaiced for a CFA)."""
    mid, half = 0.5e6 * (t_start + t_end), (t_end - t_start) * 1e6 / 16
    cm = events.count_maps(int(np.floor(mid - half)), int(np.ceil(mid + half))).sum(0).astype(np.float64)
    return cm if events.cfa is None else np.asarray(demosaic(cm, events.cfa, "bilinear")).mean(-1)


def estimate_theta(frame_linear: np.ndarray, events: EventStream, t_start: float, t_end: float,
                   n_samples: int = 32, grid=THETA_GRID) -> float:
    """Threshold whose EDI result best agrees with the events at mid-exposure.

    Events fire where ``|grad log L . v|`` is large, so the sharp mid-exposure image has its
    log-gradient magnitude where the events of a short window around ``t_mid`` are. The estimate
    maximises the normalised cross-correlation between ``|grad log L(theta)|`` (luminance) and the
    event counts of the middle eighth of the exposure: the edge-consistency term of Pan et al.
    (CVPR 2019, Sec. 4.3). Their total-variation term is left out: on thin structures narrower
    than the blur it prefers residual blur (measured on the moving-bar test data).

    Args:
        frame_linear: ``[H, W, C]`` blurry frame, linear.
        events, t_start, t_end, n_samples: as :func:`edi_deblur`.
        grid: candidate thresholds (default 33 values geometrically spaced in [0.02, 0.8]).

    Returns:
        the best threshold of ``grid`` (one value for both polarities).
    """
    b = _check_frame(frame_linear, events)
    counts = event_count_samples(events, t_start, t_end, n_samples)
    edges = _event_edges(events, t_start, t_end)
    eps = 1e-3 * max(float(b.mean()), 1e-12)
    scores = []
    for th in grid:  # a few candidate thresholds, each a vectorised image operation
        lum = (b / edi_ratio(counts, th, events.cfa)).mean(axis=2)
        gy, gx = np.gradient(np.log(np.maximum(lum, eps)))
        scores.append(_ncc(np.hypot(gx, gy), edges))
    return float(grid[int(np.argmax(scores))])


def edi_deblur(frame_linear: np.ndarray, events: EventStream, t_start: float, t_end: float,
               theta=0.2, n_samples: int = EDI_SAMPLES, weights: np.ndarray | None = None) -> np.ndarray:
    """Sharp mid-exposure image of one blurry frame (EDI, Pan et al., CVPR 2019).

    Args:
        frame_linear: ``[H, W, C]`` blurry frame in linear light (C = 1 or 3; 3 for CFA events).
        events: time-sorted stream of the same sensor (µs clock = seconds x 1e6).
        t_start, t_end: exposure window in seconds.
        theta: contrast threshold, a ``(theta_pos, theta_neg)`` pair, :class:`SensorThresholds`, or
            ``None`` to estimate one symmetric threshold with :func:`estimate_theta`.
        n_samples: instants ``M`` the exposure mean is taken over.
        weights: optional ``[E]`` crossings each event stands for (a pixel held in reset,
            :func:`fusiongs.events.thresholds.calibration_event_weights`); None counts each once.

    Returns:
        ``[H, W, C]`` float32 linear image at ``(t_start + t_end) / 2`` (not clipped).
    """
    b = _check_frame(frame_linear, events)
    if theta is None:
        theta = estimate_theta(frame_linear, events, t_start, t_end, n_samples)
    counts = event_count_samples(events, t_start, t_end, n_samples, weights)
    return (b / edi_ratio(counts, theta, events.cfa)).astype(np.float32)


def check_scene(scene) -> None:
    """Raise :class:`InputError` unless ``scene`` has events and at least one frame (what EDI needs)."""
    if scene.events is None or len(scene.events) == 0:
        raise InputError("edi", "events", "a scene with an event stream", "none")
    if len(scene.frames) == 0:
        raise InputError("edi", "frames", "a scene with at least one frame", "none")


def edi_scene(scene, theta, n_samples: int = EDI_SAMPLES, reset_weights: bool = True) -> np.ndarray:
    """EDI-deblur every frame of a :class:`~fusiongs.io.scene.Scene`.

    Args:
        scene: a scene with events and frames.
        theta: threshold, ``(theta_pos, theta_neg)`` pair or :class:`SensorThresholds` (per CFA
            channel), e.g. from :func:`fusiongs.calibrate.estimate.estimate_thresholds`.
        n_samples: instants per exposure.
        reset_weights: where the thresholds are a calibration that chose the pixel model of a
            pixel held in reset, count each event as the crossings it stands for, as the
            calibration and ``deblur`` do
            (:func:`fusiongs.events.thresholds.calibration_event_weights`); plain numbers, and
            calibrations of the step model, count each event once either way.

    Returns:
        ``[F, H, W, C]`` float32 linear images at the frames' mid-exposure times.

    Raises:
        InputError: no events or no frames, or a reset calibration with an invalid dead time.
    """
    check_scene(scene)
    fs = scene.frames
    weights = calibration_event_weights(scene.events, theta) if reset_weights else None
    lin = fs.to_linear()
    out = [edi_deblur(lin[i], scene.events, float(fs.t_start[i]), float(fs.t_end[i]), theta,
                      n_samples, weights) for i in range(len(fs))]  # loop over frames, not pixels
    return np.stack(out)
