"""Small plotting helpers for the notebooks: event frames, CFA masks, HPF traces, image strips.

Image helpers (``event_frame``, ``cfa_mask_image``, ``to_rgb8``) return ``[H, W, 3]`` uint8 RGB
arrays and need only numpy. Plot helpers (``strip``, ``hpf_traces``, ``event_rate``,
``line_plot``) return matplotlib Figures; matplotlib is an optional dependency (the ``notebooks``
extra) imported when a plot is made. Figures are made with pyplot, so a notebook shows them
inline; in a script save them with ``fig.savefig(...)`` and free them with ``plt.close(fig)``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from fusiongs.errors import InputError, MissingDependencyError
from fusiongs.events.cfa import cfa_channel_index
from fusiongs.events.stream import EventStream

ON_RGB = (214, 39, 40)  # red: brightness increase
OFF_RGB = (31, 119, 180)  # blue: brightness decrease
_FILTER_RGB = np.array([(220, 40, 40), (40, 170, 40), (40, 80, 230)], dtype=np.uint8)


def _pyplot():
    """``matplotlib.pyplot``, or a :class:`MissingDependencyError` naming the extra to install."""
    try:
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingDependencyError("matplotlib", "plotting with fusiongs.viz", "notebooks") from None
    return plt


def to_rgb8(img: np.ndarray) -> np.ndarray:
    """Any displayable image as ``[H, W, 3]`` uint8.

    Args:
        img: ``[H, W]``, ``[H, W, 1]`` or ``[H, W, 3]``; uint8 as is, uint16 scaled by 1/257,
            floats taken as values in [0, 1] (clipped).

    Returns:
        ``[H, W, 3]`` uint8 (a new array).
    """
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] != 3:
        raise InputError("to_rgb8", "img", "an image [H, W], [H, W, 1] or [H, W, 3]", a.shape)
    if a.dtype == np.uint8:
        return a.copy()
    if a.dtype == np.uint16:
        return (a // 257).astype(np.uint8)
    return np.rint(np.clip(np.nan_to_num(a.astype(np.float64)), 0.0, 1.0) * 255.0).astype(np.uint8)


def event_frame(events: EventStream, t0_us: int | None = None, t1_us: int | None = None, *,
                mask: np.ndarray | None = None, clip: float | None = None) -> np.ndarray:
    """Picture of the events in ``[t0_us, t1_us)``: ON pixels red, OFF pixels blue, none white.

    The colour of a pixel follows the sign of its signed count (ON minus OFF); its saturation the
    magnitude, scaled so that ``clip`` events (default: the 99th percentile of the non-zero
    magnitudes) or more are fully saturated.

    Args:
        events: time-sorted stream.
        t0_us, t1_us: window in microseconds (the whole stream when both are ``None``).
        mask: optional ``[H, W]`` bool; pixels outside it are drawn light grey (e.g. one CFA
            channel's pixels, from :func:`fusiongs.events.cfa.cfa_masks`).
        clip: count drawn fully saturated.

    Returns:
        ``[H, W, 3]`` uint8 RGB.
    """
    h, w = events.height, events.width
    if mask is not None and np.shape(mask) != (h, w):
        raise InputError("event_frame", "mask", f"a bool array of the sensor size [{h}, {w}]",
                         np.shape(mask))
    signed = events.signed_count_map(t0_us, t1_us).astype(np.float64)
    mag = np.abs(signed)
    if clip is None:
        nz = mag[mag > 0] if mask is None else mag[(mag > 0) & mask]
        clip = float(np.percentile(nz, 99)) if nz.size else 1.0
    s = np.clip(mag / max(float(clip), 1e-12), 0.0, 1.0)[..., None]
    colour = np.where((signed > 0)[..., None], np.array(ON_RGB, np.float64), np.array(OFF_RGB, np.float64))
    out = 255.0 * (1.0 - s) + colour * s
    if mask is not None:
        out = np.where(np.asarray(mask, bool)[..., None], out, 225.0)
    return np.rint(out).astype(np.uint8)


def cfa_mask_image(pattern: str, height: int, width: int) -> np.ndarray:
    """``[H, W, 3]`` uint8 picture of a Bayer filter: every pixel in its filter's colour."""
    return _FILTER_RGB[cfa_channel_index(pattern, height, width).astype(np.int64)]


def strip(images: Sequence[np.ndarray], titles: Sequence[str] | None = None, *,
          height_in: float = 2.6, suptitle: str | None = None):
    """A row of images with titles.

    Args:
        images: ``K`` images, each ``[H, W]``, ``[H, W, 1]`` or ``[H, W, 3]`` (see :func:`to_rgb8`);
            sizes may differ.
        titles: ``K`` titles (or ``None``).
        height_in: figure height in inches.
        suptitle: optional title over the row.

    Returns:
        a matplotlib Figure with ``K`` axes.
    """
    if len(images) == 0:
        raise InputError("strip", "images", "at least one image", "none")
    if titles is not None and len(titles) != len(images):
        raise InputError("strip", "titles", f"{len(images)} titles, one per image", len(titles))
    plt = _pyplot()
    rgb = [to_rgb8(im) for im in images]
    aspect = sum(im.shape[1] / im.shape[0] for im in rgb)
    fig, axes = plt.subplots(1, len(rgb), figsize=(max(2.0, height_in * aspect), height_in + 0.4),
                             squeeze=False)
    for k, (ax, im) in enumerate(zip(axes[0], rgb)):
        ax.imshow(im, interpolation="nearest")
        ax.set_axis_off()
        if titles is not None:
            ax.set_title(titles[k], fontsize=9)
    if suptitle:
        fig.suptitle(suptitle, fontsize=10)
    fig.tight_layout()
    return fig


def hpf_traces(events: EventStream, pixels: Sequence[tuple[int, int]], t0_us: float, t1_us: float, *,
               tau: float = 0.05, contrast: float = 0.2, n_samples: int = 500):
    """High-pass-filtered photovoltage ``V(t)`` of a few pixels, with their events as ticks.

    Uses :func:`fusiongs.events.hpf.high_pass_filter` on the chosen pixels' events only (so the
    read-out costs ``O(n_samples x len(pixels))``, not the whole sensor).

    Args:
        events: time-sorted stream.
        pixels: ``(x, y)`` pixel coordinates.
        t0_us, t1_us: plotted time range in microseconds (the filter starts at rest at ``t0_us``).
        tau: filter time constant (s). contrast: per-event step ``C``.
        n_samples: read-out instants.

    Returns:
        a matplotlib Figure (one axis; time in seconds).
    """
    from fusiongs.events.hpf import high_pass_filter

    if not t1_us > t0_us:
        raise InputError("hpf_traces", "t0_us/t1_us", "t1_us > t0_us", (t0_us, t1_us))
    xy = np.asarray(pixels, dtype=np.int64).reshape(-1, 2)
    bad = (xy[:, 0] < 0) | (xy[:, 0] >= events.width) | (xy[:, 1] < 0) | (xy[:, 1] >= events.height)
    if xy.shape[0] == 0 or bad.any():
        raise InputError("hpf_traces", "pixels", f"(x, y) pixels inside {events.width}x{events.height}",
                         xy[bad].tolist() if bad.any() else "none")
    if np.unique(xy, axis=0).shape[0] != xy.shape[0]:
        raise InputError("hpf_traces", "pixels", "distinct (x, y) pixels", xy.tolist())
    sub = events.slice_time(int(np.floor(t0_us)), int(np.ceil(t1_us)))
    flat = sub.y.astype(np.int64) * events.width + sub.x
    key = xy[:, 1] * events.width + xy[:, 0]
    order = np.argsort(key, kind="stable")
    pos = np.searchsorted(key[order], flat)
    hit = (pos < key.size) & (key[order][np.minimum(pos, key.size - 1)] == flat)
    col = order[np.minimum(pos, key.size - 1)][hit]  # index into ``pixels`` of each kept event
    picked = EventStream(sub.t[hit], col.astype(np.uint16), np.zeros(col.size, np.uint16), sub.p[hit],
                         int(key.size), 1, None)
    times = np.linspace(t0_us, t1_us, n_samples)
    v = high_pass_filter(picked, times, tau, contrast)[:, 0, :]  # [R, P]
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 3))
    lo, span = float(v.min()), float(np.ptp(v)) or 1.0
    for k, (x, y) in enumerate(xy.tolist()):
        (line,) = ax.plot(times * 1e-6, v[:, k], lw=1.2, label=f"pixel ({x}, {y})")
        sel = col == k
        row = lo - 0.12 * span * (k + 1)  # one row of ticks per pixel under the curves
        for sign, marker in ((1, "^"), (-1, "v")):
            ts = picked.t[sel & (picked.p == sign)] * 1e-6
            ax.plot(ts, np.full(ts.shape, row), marker, color=line.get_color(), ms=4, ls="none")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"V (log units, C = {contrast:g})")
    ax.set_title(f"high-pass filtered events, tau = {tau:g} s (markers: ON ^ / OFF v events)", fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig


def event_rate(events: EventStream, bin_s: float = 0.01, *, exposures=None):
    """ON and OFF event rates over time, with optional exposure windows shaded.

    Args:
        events: the stream.
        bin_s: histogram bin width in seconds.
        exposures: optional ``(t_start [F], t_end [F])`` in seconds (e.g. a FrameSet's).

    Returns:
        a matplotlib Figure (time in seconds, rate in events per second).
    """
    if not bin_s > 0:
        raise InputError("event_rate", "bin_s", "a positive bin width in seconds", bin_s)
    plt = _pyplot()
    t = events.t * 1e-6
    lo, hi = (float(t[0]), float(t[-1])) if len(events) else (0.0, 1.0)
    edges = np.arange(lo, hi + bin_s, bin_s)
    if edges.size < 2:
        edges = np.array([lo, lo + bin_s])
    fig, ax = plt.subplots(figsize=(8, 2.8))
    for sign, name, rgb in ((1, "ON", ON_RGB), (-1, "OFF", OFF_RGB)):
        n, _ = np.histogram(t[events.p == sign], edges)
        ax.step(edges[:-1], n / bin_s, where="post", color=np.array(rgb) / 255, label=name)
    if exposures is not None:
        for k, (s, e) in enumerate(zip(*exposures)):
            ax.axvspan(s, e, color="0.5", alpha=0.25, lw=0, label="exposures" if k == 0 else None)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("events / s")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    return fig


def line_plot(series: Mapping[str, tuple[Sequence[float], Sequence[float]]], *, title: str = "",
              xlabel: str = "", ylabel: str = ""):
    """Curves ``name -> (x, y)`` on one axis; returns a matplotlib Figure."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3))
    for name, (x, y) in series.items():
        ax.plot(x, y, label=name)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if series:
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
