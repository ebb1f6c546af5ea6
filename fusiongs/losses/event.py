"""Event losses on sampled pixels: rendered log change against event counts or HPF contrast.

An event pixel fires when its log intensity changes by ``p * theta_p`` (docs/method.md section 1), so
over a window ``(t_a, t_b]``: ``dlog I ~= theta_+ n_+ - theta_- n_-``. Three losses compare the
rendered log change ``d_hat = log(I(t_b) + eps) - log(I(t_a) + eps)`` with the events on ``P``
sampled pixels (docs/method.md section 3):

- *mse* (EventNeRF, Rudnev et al., CVPR 2023, Eq. 5; EvDeblurNeRF, Cannici & Scaramuzza, CVPR 2024):
  ``sum_c w_c (d_hat - (theta_+ n_+ - theta_- n_-))^2 / sum_c w_c``;
- *band* (Event-3DGS, Han et al., NeurIPS 2024, Eq. 15) in count units ``D_r = d_hat / theta``;
- *pvc*: band or mse against the photovoltage-contrast (high-pass filter) target ``D_gt``.

Shapes: ``P`` sampled pixels, ``C'`` channels of the comparison (1 for grey sensors and for colour
*mask* mode, 3 for colour *demosaic* mode). Thresholds, weights and targets broadcast to ``[P, C']``.
"""

from __future__ import annotations

from typing import Literal

import torch

from fusiongs.errors import InputError

REC601 = (0.299, 0.587, 0.114)


def to_grey(linear: torch.Tensor, weights: tuple[float, float, float] = REC601) -> torch.Tensor:
    """``[..., 1]`` grey ``w . L`` of ``[..., 3]`` linear radiance.

    The weights stay Python numbers: no weight tensor is made on the device per call (a
    ``torch.tensor(..., device=cuda)`` is a host copy that waits for the queued GPU work).
    """
    r, g, b = (float(w) for w in weights)
    return linear[..., 0:1] * r + linear[..., 1:2] * g + linear[..., 2:3] * b


def log_intensity(
    linear: torch.Tensor,
    mode: Literal["grey", "rgb"] = "grey",
    weights: tuple[float, float, float] = REC601,
    eps: float = 1e-3,
) -> torch.Tensor:
    """Log intensity an event pixel sees: ``log(w . L + eps)`` (grey) or ``log(L_c + eps)`` (rgb).

    Args:
        linear: ``[..., C]`` linear radiance (C = 3, or C = 1 for a grey render).
        mode: ``"grey"`` projects RGB with ``weights`` (Rec.601 by default); ``"rgb"`` keeps channels.
        weights: RGB weights of the grey sensor.
        eps: offset against log(0), ~1e-3 of the radiance range.

    Returns:
        ``[..., 1]`` (grey) or ``[..., C]`` (rgb) natural-log intensity.
    """
    if mode == "grey":
        if linear.shape[-1] == 3:
            linear = to_grey(linear, weights)
        elif linear.shape[-1] != 1:
            raise InputError("log_intensity", "linear", "[..., 3] or [..., 1]", tuple(linear.shape))
    elif mode != "rgb":
        raise InputError("log_intensity", "mode", "'grey' or 'rgb'", repr(mode))
    return torch.log(linear + eps)


def delta_log(
    linear_a: torch.Tensor,
    linear_b: torch.Tensor,
    mode: Literal["grey", "rgb"] = "grey",
    weights: tuple[float, float, float] = REC601,
    eps: float = 1e-3,
) -> torch.Tensor:
    """Rendered log change from window start ``t_a`` to end ``t_b``.

    Args:
        linear_a, linear_b: ``[..., C]`` linear renders (or sampled pixels) at ``t_a`` and ``t_b``.
        mode, weights, eps: as :func:`log_intensity`.

    Returns:
        ``[..., C']`` ``log I(t_b) - log I(t_a)``.
    """
    return log_intensity(linear_b, mode, weights, eps) - log_intensity(linear_a, mode, weights, eps)


