"""Photovoltage contrast by a per-pixel high-pass filter of the event stream.

The filter of Scheerlinck et al. (ACCV 2018, "Continuous-time intensity estimation using event
cameras", cut-off ``1/tau``) as used by Event-3DGS (Han et al., NeurIPS 2024, tau = 0.05 s): each
pixel keeps ``(V, t_last)``; an event ``(t, p)`` does ``V <- exp(-(t - t_last)/tau) V + p C_p`` and
``t_last <- t``; a read-out at ``t*`` decays every pixel to ``t*``. Equivalently
``V(t*) = sum_{events e at the pixel, t_e < t*} p_e C_{p_e} exp(-(t* - t_e)/tau)``.

Read-outs count the events strictly before ``t*`` (half-open windows, like
:meth:`EventStream.count_maps`), so for ``tau -> inf`` and ``C = theta0`` :func:`hpf_contrast` over
``[t_a, t_b)`` equals the signed event count of that window.
"""

from __future__ import annotations

import numba
import numpy as np

from fusiongs.errors import InputError
from fusiongs.events.stream import EventStream


@numba.njit(cache=True, nogil=True)
def _hpf_kernel(t, pix, p, times, n_pix, tau_us, c_pos, c_neg):  # pragma: no cover - compiled
    out = np.zeros((times.shape[0], n_pix), dtype=np.float64)
    v = np.zeros(n_pix, dtype=np.float64)
    last = np.zeros(n_pix, dtype=np.float64)
    n = t.shape[0]
    i = 0
    for r in range(times.shape[0]):
        tr = times[r]
        while i < n and t[i] < tr:
            k = pix[i]
            ti = float(t[i])
            c = c_pos if p[i] > 0 else -c_neg
            v[k] = np.exp(-(ti - last[k]) / tau_us) * v[k] + c
            last[k] = ti
            i += 1
        for k in range(n_pix):
            if v[k] != 0.0:
                out[r, k] = np.exp(-(tr - last[k]) / tau_us) * v[k]
    return out


def _check(events: EventStream, times_us, tau: float, contrasts) -> np.ndarray:
    times = np.asarray(times_us, dtype=np.float64)
    if times.ndim != 1:
        raise InputError("high_pass_filter", "times_us", "a 1-D array of read-out times", times.shape)
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) < 0):
        raise InputError("high_pass_filter", "times_us", "finite read-out times sorted ascending")
    if not (np.isfinite(tau) and tau > 0):
        raise InputError("high_pass_filter", "tau", "a positive time constant in seconds", tau)
    for name, c in contrasts:
        if not (np.isfinite(c) and c > 0):
            raise InputError("high_pass_filter", name, "a positive contrast", c)
    return times


def high_pass_filter(events: EventStream, times_us, tau: float = 0.05, contrast: float = 0.2, *,
                     contrast_pos: float | None = None, contrast_neg: float | None = None
                     ) -> np.ndarray:
    """High-pass filtered photovoltage read out at given instants.

    One pass over the time-sorted events (compiled with numba), ``O(E + R H W)``.

    Args:
        events: time-sorted stream, ``H x W`` sensor.
        times_us: ``[R]`` read-out times in microseconds, sorted ascending (float allowed).
        tau: filter time constant in seconds (cut-off frequency ``1/tau``).
        contrast: per-event step ``C`` (log-intensity units), both polarities.
        contrast_pos, contrast_neg: separate positive steps for ON / OFF events (ON adds
            ``+contrast_pos``, OFF adds ``-contrast_neg``); default ``contrast``.

    Returns:
        ``[R, H, W]`` float32 ``V(t_r)`` from the events with ``t < t_r`` (state starts at 0).
    """
    cp = float(contrast if contrast_pos is None else contrast_pos)
    cn = float(contrast if contrast_neg is None else contrast_neg)
    times = _check(events, times_us, float(tau), (("contrast_pos", cp), ("contrast_neg", cn)))
    h, w = events.height, events.width
    i1 = int(np.searchsorted(events.t, times[-1], side="left")) if times.size else 0
    t = events.t[:i1]
    pix = events.y[:i1].astype(np.int64) * w + events.x[:i1]
    out = _hpf_kernel(t, pix, events.p[:i1], times, h * w, float(tau) * 1e6, cp, cn)
    return out.astype(np.float32).reshape(times.shape[0], h, w)


def hpf_contrast(events: EventStream, t_a_us: float, t_b_us: float, tau: float = 0.05,
                 theta0: float = 0.2, *, contrast: float | None = None) -> np.ndarray:
    """Target contrast between two read-outs, ``D_gt = (V(t_b) - V(t_a)) / theta0`` (Event-3DGS).

    Args:
        events: time-sorted stream.
        t_a_us, t_b_us: read-out times in microseconds, ``t_a_us <= t_b_us``.
        tau: filter time constant in seconds.
        theta0: contrast threshold the difference is divided by (count units).
        contrast: per-event step ``C`` of the filter; default ``theta0`` (then short windows give
            the signed event count).

    Returns:
        ``[H, W]`` float32 contrast in event-count units.
    """
    if not (np.isfinite(theta0) and theta0 > 0):
        raise InputError("hpf_contrast", "theta0", "a positive threshold", theta0)
    if not t_a_us <= t_b_us:
        raise InputError("hpf_contrast", "t_a_us/t_b_us", "t_a_us <= t_b_us", (t_a_us, t_b_us))
    c = theta0 if contrast is None else contrast
    v = high_pass_filter(events, [t_a_us, t_b_us], tau, c)
    return ((v[1].astype(np.float64) - v[0]) / theta0).astype(np.float32)
