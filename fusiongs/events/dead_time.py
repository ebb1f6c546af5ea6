"""Sensor statistics the threshold calibration reads off the events: spatial hot pixels, the dead
time (refractory period) from the inter-event interval histogram, per-event reset weights, fast
events and the pixels' threshold spread."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusiongs.events.stream import EventStream


def spatial_hot_pixels(events: EventStream, factor: float = 5.0, floor: float = 20.0) -> np.ndarray:
    """``[H*W]`` bool: pixels whose event count is a spatial outlier among same-channel neighbours.

    A pixel is hot when its count exceeds ``factor`` times the median of its eight same-channel
    neighbours (distance 2 on a CFA, 1 on a grey sensor) plus ``floor``.
    """
    from scipy.ndimage import median_filter

    counts = events.pixel_counts().astype(np.float64)
    step = 1 if events.cfa is None else 2
    foot = np.zeros((2 * step + 1, 2 * step + 1), bool)
    foot[::step, ::step] = True
    foot[step, step] = False
    med = median_filter(counts, footprint=foot, mode="mirror")
    return (counts > factor * med + floor).reshape(-1)


def dead_time_us(events: EventStream, jump: float = 5.0, plateau: float = 1.5,
                 max_us: float = 10_000.0) -> float:
    """Estimated refractory period (µs) of the sensor: the floor of the distribution of intervals
    between consecutive events of the same pixel, where it is a step.

    A refractory period makes the interval histogram (log-spaced bins) jump at the dead time:
    below it only noise and hot-pixel events meet a pixel's previous event, above it every fast
    edge does. The estimate is the left edge of the first bin ``k`` holding ``jump`` times more
    intervals than the largest of the three bins before it, where bins ``k`` and ``k + 1`` together
    hold at least 0.5 % of all intervals (a dead time inside bin ``k`` splits the step over both)
    and bin ``k + 2`` holds at most ``plateau`` times the larger of them (a step, not a rise); 0
    when the histogram has no such step. Background activity that ignores the dead time fills the
    bins below it (measured on tuning scenes: a 3-5 Hz sensor's step is 10-15x, not 20x), while
    the smooth rise of a real DAVIS346's intervals (pixel bandwidth: none under 100 µs, then 2-6x
    more per bin from 1 ms on for several bins) is no step. A floor above ``max_us`` is not taken
    for a dead time: a texture moving at one speed over every pixel (the closed-form plane wave of
    :mod:`fusiongs.sim.plane_wave`: a floor at 36 ms) makes such a step with no refractory period
    at all, and a pixel that could fire only every 10 ms would miss almost any motion.

    A pixel that is held in reset during its dead time makes no step (its intervals are the dead
    time plus the time to a full threshold after the release): :func:`interval_floor` finds that
    floor too.
    """
    hist = _interval_hist(events)
    return 0.0 if hist is None else _step_us(*hist, jump, plateau, max_us)


def _interval_edges() -> np.ndarray:
    """``[B + 1]`` µs edges of the interval histogram: 16 log bins a decade from 1 µs to 0.1 s,
    rounded to the timestamps' unit."""
    return np.unique(np.round(np.geomspace(1.0, 1e5, 81)))


def _interval_hist(events: EventStream) -> tuple[np.ndarray, np.ndarray, int] | None:
    """``(counts [B + 2] float64, edges [B + 1] µs, intervals)`` of the same-pixel intervals on
    16 log bins a decade from 1 µs to 0.1 s (two empty bins appended), None below 100 intervals."""
    from fusiongs.events._kernels import interval_histogram

    if len(events) < 2:
        return None
    edges = _interval_edges()
    h, n_intervals = interval_histogram(events.t, events.x, events.y, events.width,
                                        events.height * events.width, edges)
    if n_intervals < 100:
        return None
    return np.concatenate([h.astype(np.float64), np.zeros(2)]), edges, int(n_intervals)


def _step_us(h: np.ndarray, edges: np.ndarray, n_intervals: int, jump: float, plateau: float,
             max_us: float) -> float:
    """The step rule of :func:`dead_time_us` on a histogram of :func:`_interval_hist`."""
    for k in range(1, len(h) - 2):
        if edges[k] > max_us:
            break
        before = h[max(0, k - 3):k].max()
        step = max(h[k], h[k + 1])  # a dead time inside bin k splits the step over k and k + 1
        if (h[k] > jump * (before + 1.0) and h[k] + h[k + 1] >= 0.005 * n_intervals
                and h[k + 2] <= plateau * step):
            return float(edges[k])
    return 0.0