def select_channel(values: torch.Tensor, channel_index: torch.Tensor) -> torch.Tensor:
    """Colour *mask* mode: keep each pixel's own CFA channel.

    Args:
        values: ``[..., P, 3]`` per-pixel three-channel values (e.g. rendered log change,
            thresholds), optionally with leading batch dimensions (several windows).
        channel_index: ``[P]`` int64 CFA channel of each sampled pixel (0 = R, 1 = G, 2 = B), e.g.
            ``cfa_channel_index(pattern, H, W).reshape(-1)[flat_idx]``.

    Returns:
        ``[..., P, 1]``.
    """
    index = channel_index.reshape(-1, 1).to(torch.int64)
    return values.gather(-1, index.expand(*values.shape[:-1], 1))


def _weighted_mean(per_elem: torch.Tensor, channel_weights: torch.Tensor | None) -> torch.Tensor:
    if channel_weights is None:
        return per_elem.mean()
    w = torch.as_tensor(channel_weights, dtype=per_elem.dtype, device=per_elem.device)
    w = w.expand_as(per_elem)
    return (w * per_elem).sum() / w.sum()


def censored_residual(residual: torch.Tensor, target: torch.Tensor, censored: torch.Tensor) -> torch.Tensor:
    """Residual of a count that is only a lower bound: zero when the prediction goes further.

    A pixel that fired faster than its refractory period allows lost events, so its count bounds
    the log change from below in the direction of the target's sign: ``|d_hat| >= |target|`` is
    consistent with it. Where ``censored`` (and the target is nonzero) only the shortfall
    ``sign(target) * r < 0`` is kept, the one-sided (Tobit) treatment of a censored observation
    (Tobin, Econometrica 1958); elsewhere the residual is unchanged.

    Args:
        residual: ``[P, C']`` ``d_hat - target``.
        target: ``[P, C']`` the count target ``theta_+ n_+ - theta_- n_-``.
        censored: bool broadcastable to ``[P, C']``.

    Returns:
        ``[P, C']`` residual.
    """
    short = torch.sign(target) * residual < 0
    keep = ~censored | (target == 0) | short
    return torch.where(keep, residual, torch.zeros_like(residual))


def event_loss_mse(
    delta_pred: torch.Tensor,
    n_pos: torch.Tensor,
    n_neg: torch.Tensor,
    theta_pos: torch.Tensor,
    theta_neg: torch.Tensor,
    channel_weights: torch.Tensor | None = None,
    censored: torch.Tensor | None = None,
) -> torch.Tensor:
    """Squared error of the log change against ``theta_+ n_+ - theta_- n_-`` (EventNeRF Eq. 5).

    ``sum_{p,c} w (d_hat - (theta_+ n_+ - theta_- n_-))^2 / sum_{p,c} w``: with per-channel weights
    ``[C']`` this is the mean over pixels of ``sum_c w_c r_c^2 / sum_c w_c``; with per-pixel
    weights ``[P, 1]`` (mask mode, :func:`fusiongs.losses.colour.channel_weights_for`) each pixel
    counts with its own channel's weight.

    Args:
        delta_pred: ``[P, C']`` rendered log change (natural log).
        n_pos, n_neg: ``[P, C']`` positive / negative event counts of the window (float).
        theta_pos, theta_neg: thresholds broadcastable to ``[P, C']`` (``[C']`` or ``[P, C']``).
        channel_weights: weights broadcastable to ``[P, C']``, or None for a plain mean.
        censored: bool broadcastable to ``[P, C']``: counts that are lower bounds (the pixel hit
            its refractory period in the window), compared one-sided (:func:`censored_residual`);
            None for none.

    Returns:
        Scalar loss in (log units)^2.
    """
    target = theta_pos * n_pos - theta_neg * n_neg
    r = delta_pred - target
    if censored is not None:
        r = censored_residual(r, target, censored)
    return _weighted_mean(r**2, channel_weights)


