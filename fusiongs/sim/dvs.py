"""A DVS (event camera) pixel model on densely sampled linear radiance.

Each pixel ``u`` fires an event of polarity ``p = +-1`` whenever its log intensity
``log(I_u(t) + eps)`` moves one threshold ``theta_p(u)`` away from the level stored at its last
event (the standard DVS model: Lichtsteiner et al., IEEE JSSC 2008; the simulator form with linear
interpolation between render samples follows ESIM, Rebecq et al., CoRL 2018). Between two render
samples the log intensity is interpolated linearly in time, so a step that crosses several levels
gives several events with interpolated timestamps. Per-pixel thresholds vary around distinct ON
and OFF nominal values; a refractory period drops events that follow the pixel's previous event too
closely. By default the stored level still advances by every crossing, so the dropped events' change
is lost but the level stays on its grid of thresholds (:func:`dvs_events`). With
``refractory_reset`` the pixel instead takes its level again when the refractory period ends, as
the reset switch of a physical pixel does (Lichtsteiner et al. 2008; :func:`dvs_events_reset`):
every change during the period is lost, and the next event needs a full threshold from the level
at the release. Background activity adds Poisson noise events. Grey sensors see ``I = w . L``
(Rec.601 weights), colour sensors one Bayer channel per pixel.

Two further non-idealities, both off by default:

- *Leak events* (junction leakage in the reset switch; model as in v2e, Hu, Liu & Delbruck,
  "v2e: From Video Frames to Realistic DVS Events", CVPR Workshops 2021): the stored reference level
  drifts down at ``r(u) * theta_on(u)`` log units per second, so a pixel looking at a static
  scene fires ON events at ``r(u)`` Hz. ``r(u)`` is log-normal over pixels with mean
  ``leak_rate_hz`` and a spread of ``leak_spread_decades`` decades (v2e's per-pixel rate mismatch;
  its per-step jitter is left out), and every pixel starts with its reference a uniform fraction
  of ``theta_on`` below the signal so that leak events are not synchronised. The drift is exact
  inside the event model (:func:`dvs_events` ``drift`` and ``ref0``): leak events interact with
  signal events and the refractory period as in a real pixel, with interpolated timestamps.
- *Hot pixels*: a fixed random set of ``round(hot_pixel_fraction * P)`` pixels fires Poisson
  events at ``hot_pixel_rate_hz`` each, whatever the scene does; the polarity is fixed per hot
  pixel (drawn ON or OFF with equal odds once), as a stuck pixel of a real sensor.

Background-activity and hot-pixel events are added after the pixel model and ignore its refractory
period (a Poisson hot pixel at 200 Hz would lose ~20 % of its events to a 1 ms dead time; this
model keeps them, so its hot-pixel rate is the rate seen in the stream).

Vectorised over pixels; the only Python loop is over time steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from fusiongs.events.cfa import cfa_channel_index

REC601 = (0.299, 0.587, 0.114)


@dataclass(frozen=True)
class DVSParams:
    """Event sensor parameters.

    Attributes:
        theta_on, theta_off: nominal ON / OFF contrast thresholds (log units).
        theta_sigma: standard deviation of the per-pixel threshold mismatch (log units).
        theta_min: smallest threshold a pixel may get after mismatch (the per-pixel draw is
            clamped there). With a nominal threshold of 0.1 and a spread of 0.05 about 16 % of the
            pixels sit at the clamp and the mean per-pixel threshold is ~0.004 above the nominal
            one; the simulator records the actual per-pixel means next to the nominal values.
        refractory_s: refractory period in seconds.
        ba_rate_hz: background-activity noise rate per pixel (Hz), half ON half OFF.
        eps: offset inside ``log(I + eps)`` (radiance units; scenes have radiance range ~1).
        theta_gradient: smooth spatial variation of the nominal thresholds: a factor
            ``1 + g (2 x / (W - 1) - 1)`` from the left to the right edge (0 = none); models a
            sensor whose thresholds vary across pixels (a learned threshold field can follow it).
        hot_pixel_fraction: fraction of pixels that are hot (0 = none).
        hot_pixel_rate_hz: event rate of each hot pixel (Hz), polarity fixed per pixel.
        leak_rate_hz: nominal leak (ON) event rate per pixel on a static scene (Hz, 0 = none).
        leak_spread_decades: standard deviation of the per-pixel leak rate in decades (log10).
        refractory_reset: the pixel takes its stored level again when its refractory period ends
            (a physical pixel's reset, :func:`dvs_events_reset`) instead of advancing it by every
            crossing (:func:`dvs_events`, the default).
    """

    theta_on: float = 0.25
    theta_off: float = 0.22
    theta_sigma: float = 0.03
    theta_min: float = 0.05
    refractory_s: float = 100e-6
    ba_rate_hz: float = 0.1
    eps: float = 1e-3
    theta_gradient: float = 0.0
    hot_pixel_fraction: float = 0.0
    hot_pixel_rate_hz: float = 200.0
    leak_rate_hz: float = 0.0
    leak_spread_decades: float = 0.1
    refractory_reset: bool = False


def sensor_log(rgb: torch.Tensor, cfa: str | None, eps: float) -> np.ndarray:
    """Log intensity each event pixel sees.

    Args:
        rgb: ``[H, W, 3]`` linear radiance.
        cfa: ``None`` (grey: Rec.601 weights) or a Bayer pattern name (one channel per pixel).
        eps: log offset.

    Returns:
        ``[H * W]`` float32 ``log(I + eps)``, row-major pixel order.
    """
    h, w, _ = rgb.shape
    if cfa is None:
        inten = rgb @ torch.tensor(REC601, dtype=rgb.dtype, device=rgb.device)
    else:
        idx = torch.as_tensor(cfa_channel_index(cfa, h, w).astype(np.int64), device=rgb.device)
        inten = torch.gather(rgb, 2, idx[..., None])[..., 0]
    return torch.log(inten.clamp_min(0) + eps).reshape(-1).cpu().numpy().astype(np.float32)


def pixel_thresholds(params: DVSParams, n_pixels: int, rng: np.random.Generator,
                     scale: float = 1.0, width: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ON and OFF thresholds ``[P]`` float64 (row-major pixels of a ``width``-wide sensor):
    ``scale * (nominal * ramp(x) + sigma * N(0, 1))`` with the ``theta_gradient`` ramp."""
    z = rng.standard_normal((2, n_pixels))
    ramp = 1.0
    if params.theta_gradient and width:
        x = (np.arange(n_pixels) % width) / max(width - 1, 1)
        ramp = 1.0 + params.theta_gradient * (2.0 * x - 1.0)
    on = np.maximum(params.theta_on * ramp + params.theta_sigma * z[0], params.theta_min) * scale
    off = np.maximum(params.theta_off * ramp + params.theta_sigma * z[1], params.theta_min) * scale
    return on, off


def count_events(logs: np.ndarray, theta_on: np.ndarray, theta_off: np.ndarray) -> int:
    """Number of threshold crossings (refractory period and noise ignored): cheap, for tuning.

    Args:
        logs: ``[K + 1, P]`` log intensity at the render instants. theta_on, theta_off: ``[P]``.
    """
    ref = logs[0].astype(np.float64)
    total = 0
    for k in range(1, logs.shape[0]):
        d = logs[k] - ref
        n_on = np.floor(np.maximum(d, 0) / theta_on)
        n_off = np.floor(np.maximum(-d, 0) / theta_off)
        ref = ref + n_on * theta_on - n_off * theta_off
        total += int(n_on.sum() + n_off.sum())
    return total


def dvs_events(logs: np.ndarray, times: np.ndarray, theta_on: np.ndarray, theta_off: np.ndarray,
               refractory_s: float, drift: np.ndarray | None = None,
               ref0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Events of all pixels from log intensities sampled at ``times``.

    Args:
        logs: ``[K + 1, P]`` float log intensity per render instant and pixel.
        times: ``[K + 1]`` float64 increasing instants (s).
        theta_on, theta_off: ``[P]`` float64 per-pixel thresholds (log units).
        refractory_s: refractory period (s); 0 disables it.
        drift: optional ``[P]`` leak: the stored reference level falls by ``drift`` log units per
            second (see :func:`leak_drift`); equivalently the signal gains ``drift * t``.
        ref0: optional ``[P]`` initial reference levels (default ``logs[0]``).

    Returns:
        ``t [E]`` int64 µs (sorted), ``pixel [E]`` int64 flat index, ``p [E]`` int8 +-1. Each pixel's
        reference level starts at ``ref0``; without refractory losses the signed sum of
        thresholds of a pixel's events stays within one threshold of its log change (plus
        ``drift * duration`` and ``logs[0] - ref0``).
    """
    n_pix = logs.shape[1]
    ref = (logs[0] if ref0 is None else ref0).astype(np.float64)
    t_last = np.full(n_pix, -np.inf)
    out_t, out_i, out_p = [], [], []
    for k in range(logs.shape[0] - 1):
        a, b = logs[k].astype(np.float64), logs[k + 1].astype(np.float64)
        if drift is not None:  # leak: a falling reference is a rising signal
            a, b = a + drift * (times[k] - times[0]), b + drift * (times[k + 1] - times[0])
        t0, dt = float(times[k]), float(times[k + 1] - times[k])
        d = b - ref
        n_on = np.floor(np.maximum(d, 0) / theta_on).astype(np.int64)
        n_off = np.floor(np.maximum(-d, 0) / theta_off).astype(np.int64)
        idx = np.flatnonzero(n_on + n_off)
        if idx.size == 0:
            continue
        up = n_on[idx] > 0
        n = np.where(up, n_on[idx], n_off[idx])
        sign = np.where(up, 1.0, -1.0)
        th = np.where(up, theta_on[idx], theta_off[idx])
        slope = (b[idx] - a[idx]) / dt  # log units per second, non-zero where events fire
        # First crossing time and spacing of the following crossings (linear in time).
        tau1 = t0 + np.clip((ref[idx] + sign * th - a[idx]) / slope, 0.0, dt)
        delta = th / np.abs(slope)
        ref[idx] += sign * n * th
        # Refractory: keep the first crossing >= t_last + r, then every stride-th one.
        if refractory_s > 0:
            j0 = 1 + np.maximum(0.0, np.ceil((t_last[idx] + refractory_s - tau1) / delta - 1e-9))
            j0 = np.minimum(j0, n + 1).astype(np.int64)
            stride = np.maximum(1, np.ceil(refractory_s / delta - 1e-9)).astype(np.int64)
        else:
            j0, stride = np.ones_like(n), np.ones_like(n)
        n_keep = np.where(j0 <= n, (n - j0) // stride + 1, 0)
        has = n_keep > 0
        if not has.any():
            continue
        last_j = j0 + (n_keep - 1) * stride
        t_last[idx[has]] = (tau1 + (last_j - 1) * delta)[has]
        # Expand pixels to events: the m-th kept event of a pixel is crossing j0 + m * stride.
        rep = np.repeat(np.arange(idx.size), n_keep)
        m = np.arange(rep.size) - np.repeat(np.cumsum(n_keep) - n_keep, n_keep)
        j = j0[rep] + m * stride[rep]
        tt = np.rint((tau1[rep] + (j - 1) * delta[rep]) * 1e6).astype(np.int64)
        order = np.argsort(tt, kind="stable")
        out_t.append(tt[order])
        out_i.append(idx[rep][order])
        out_p.append(sign[rep][order].astype(np.int8))
    if not out_t:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int8)
    return np.concatenate(out_t), np.concatenate(out_i), np.concatenate(out_p)


def dvs_events_reset(logs: np.ndarray, times: np.ndarray, theta_on: np.ndarray, theta_off: np.ndarray,
                     refractory_s: float, drift: np.ndarray | None = None,
                     ref0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Events of all pixels whose stored level is taken again when the refractory period ends.

    A pixel fires when its log intensity (linear in time between render samples) moves one
    threshold from its stored level; it is then blind for ``refractory_s`` and, at the release,
    stores the log intensity of that instant (the reset switch of a DVS pixel, Lichtsteiner et al.,
    IEEE JSSC 2008), so every change during the blind time is lost. Without a refractory period
    the events are those of :func:`dvs_events`.

    Args and returns: as :func:`dvs_events`.
    """
    n_pix = logs.shape[1]
    ref = (logs[0] if ref0 is None else ref0).astype(np.float64)
    release = np.full(n_pix, -np.inf)  # end of each pixel's blind time (s)
    th_on, th_off = np.asarray(theta_on, np.float64), np.asarray(theta_off, np.float64)
    out_t, out_i, out_p = [], [], []
    for k in range(logs.shape[0] - 1):
        a, b = logs[k].astype(np.float64), logs[k + 1].astype(np.float64)
        if drift is not None:  # leak: a falling reference is a rising signal
            a, b = a + drift * (times[k] - times[0]), b + drift * (times[k + 1] - times[0])
        t0, t1 = float(times[k]), float(times[k + 1])
        slope = (b - a) / (t1 - t0)
        freed = np.flatnonzero((release > t0) & (release <= t1))
        ref[freed] = a[freed] + slope[freed] * (release[freed] - t0)
        start = np.maximum(release, t0)
        cand = np.flatnonzero((start < t1) & ((b - ref >= th_on) | (ref - b >= th_off)))
        while cand.size:
            sl = slope[cand]
            safe = np.where(sl == 0, 1.0, sl)
            t_up = np.where(sl > 0, t0 + (ref[cand] + th_on[cand] - a[cand]) / safe, np.inf)
            t_dn = np.where(sl < 0, t0 + (ref[cand] - th_off[cand] - a[cand]) / safe, np.inf)
            te = np.maximum(np.minimum(t_up, t_dn), start[cand])
            fire = te <= t1
            idx, te = cand[fire], te[fire]
            if idx.size == 0:
                break
            pol = np.where(t_up[fire] <= t_dn[fire], 1, -1).astype(np.int8)
            out_t.append(np.rint(te * 1e6).astype(np.int64))
            out_i.append(idx)
            out_p.append(pol)
            release[idx] = te + refractory_s
            # the level at the release (at the event itself without a refractory period: one
            # threshold on); a release after t1 is taken again at its own step (``freed``)
            ref[idx] = a[idx] + slope[idx] * (np.minimum(release[idx], t1) - t0)
            again = release[idx] < t1
            cand = idx[again]
            start[cand] = release[cand]
    if not out_t:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int8)
    t, i, p = np.concatenate(out_t), np.concatenate(out_i), np.concatenate(out_p)
    order = np.argsort(t, kind="stable")
    return t[order], i[order], p[order]