def located_step_us(events: EventStream, step_us: float) -> float:
    """The refractory period (µs) of a pixel whose intervals step at it, located inside the
    histogram bin whose left edge ``step_us`` is (:func:`dead_time_us`; 0: no step, returned as is).

    The 16-a-decade bins bracket the dead time: their left edge lies up to 15 % below it (tuning
    scenes with a 0.97-0.99 ms dead time read 866 µs). Here the intervals from the bin before the
    step's to the one after the next are counted on 1 µs bins (the timestamps' unit), and the step
    is the split of that window into two Poisson rates, lower below and higher above, of the largest
    likelihood (a single change point; Raftery & Akman, Biometrika 1986), searched from the bin
    before the step's to the next bin's edge. On 99 tuning and 24 test scenes that
    step: within 0.7 µs of the simulator's dead time on all but one (median 0.2 µs;
    the bin's edge 13 % below it to 22 % above), tuning 4, whose 61 µs dead time the step rule
    had put two bins above (75 µs; located 77). ``step_us`` is returned when the window has no
    such split.

    The refractory gates and deblur's censoring keep ``step_us`` as their unit: measured in this
    located period at the same multiple (2) or at 1.75, the threshold estimates were worse on
    61 plain tuning scenes (11 outside 10 % against 7). It is what the
    sensor's refractory period is, and ``fusiongs calibrate`` reports it.
    """
    if step_us <= 0:
        return float(step_us)
    from scipy.special import xlogy

    from fusiongs.events._kernels import interval_histogram

    edges = _interval_edges()
    k = int(np.searchsorted(edges, step_us))
    lo, hi = float(edges[max(k - 1, 0)]), float(edges[min(k + 2, len(edges) - 1)])
    fine = np.arange(lo, hi + 1.0)
    if fine.size < 3:
        return float(step_us)
    h, _ = interval_histogram(events.t, events.x, events.y, events.width,
                              events.height * events.width, fine)
    cum = np.concatenate([[0.0], np.cumsum(h, dtype=np.float64)])
    total, bins = cum[-1], h.size
    split = np.arange(1, bins)  # the first 1 µs bin above the step
    split = split[fine[split] <= float(edges[min(k + 1, len(edges) - 1)])]
    n1, n2 = cum[split], total - cum[split]
    r1, r2 = n1 / split, n2 / (bins - split)
    ll = xlogy(n1, r1) + xlogy(n2, r2)
    ll[r2 <= r1] = -np.inf
    if not np.isfinite(ll).any():
        return float(step_us)
    return float(fine[split[int(np.argmax(ll))]])


def _onset_us(h: np.ndarray, edges: np.ndarray, n_intervals: int, rise: float, z: float, run: int,
              min_mass: float, max_us: float) -> float:
    """The onset rule of :func:`interval_floor` on a histogram of :func:`_interval_hist`."""
    width = np.diff(edges)
    cum = np.concatenate([[0.0], np.cumsum(h[:len(width)])])
    for k in range(4, len(width) - run):
        if edges[k] > max_us:
            break
        lo = int(np.searchsorted(edges, edges[k] / 4.0))
        base = (cum[k] - cum[lo]) / max(edges[k] - edges[lo], 1.0)  # intervals a µs below the bin
        want = base * width[k:k + run]
        above = (h[k:k + run] > rise * want) & (h[k:k + run] > want + z * np.sqrt(want + 1.0))
        if above.all() and cum[k + run] - cum[k] >= min_mass * n_intervals:
            return float(edges[k])
    return 0.0


@dataclass(frozen=True)
class IntervalFloor:
    """The floor of a sensor's same-pixel event intervals, and the kind of pixel it says.

    Attributes:
        step_us: the floor where the histogram steps up (:func:`dead_time_us`; 0: no step).
        onset_us: the floor where the interval density first rises well above the noise below it
            (0: none below ``max_us``).
    """

    step_us: float
    onset_us: float

    @property
    def reset(self) -> bool:
        """The density rises from its floor without a step, or steps only above it: the shape a
        pixel held in reset during its dead time makes (see :func:`interval_floor`), but also a
        scene whose fastest edge sets the floor; the intervals alone cannot tell the two apart
        (``fusiongs calibrate`` asks the frames, :class:`~fusiongs.calibrate.options.CalibrateOptions`
        ``pixel_model``)."""
        return self.onset_us > 0 and (self.step_us == 0 or self.step_us > self.onset_us)

    @property
    def dead_us(self) -> float:
        """The dead time (µs): the onset for a reset pixel, else the step (0: none)."""
        return self.onset_us if self.reset else self.step_us