def band_penalty(d_r: torch.Tensor, d_gt: torch.Tensor, beta: float, zero_tol: float = 0.0,
                 censored: torch.Tensor | None = None) -> torch.Tensor:
    """Event-3DGS Eq. 15, elementwise, in count units.

    ``relu(|D_r - D_gt - beta| - beta)`` where ``D_gt > 0`` (zero for ``D_r`` in
    ``[D_gt, D_gt + 2 beta]``), ``relu(|D_gt - D_r - beta| - beta)`` where ``D_gt < 0`` (zero in
    ``[D_gt - 2 beta, D_gt]``) and ``relu(|D_r| - 1)`` where ``|D_gt| <= zero_tol``. Where
    ``censored`` (a count that is only a lower bound, see :func:`censored_residual`) the band is
    open on the far side: ``relu(D_gt - D_r)`` for ``D_gt > 0``, ``relu(D_r - D_gt)`` for
    ``D_gt < 0`` (only a shortfall is penalised).

    Args:
        d_r: ``[...]`` rendered change in count units.
        d_gt: ``[...]`` target count (signed event count or HPF contrast).
        beta: band half-width (0.5 for real data, 0 for clean synthetic data).
        zero_tol: ``|D_gt|`` at or below it counts as "no event" (0 for integer counts).
        censored: bool broadcastable to ``d_r``, or None for none.

    Returns:
        ``[...]`` non-negative penalty.
    """
    pos = torch.relu((d_r - d_gt - beta).abs() - beta)
    neg = torch.relu((d_gt - d_r - beta).abs() - beta)
    if censored is not None:
        pos = torch.where(censored, torch.relu(d_gt - d_r), pos)
        neg = torch.where(censored, torch.relu(d_r - d_gt), neg)
    zero = torch.relu(d_r.abs() - 1.0)
    return torch.where(d_gt.abs() <= zero_tol, zero, torch.where(d_gt > 0, pos, neg))


def polarity_theta(
    d_gt: torch.Tensor, delta_pred: torch.Tensor, theta_pos: torch.Tensor, theta_neg: torch.Tensor,
    zero_tol: float = 0.0,
) -> torch.Tensor:
    """Threshold converting a log change into count units, chosen per pixel by polarity.

    Where ``D_gt`` is nonzero its sign says which polarity produced the count, so ``theta_+`` is
    used where ``D_gt > 0`` and ``theta_-`` where ``D_gt < 0``; where ``|D_gt| <= zero_tol`` the
    sign of the rendered change ``d_hat`` picks the polarity whose band ``|d_hat| < theta_p`` it
    would have to cross.

    Returns:
        ``[P, C']`` positive thresholds.
    """
    sign = torch.where(d_gt.abs() <= zero_tol, delta_pred.detach(), d_gt)
    return torch.where(sign >= 0, theta_pos, theta_neg)


def event_loss_band(
    delta_pred: torch.Tensor,
    d_gt: torch.Tensor,
    theta_pos: torch.Tensor,
    theta_neg: torch.Tensor | None = None,
    beta: float = 0.5,
    channel_weights: torch.Tensor | None = None,
    zero_tol: float = 0.0,
    censored: torch.Tensor | None = None,
) -> torch.Tensor:
    """Event-3DGS band loss (Han et al., NeurIPS 2024, Eq. 15) with per-polarity thresholds.

    ``D_r = d_hat / theta`` with ``theta`` from :func:`polarity_theta`, then :func:`band_penalty`,
    averaged with ``channel_weights`` as in :func:`event_loss_mse`.

    Args:
        delta_pred: ``[P, C']`` rendered log change.
        d_gt: ``[P, C']`` target in count units (signed counts ``n+ - n-``, or HPF contrast).
        theta_pos, theta_neg: thresholds broadcastable to ``[P, C']``; ``theta_neg`` defaults to
            ``theta_pos`` (one threshold for both polarities, as Event-3DGS).
        beta: band half-width.
        channel_weights: weights broadcastable to ``[P, C']`` or None.
        zero_tol: see :func:`band_penalty`.
        censored: bool broadcastable to ``[P, C']``: counts that are lower bounds (the pixel hit
            its refractory period in the window), penalised one-sided (:func:`band_penalty`).

    Returns:
        Scalar loss in count units.
    """
    if theta_neg is None:
        theta_neg = theta_pos
    theta = polarity_theta(d_gt, delta_pred, theta_pos, theta_neg, zero_tol)
    return _weighted_mean(band_penalty(delta_pred / theta, d_gt, beta, zero_tol, censored), channel_weights)


