"""Training tensors prepared once from a :class:`~fusiongs.io.scene.Scene`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import kornia
import numpy as np
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError
from fusiongs.events.stream import EventStream
from fusiongs.io.scene import Scene
from fusiongs.losses.colour import cfa_index


@dataclass(eq=False)
class TrainData:
    """What the training step reads.

    Attributes:
        camera: the shared pinhole camera.
        targets: ``[F, H, W, C]`` float32 frames as stored (encoded by ``response``), C = 1 or 3.
        response: the frames' response curve name.
        exposures: ``[F, 2]`` float64 exposure windows (s).
        names: frame stems.
        events: the event stream or None.
        cfa_index: ``[H, W]`` int64 CFA channel per pixel (0 R, 1 G, 2 B) for colour events.
        t_range: ``(t0, t1)`` seconds where both events (if any) and the trajectory are defined.
        frame_interval: median spacing of frame mid-times (s), or the range when < 2 frames.
        event_index: ``[E]`` int32 flat index ``p * H * W + y * W + x`` of every event (p = 0 ON,
            1 OFF) on the training device, for :meth:`count_maps` and :meth:`cumulative_counts`;
            None without events.

    Host and device: ``exposures``, ``hpf_times`` and ``pvc_times`` stay on the host (the step's
    times are drawn there and moved to the device explicitly); images and maps live on the device.
    """

    camera: PinholeCamera
    targets: torch.Tensor
    response: str
    exposures: torch.Tensor
    names: tuple[str, ...]
    events: EventStream | None
    cfa_index: torch.Tensor | None
    t_range: tuple[float, float]
    frame_interval: float
    edi: torch.Tensor | None = None  # [F, H, W, 3] linear EDI images for the prior, or None
    hpf_times: torch.Tensor | None = None  # [G] float64 s: read-outs of the HPF intensity images
    hpf: torch.Tensor | None = None  # [G, H, W, 1] HPF log-intensity images (event-only anchor)
    pvc_times: torch.Tensor | None = None  # [R] float64 s: read-outs of the pvc targets
    pvc: torch.Tensor | None = None  # [R, H, W] float32 photovoltage V(t)/θ0 (count units)
    event_index: torch.Tensor | None = None  # [E] int32 flat (polarity, pixel) index, on the device
    fast: torch.Tensor | None = None  # [E] bool: a fast event (censored counts), on the device
    event_weight: torch.Tensor | None = None  # [E] float32 crossings per event (reset pixel), or None
    hot: torch.Tensor | None = None  # [H, W] bool hot pixels (train/lowpass_term.py), on the device
    lowpass_support: tuple[float, torch.Tensor] | None = None  # (sigma, [C, H, W]) lowpass_term.py

    _coarse: dict = field(default_factory=dict, repr=False)  # factor -> (camera, targets)

    def coarse(self, factor: int) -> tuple[PinholeCamera, torch.Tensor]:
        """The camera and frames at ``1/factor`` resolution: ``(camera, [F, H//f, W//f, C])``.

        Frames are averaged over ``factor x factor`` blocks in linear light (then re-encoded), so
        a coarse pixel is the mean irradiance of the full-resolution pixels it covers; the coarse
        camera covers the first ``f * (W // f)`` columns and ``f * (H // f)`` rows exactly.
        """
        if factor not in self._coarse:
            self._coarse[factor] = (coarse_camera(self.camera, factor),
                                    downsample_frames(self.targets, self.response, factor))
        return self._coarse[factor]

    @property
    def n_frames(self) -> int:
        return int(self.targets.shape[0])

    def count_maps(self, t_a: float, t_b: float, device: torch.device) -> torch.Tensor:
        """``[2, H, W]`` float32 counts of (+, −) events with ``t_a <= t < t_b`` (seconds), each
        event counted ``event_weight`` times when set (a reset pixel's crossings).

        The window's index range comes from a binary search of the host timestamps; the counting
        is an ``index_add`` on ``event_index``'s device (no host copy, no synchronisation).
        """
        if self.events is None:
            raise RuntimeError("count_maps needs events (TrainData.events is None)")
        h, w = self.events.height, self.events.width
        return self._window_sum(t_a, t_b, device, self.event_weight).reshape(2, h, w).to(device)

    def _window_sum(self, t_a: float, t_b: float, device: torch.device,
                    weights: torch.Tensor | None = None) -> torch.Tensor:
        """``[2 H W]`` float32 sum over the events with ``t_a <= t < t_b`` (seconds) of 1, or of
        ``weights[i]`` (``[E]``, on ``event_index``'s device), at each event's (polarity, pixel)
        slot: the window's index range from a binary search of the host timestamps, then an
        ``index_add`` on ``event_index``'s device (no host copy, no synchronisation)."""
        if self.event_index is None:
            self.event_index = event_indices(self.events, device)
        i0, i1 = self.events.index_range(int(round(t_a * 1e6)), int(round(t_b * 1e6)))
        idx = self.event_index[i0:i1]
        src = (torch.ones(idx.shape[0], dtype=torch.float32, device=idx.device) if weights is None
               else weights[i0:i1].to(torch.float32))
        h, w = self.events.height, self.events.width
        out = torch.zeros(2 * h * w, dtype=torch.float32, device=idx.device)
        return out.index_add_(0, idx, src)

    def cumulative_counts(self, times: list[float], device: torch.device
                          ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Counts from ``times[0]`` to each of ``times`` (seconds, ascending), for many windows
        between these instants at once.

        Returns:
            ``(counts [K, 2, H*W], fast [K, H*W] | None)`` float32 on ``device``: the (+, −)
            events with ``times[0] <= t < times[k]`` (``event_weight`` each when set), and the
            fast events (:func:`fast_events`)
            of either polarity among them (None when none were marked); row 0 is zero. Row ``b``
            minus row ``a`` is :meth:`count_maps` ``(times[a], times[b])`` exactly (integer sums
            in float32), and the fast row difference is :meth:`censored_map`'s sum before its
            threshold. The events of ``[times[0], times[-1])`` are added once, segment by segment
            (:meth:`_window_sum`), where a window at a time adds up each long window's events
            again.
        """
        if self.events is None:
            raise RuntimeError("cumulative_counts needs events (TrainData.events is None)")
        h, w = self.events.height, self.events.width
        segments = list(zip(times[:-1], times[1:]))  # each segment's events once, into its own row
        maps = [[self._window_sum(a, b, device, self.event_weight) for a, b in segments]]
        if self.fast is not None:
            maps.append([self._window_sum(a, b, device, self.fast) for a, b in segments])
        rows = []
        for segs in maps:  # row 0 is zero: nothing between times[0] and itself
            zero = torch.zeros(1, 2 * h * w, dtype=torch.float32, device=device)
            rows.append(torch.cat([zero, *(seg[None].to(device) for seg in segs)]).cumsum(0))
        counts = rows[0].reshape(len(times), 2, h * w)
        fast = None if self.fast is None else rows[1][:, :h * w] + rows[1][:, h * w:]
        return counts, fast

    def censored_map(self, t_a: float, t_b: float, radius: int = 0) -> torch.Tensor | None:
        """``[H, W]`` bool: pixels with a fast event (:func:`fast_events`) in ``[t_a, t_b)``
        seconds, or within ``radius`` pixels (Chebyshev) of one, whose counts there are lower
        bounds; None when no fast events were marked.

        The neighbours count because an edge faster than the dead time leaves single events on
        pixels it crosses (no fast pair there) while its neighbours show the pairs. The window's
        fast events are added up as :meth:`count_maps` adds its events (one byte an event
        resident; no selection, so no host synchronisation)."""
        if self.fast is None or self.events is None:
            return None
        h, w = self.events.height, self.events.width
        out = self._window_sum(t_a, t_b, self.fast.device, self.fast)
        out = (out[:h * w] + out[h * w:]).reshape(1, 1, h, w)
        return square_dilate(out[0, 0], radius) > 0


def square_dilate(x: torch.Tensor, radius: int) -> torch.Tensor:
    """``[..., H, W]`` maximum of non-negative maps ``x`` over each pixel's ``(2 radius + 1)^2``
    square (zero outside the map), i.e. ``max_pool2d(x, 2 radius + 1, stride=1, padding=radius)``,
    by kornia's grey dilation (0.22 against 0.48 ms a 173x130 map on one CPU thread)."""
    if radius <= 0:
        return x
    kernel = torch.ones(2 * radius + 1, 2 * radius + 1, dtype=x.dtype, device=x.device)
    maps = x.reshape(-1, 1, *x.shape[-2:])
    return kornia.morphology.dilation(maps, kernel, border_type="constant", border_value=0.0).reshape(x.shape)


def fast_events(events: EventStream, gap_us: float, device: torch.device) -> torch.Tensor:
    """``[E]`` bool on ``device``: the event follows its pixel's previous event by less than
    ``gap_us`` (where the sensor's refractory period may have swallowed events,
    :func:`~fusiongs.events.stats.fast_event_mask`)."""
    from fusiongs.events.stats import fast_event_mask

    return torch.from_numpy(fast_event_mask(events, gap_us)).to(device)


def event_indices(events: EventStream, device: torch.device) -> torch.Tensor:
    """``[E]`` int32 flat index ``p * H * W + y * W + x`` of each event (p = 0 ON, 1 OFF) on
    ``device``: what :meth:`TrainData.count_maps` adds up (the layout of
    :meth:`EventStream.count_maps`)."""
    from fusiongs.events._kernels import flat_index

    hw = events.height * events.width
    if 2 * hw > np.iinfo(np.int32).max:
        raise InputError("events", "width/height", "a sensor of fewer than 2**30 pixels", hw)
    flat = np.empty(len(events), np.int32)  # one pass, no int64 temporaries (1e8 events: 0.8 GB each)
    flat_index(events.x, events.y, events.p, events.width, hw, flat)
    return torch.from_numpy(flat).to(device)


def coarse_camera(camera: PinholeCamera, factor: int) -> PinholeCamera:
    """``camera`` with pixels ``factor`` times larger (size floored; exact scale ``1/factor``)."""
    f = int(factor)
    return PinholeCamera(camera.width // f, camera.height // f, camera.fx / f, camera.fy / f,
                         camera.cx / f, camera.cy / f, camera.distortion)


def downsample_frames(frames: torch.Tensor, response: str, factor: int) -> torch.Tensor:
    """``[F, H, W, C]`` frames encoded by ``response`` -> ``[F, H//f, W//f, C]``, block means taken
    in linear light."""
    from fusiongs.frames.response import linear_to_response, response_to_linear

    return linear_to_response(block_mean(response_to_linear(frames, response), factor), response)


def block_mean(images: torch.Tensor, factor: int) -> torch.Tensor:
    """``[..., H, W, C]`` -> ``[..., H//f, W//f, C]``: means over ``f x f`` blocks (the last rows and
    columns that do not fill a block are dropped)."""
    f = int(factor)
    h, w = images.shape[-3] // f * f, images.shape[-2] // f * f
    x = images[..., :h, :w, :]
    lead = x.shape[:-3]
    x = x.reshape(-1, h, w, x.shape[-1]).permute(0, 3, 1, 2)
    small = torch.nn.functional.avg_pool2d(x, f).permute(0, 2, 3, 1).contiguous()
    return small.reshape(*lead, h // f, w // f, x.shape[1])


def edi_images(scene: Scene, theta, device: torch.device, reset_weights: bool = True) -> torch.Tensor:
    """``[F, H, W, 3]`` linear EDI images of the frames.

    Args:
        theta: :class:`~fusiongs.events.thresholds.SensorThresholds`, a threshold or an ON/OFF
            pair; 0 or None to estimate them (``fusiongs calibrate``'s estimator).
        reset_weights: count a reset pixel's events as the crossings they stand for where the
            calibration chose that model (``events.reset_weights``; see
            :func:`fusiongs.edi.edi_scene`).
    """
    from fusiongs.edi import check_scene, edi_scene

    if theta is None or (isinstance(theta, float | int) and theta == 0):
        from fusiongs.calibrate.estimate import estimate_thresholds

        check_scene(scene)
        theta = estimate_thresholds(scene.frames, scene.events)
    e = edi_scene(scene, theta=theta, reset_weights=reset_weights)
    if e.shape[-1] == 1:
        e = np.repeat(e, 3, axis=-1)
    return torch.from_numpy(np.clip(e, 0.0, None).astype(np.float32)).to(device)


def even_instants(t_range: tuple[float, float], n: int) -> np.ndarray:
    """``[max(n, 2)]`` float64 instants (s) evenly over ``t_range``, both ends included: where
    :func:`hpf_images` (and so :func:`event_stereo_images`) take their images."""
    return np.linspace(t_range[0], t_range[1], max(int(n), 2))


def hpf_images(events: EventStream, t_range: tuple[float, float], n: int, tau: float,
               theta0: float, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """HPF intensity images at ``n`` instants over ``t_range`` (Event-3DGS's intensity anchor).

    Returns:
        ``(times [n] float64 s, images [n, H, W, 1] float32 log units)``.
    """
    from fusiongs.events.hpf import high_pass_filter

    times = even_instants(t_range, n)
    v = high_pass_filter(events, times * 1e6, tau=tau, contrast=theta0)
    return torch.from_numpy(times), torch.from_numpy(v[..., None]).to(device)


def hpf_image_at(data: TrainData, t: float, tau: float, contrast: float) -> torch.Tensor:
    """``[H, W, 1]`` the HPF intensity image (:func:`hpf_images`, kept in ``data.hpf``) at any
    instant ``t`` (s) of ``data.t_range``: the read-out itself at a read-out instant, else the last
    read-out before ``t`` advanced by the events in between,
    ``V(t) ≈ e^{−Δ/τ} V(t_g) + C e^{−Δ/2τ} (N₊ − N₋)[t_g, t)`` with ``Δ = t − t_g``. The filter
    decays each of those events by ``e^{−(t − t_e)/τ}``; the midpoint's factor is off by at most
    ``1 − e^{−Δ/2τ}`` of their share (2.5 % for read-outs 5 ms apart and τ 50 ms).

    Args:
        tau, contrast: the filter's time constant (s) and per-event step (log units), those the
            read-outs were made with.
    """
    if data.hpf is None or data.hpf_times is None:
        raise RuntimeError("hpf_image_at needs TrainData.hpf (see fusiongs.train.data.hpf_images)")
    times = data.hpf_times
    g = max(int(np.searchsorted(times.cpu().numpy(), t, side="right")) - 1, 0)  # on the host
    dt = t - float(times[g])
    if dt <= 0.0:
        return data.hpf[g]
    h, w = data.camera.height, data.camera.width
    counts = data._window_sum(float(times[g]), t, data.hpf.device)  # [2 H W], each event once
    signed = (counts[: h * w] - counts[h * w:]).reshape(h, w, 1)
    return data.hpf[g] * math.exp(-dt / tau) + (contrast * math.exp(-0.5 * dt / tau)) * signed


def event_stereo_images(events: EventStream, t_range: tuple[float, float], n: int, tau: float,
                        theta0: float, colour: bool) -> torch.Tensor:
    """``[n, H, W, 1]`` float32 images in [0, 1] at ``n`` instants evenly over ``t_range`` (the
    instants :func:`fusiongs.train.state.build_state` poses an event-only scene's first Gaussians
    at) for the plane-sweep stereo of a scene without frames: ``0.5 · exp(V)`` of the HPF image
    ``V`` (log units, 0 where nothing fired lately). A moving edge leaves the same trail in views
    a few tens of milliseconds apart, shifted by its parallax, which is what the sweep matches.
    ``colour`` (a CFA sensor): a 2x2 box mean first, so that the mosaic of per-channel values
    does not look like texture.
    """
    _, v = hpf_images(events, t_range, n, tau, theta0, torch.device("cpu"))  # [n, H, W, 1]
    if colour:  # each output pixel mixes the four channels of a Bayer cell
        v = torch.nn.functional.avg_pool2d(torch.nn.functional.pad(v.permute(0, 3, 1, 2), (0, 1, 0, 1),
                                                                   mode="replicate"), 2, stride=1)
        v = v.permute(0, 2, 3, 1)
    return (0.5 * torch.exp(v)).clamp(0.0, 1.0).contiguous()


def pvc_readouts(events: EventStream, instants: np.ndarray, t_range: tuple[float, float],
                 spacing: float, tau: float, theta0: float, device: torch.device
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    """Photovoltage read-outs for the ``pvc`` event loss, computed once (one pass over the stream).

    Read-outs are taken at ``instants`` (e.g. every frame's exposure instants) and on a grid of
    ``spacing`` seconds over ``t_range``; a window's target is then ``pvc[b] - pvc[a]``
    (Event-3DGS photovoltage contrast, docs/method.md §2), free of the O(events) cost per window.

    Returns:
        ``(times [R] float64 s, maps [R, H, W] float32 V(t)/θ0)``.
    """
    from fusiongs.events.hpf import high_pass_filter

    n_grid = max(int(math.ceil((t_range[1] - t_range[0]) / spacing)) + 1, 2)
    times = np.unique(np.concatenate([np.asarray(instants, np.float64).reshape(-1),
                                      np.linspace(t_range[0], t_range[1], n_grid)]))
    v = high_pass_filter(events, times * 1e6, tau=tau, contrast=theta0) / theta0
    return torch.from_numpy(times), torch.from_numpy(v.astype(np.float32)).to(device)


def prepare_data(scene: Scene, device: torch.device, use_events: bool) -> TrainData:
    """Convert a scene into training tensors and check that it can be trained on.

    Raises:
        InputError: no trajectory (pose estimation is not part of this path yet), neither frames nor
            events, or exposures outside the trajectory's time range.
    """
    where = str(scene.root / "scene.json") if scene.root else "scene"
    if scene.poses is None:
        raise InputError(where, "trajectory", "a trajectory file (pose estimation from frames is "
                         "not available in this version)", "none")
    frames = scene.frames
    events = scene.events if use_events else None
    if events is not None and len(events) == 0:
        events = None
    if len(frames) == 0 and events is None:
        raise InputError(where, "frames/events", "at least one frame or a non-empty event stream")
    t_lo, t_hi = float(scene.poses.t[0]), float(scene.poses.t[-1])
    if events is not None:
        t_lo, t_hi = max(t_lo, events.t[0] * 1e-6), min(t_hi, events.t[-1] * 1e-6)
    exposures = np.stack([frames.t_start, frames.t_end], axis=1) if len(frames) else np.zeros((0, 2))
    if len(frames):
        bad = np.flatnonzero((exposures[:, 0] < scene.poses.t[0]) | (exposures[:, 1] > scene.poses.t[-1]))
        if bad.size:
            raise InputError(where, f"frames[{bad[0]}]", "an exposure inside the trajectory's time range "
                             f"[{scene.poses.t[0]}, {scene.poses.t[-1]}] s", exposures[bad[0]].tolist())
    mids = exposures.mean(axis=1) if len(frames) else np.zeros(0)
    interval = float(np.median(np.diff(mids))) if mids.size >= 2 else max(t_hi - t_lo, 1e-3)
    cfa = None
    if events is not None and events.cfa is not None:
        cfa = cfa_index(events.cfa, scene.camera.height, scene.camera.width, device=device)
    return TrainData(
        camera=scene.camera,
        targets=torch.from_numpy(np.ascontiguousarray(frames.images, dtype=np.float32)).to(device),
        response=frames.response,
        exposures=torch.from_numpy(exposures.astype(np.float64)),
        names=tuple(frames.names),
        events=events,
        cfa_index=cfa,
        t_range=(t_lo, t_hi),
        frame_interval=interval,
        event_index=None if events is None else event_indices(events, device),
    )