def background_activity(rate_hz: float, n_pixels: int, t0_s: float, t1_s: float,
                        rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poisson background-activity noise: uniform in time and over pixels, random polarity.

    Returns:
        ``t [E]`` int64 µs (sorted), ``pixel [E]`` int64, ``p [E]`` int8.
    """
    n = int(rng.poisson(max(rate_hz, 0.0) * n_pixels * max(t1_s - t0_s, 0.0)))
    t = np.sort(rng.integers(int(round(t0_s * 1e6)), int(round(t1_s * 1e6)) + 1, size=n))
    pix = rng.integers(0, n_pixels, size=n)
    p = np.where(rng.random(n) < 0.5, 1, -1).astype(np.int8)
    return t.astype(np.int64), pix.astype(np.int64), p


def hot_pixel_events(fraction: float, rate_hz: float, n_pixels: int, t0_s: float, t1_s: float,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hot pixels: ``round(fraction * n_pixels)`` distinct random pixels, each firing Poisson events
    at ``rate_hz`` with one polarity per pixel (ON or OFF with equal odds).

    Returns:
        ``t [E]`` int64 µs (sorted), ``pixel [E]`` int64, ``p [E]`` int8.
    """
    n_hot = hot_pixel_count(fraction, n_pixels)
    if n_hot == 0 or rate_hz <= 0 or t1_s <= t0_s:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int8)
    hot = rng.choice(n_pixels, size=n_hot, replace=False).astype(np.int64)
    pol = np.where(rng.random(n_hot) < 0.5, 1, -1).astype(np.int8)
    counts = rng.poisson(rate_hz * (t1_s - t0_s), size=n_hot)
    t = rng.integers(int(round(t0_s * 1e6)), int(round(t1_s * 1e6)) + 1, size=int(counts.sum()))
    pix, p = np.repeat(hot, counts), np.repeat(pol, counts)
    order = np.argsort(t, kind="stable")
    return t[order].astype(np.int64), pix[order], p[order]