def event_loss_pvc(
    delta_pred: torch.Tensor,
    d_gt: torch.Tensor,
    theta_pos: torch.Tensor,
    theta_neg: torch.Tensor | None = None,
    kind: Literal["band", "mse"] = "band",
    beta: float = 0.5,
    channel_weights: torch.Tensor | None = None,
    zero_tol: float = 0.0,
) -> torch.Tensor:
    """Photovoltage-contrast loss: band or mse against the HPF target ``D_gt`` (docs/method.md 2-3).

    ``kind="band"`` is :func:`event_loss_band`; ``kind="mse"`` is the squared error
    ``(d_hat - theta_p D_gt)^2`` with ``theta_p`` chosen by :func:`polarity_theta`.

    Args:
        delta_pred: ``[P, C']`` rendered log change.
        d_gt: ``[P, C']`` HPF contrast ``(V(t_b) - V(t_a)) / theta0`` (count units).
        theta_pos, theta_neg, beta, channel_weights, zero_tol: as :func:`event_loss_band`.
        kind: ``"band"`` or ``"mse"``.

    Returns:
        Scalar loss.
    """
    if kind == "band":
        return event_loss_band(delta_pred, d_gt, theta_pos, theta_neg, beta, channel_weights, zero_tol)
    if kind != "mse":
        raise InputError("event_loss_pvc", "kind", "'band' or 'mse'", repr(kind))
    theta_neg = theta_pos if theta_neg is None else theta_neg
    theta = polarity_theta(d_gt, delta_pred, theta_pos, theta_neg, zero_tol)
    return _weighted_mean((delta_pred - theta * d_gt) ** 2, channel_weights)


def sample_event_pixels(
    count_maps: torch.Tensor,
    n_pixels: int,
    frac_with_events: float = 0.9,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Sample pixels for the event loss: ~``frac_with_events`` of them where events fired.

    Without replacement. ``k = round(frac * P)`` pixels are drawn uniformly among pixels with at
    least one event and ``P - k`` among pixels without; if one set is too small the other fills
    the rest. Vectorised over windows (two ``topk`` of random keys per window).

    Args:
        count_maps: ``[..., 2, H, W]`` per-polarity activity maps (event counts, or absolute HPF
            contrast); leading dimensions are windows.
        n_pixels: ``P``, at most ``H * W``.
        frac_with_events: share of pixels with events, in [0, 1].
        generator: random generator (on the maps' device).

    Returns:
        ``[..., P]`` int64 flat pixel indices ``y * W + x``, distinct within each window.
    """
    if count_maps.ndim < 3 or count_maps.shape[-3] != 2:
        raise InputError("sample_event_pixels", "count_maps", "[..., 2, H, W]", tuple(count_maps.shape))
    lead, hw = count_maps.shape[:-3], count_maps.shape[-2] * count_maps.shape[-1]
    if not 0 < n_pixels <= hw:
        raise InputError("sample_event_pixels", "n_pixels", f"in [1, {hw}]", n_pixels)
    if not 0.0 <= frac_with_events <= 1.0:
        raise InputError("sample_event_pixels", "frac_with_events", "in [0, 1]", frac_with_events)
    active = (count_maps.abs().sum(-3) > 0).reshape(-1, hw)  # [M, HW]
    n_act = active.sum(-1, keepdim=True)  # [M, 1]
    want = round(frac_with_events * n_pixels)
    k_act = torch.clamp(n_act, max=want)
    k_act = torch.maximum(k_act, n_pixels - (hw - n_act))  # not enough inactive pixels
    # random keys, active pixels in [0, 1), inactive in [2, 3): the P smallest keys are active
    # pixels first (a uniform random subset), the P largest are inactive pixels first
    key = torch.rand(active.shape, generator=generator, device=count_maps.device) + 2.0 * (~active)
    first_active = torch.topk(key, n_pixels, dim=-1, largest=False).indices
    first_inactive = torch.topk(key, n_pixels, dim=-1, largest=True).indices
    j = torch.arange(n_pixels, device=count_maps.device)[None]
    out = torch.where(
        j < k_act, first_active, first_inactive.gather(-1, (j - k_act).clamp(min=0))
    )
    return out.reshape(*lead, n_pixels)