def interval_floor(events: EventStream, jump: float = 5.0, plateau: float = 1.5,
                   max_us: float = 10_000.0, rise: float = 2.0, z: float = 5.0, run: int = 3,
                   min_mass: float = 1e-3) -> IntervalFloor:
    """Where a sensor's same-pixel event intervals begin, as a step and as an onset.

    Two pixel models lose events in a dead time ``d`` in different ways. A pixel whose reference
    level keeps moving with every threshold crossing while it is blind (``fusiongs simulate``'s
    default; also ESIM-like and v2e-like simulators, where the crossings wait for the release)
    fires again as soon as the dead time ends on a fast edge: its intervals pile up at ``d``, a
    step (:func:`dead_time_us`). A DVS pixel held in reset (Lichtsteiner et al., IEEE JSSC 2008;
    ``fusiongs simulate --refractory-reset``) stores the level at its release and needs a whole
    threshold after it: its intervals are ``d + theta / r`` at a log rate ``r``, so their density
    rises from ``d`` without a step. The onset is the left edge of the first of ``run`` bins whose
    every count exceeds ``rise`` times, and ``z`` Poisson deviations above, the mean density
    (intervals a µs) from a quarter of the bin's edge up to it (the noise floor: background
    activity that ignores the dead time), those bins holding at least ``min_mass`` of all
    intervals. Measured on the 173x130 tuning scenes: the
    onset is within one bin (15 %) of the true dead time on 16 of 17 (both pixel models; 1.45x on
    one sparse reset scene), and equals the step on every default-pixel scene; the real DAVIS346
    recordings have no step and an onset at 0.87-1.2 ms.

    Args:
        events: the time-sorted stream.
        jump, plateau, max_us: the step rule (:func:`dead_time_us`); ``max_us`` bounds both.
        rise, z, run, min_mass: the onset rule above.

    Returns:
        :class:`IntervalFloor` (zeros below 100 intervals).
    """
    hist = _interval_hist(events)
    if hist is None:
        return IntervalFloor(0.0, 0.0)
    return IntervalFloor(_step_us(*hist, jump, plateau, max_us),
                         _onset_us(*hist, rise, z, run, min_mass, max_us))


def reset_weights(events: EventStream, dead_us: float, cap: float = 4.0,
                  burst_end: bool = True) -> np.ndarray:
    """``[E]`` float32 weight of each event: the threshold crossings it stands for on a pixel held
    in reset during its dead time.

    Such a pixel (:func:`interval_floor`) is blind for ``d`` after each event and then stores the
    level of that instant, so every change during the blind time is lost. At a steady log rate
    ``r`` its events are ``Δt = d + theta / r`` apart and each stands for ``theta + r d`` of
    change, i.e. ``w = Δt / (Δt - d)`` thresholds, with ``Δt`` the interval to the pixel's previous
    event. Events at or under ``d`` after it (noise, hot pixels) and a pixel's first event weigh
    1; the weight is at most ``cap`` (an interval just above ``d``: the rate is not measured there).

    That weight counts the change lost in the blind time *before* an event. The blind time after a
    burst's last event is recorded by no later interval: the edge stops somewhere before the next
    event would have come. With ``burst_end``, an event followed by a slower one gets the
    difference: at its own rate the edge, ending at a uniformly random instant of the ``Δt`` that
    the next event would have needed, loses ``(w - 1)(1 - d / (2 Δt)) = (w^2 - 1) / (2 w)``
    thresholds in that blind time on average, of which the next event's weight ``w_next`` already
    counts ``w_next - 1``; the event gets ``max(0, (w^2 - 1) / (2 w) - (w_next - 1))`` more
    (``w_next`` = 1 for a pixel's last event). An event followed at the same rate gets nothing.
    Measured on the 12 reset-pixel tuning scenes: the
    calibration's mean error 5.5 → 4.8 %, and the frames' coefficient on the extra crossings moves
    toward its reset value 1 where it lay above.
    """
    from fusiongs.events._kernels import reset_weights as kernel

    out = np.ones(len(events), np.float32)
    if dead_us > 0 and len(events) > 1:
        kernel(events.t, events.x, events.y, events.width, events.height * events.width,
               float(dead_us), float(cap), bool(burst_end), out)
    return out


def fast_event_counts(events: EventStream, gap_us: float, edges_us: np.ndarray) -> np.ndarray:
    """``[len(edges) - 1, H*W]`` int32 number of events closer than ``gap_us`` to the previous event
    of the same pixel (:func:`fusiongs.events.stats.fast_event_mask`), per time segment
    ``[edges[j], edges[j+1])``."""
    from fusiongs.events._kernels import fast_counts

    hw = events.height * events.width
    out = np.zeros((len(edges_us) - 1, hw), np.int32)
    if gap_us <= 0 or len(events) < 2 or len(edges_us) < 2:
        return out
    fast_counts(events.t, events.x, events.y, events.width, hw, float(gap_us),
                np.asarray(edges_us, np.float64), out)
    return out