def hot_pixel_count(fraction: float, n_pixels: int) -> int:
    """Number of hot pixels of a sensor: ``round(fraction * n_pixels)`` (fraction clipped to [0, 1])."""
    return int(round(min(max(fraction, 0.0), 1.0) * n_pixels))


def leak_drift(params: DVSParams, theta_on: np.ndarray,
               rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Leak inputs of :func:`dvs_events` for per-pixel ON thresholds ``theta_on [P]``.

    Returns:
        ``drift [P]`` float64 log units per second (``rate(u) * theta_on(u)``, ``rate(u)`` the
        pixel's leak rate, log-normal with mean ``params.leak_rate_hz``) and ``phase [P]`` in [0, 1):
        start each reference ``phase * theta_on`` below the signal (``ref0 = logs[0] - phase *
        theta_on``) so that leak events of a static scene are spread over the first period.
    """
    n = theta_on.shape[0]
    z, phase = rng.standard_normal(n), rng.random(n)
    sd = params.leak_spread_decades * np.log(10.0)  # log-normal with mean leak_rate_hz
    rate = params.leak_rate_hz * np.exp(sd * z - sd**2 / 2)
    return rate * theta_on, phase


def merge_sorted(*streams: tuple[np.ndarray, np.ndarray, np.ndarray]):
    """Concatenate ``(t, pixel, p)`` triples and sort stably by time (earlier arguments first on ties)."""
    t = np.concatenate([s[0] for s in streams])
    order = np.argsort(t, kind="stable")
    pix = np.concatenate([s[1] for s in streams])[order]
    return t[order], pix, np.concatenate([s[2] for s in streams])[order]