def fast_in_spans(events: EventStream, gap_us: float, spans: np.ndarray) -> np.ndarray:
    """``[S, H*W]`` bool: pixel has two events closer than ``gap_us`` inside span ``[a, b)``."""
    hw = events.height * events.width
    if gap_us <= 0 or len(spans) == 0:
        return np.zeros((len(spans), hw), bool)
    bounds = np.unique(spans.reshape(-1))
    seg = fast_event_counts(events, gap_us, bounds)  # [len(bounds) - 1, HW]
    cum = np.concatenate([np.zeros((1, hw), np.int64), np.cumsum(seg, axis=0)])
    a = np.searchsorted(bounds, spans[:, 0])
    b = np.searchsorted(bounds, spans[:, 1])
    return (cum[b] - cum[a]) > 0


def _robust_cov(a: np.ndarray, b: np.ndarray) -> float:
    """``(MAD(a + b)^2 - MAD(a - b)^2) / 4`` with 1.4826 MAD: the covariance of ``a`` and ``b`` for
    normal data, insensitive to a few outlying pairs."""
    def mad(v: np.ndarray) -> float:
        return 1.4826 * float(np.median(np.abs(v - np.median(v))))

    return (mad(a + b) ** 2 - mad(a - b) ** 2) / 4.0


def threshold_spread(events: EventStream, hot: np.ndarray, min_count: int = 5,
                     min_pixels: int = 200, weights: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Per-polarity variance of the pixels' log contrast thresholds ``[2]`` (ON, OFF), and the
    number of pixels each was measured on ``[2]`` int64.

    A moving camera sweeps nearly the same log signal over neighbouring pixels, so a pixel's count
    over a stretch of the recording divided by the mean count of its eight same-channel neighbours
    is about ``theta_neighbours / theta_pixel``: its log varies over pixels by the thresholds'
    mismatch, plus count noise and the scene's own differences. Taken on the first and on the
    second half of the recording, the count noise of the two halves is independent, so the
    covariance over pixels of the two log ratios keeps the mismatch (which both halves share) and
    drops the noise (robust form: :func:`_robust_cov`). The neighbours' mean carries their own
    mismatch, ``var / k`` for ``k`` neighbours, which is divided out. Scene differences that both halves share
    stay in: measured on tuning scenes with a large depth range the estimate's std is ~0.04 above
    the truth (0.20 for 0.16), elsewhere within ~0.03. Pixels with fewer than ``min_count``
    events in a half (their own or their neighbours' mean) are left out; a polarity measured on
    fewer than ``min_pixels`` pixels gets 0 (no correction).

    Args:
        events: the stream. hot: ``[H*W]`` bool hot pixels (left out, also as neighbours).
        weights: optional ``[E]`` crossings per event (:func:`reset_weights`) counted instead of 1.
    """
    from scipy.ndimage import convolve

    h, w = events.height, events.width
    if len(events) < 2:
        return np.zeros(2), np.zeros(2, np.int64)
    step = 1 if events.cfa is None else 2
    foot = np.zeros((2 * step + 1, 2 * step + 1))
    foot[::step, ::step] = 1.0
    foot[step, step] = 0.0
    ok = ~np.asarray(hot, bool).reshape(h, w)
    den = np.maximum(convolve(ok.astype(np.float64), foot, mode="mirror"), 1.0)
    t0, t1 = int(events.t[0]), int(events.t[-1]) + 1
    mid = t0 + (t1 - t0) // 2
    ratios, used = [], np.broadcast_to(ok, (2, h, w))
    for a, b in ((t0, mid), (mid, t1)):
        c = events.count_maps(a, b, weights).astype(np.float64)  # [2, H, W]
        m = np.stack([convolve(c[k] * ok, foot, mode="mirror") / den for k in range(2)])
        good = (c >= min_count) & (m >= min_count)
        ratios.append(np.log(np.where(good, c, 1.0) / np.where(good, m, 1.0)))
        used = used & good
    var, n = np.zeros(2), np.zeros(2, np.int64)
    for k in range(2):
        n[k] = int(used[k].sum())
        if n[k] >= min_pixels:
            cov = _robust_cov(ratios[0][k][used[k]], ratios[1][k][used[k]])
            var[k] = max(cov / (1.0 + float(np.mean(1.0 / den[used[k]]))), 0.0)
    return var, n
