"""Learnable contrast threshold: per polarity and colour channel, optionally varying in space and time.

``theta = exp(s)`` keeps the threshold positive (docs/method.md section 4). Event-3DGS (Han et al.,
NeurIPS 2024) learns a single scalar; a real sensor's threshold varies over pixels and drifts in
time, so two optional terms are added to ``s``:

- a spatial field: a coarse ``gh x gw`` grid of log-threshold offsets over the sensor, bilinearly
  interpolated at pixel centres (``grid_sample``, ``align_corners=False``, border padding) and kept
  smooth by :meth:`ContrastThreshold.smoothness`;
- a temporal drift: log offsets at ``K`` knots spread evenly over a time range, linearly
  interpolated in time (constant outside the range).

Both start at zero, so at initialisation the threshold equals the scalar everywhere.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from fusiongs.errors import InputError


class ContrastThreshold(nn.Module):
    """Positive contrast thresholds ``theta_+`` and ``theta_-`` of an event sensor.

    Args:
        channels: 1 (grey sensor, or one threshold shared by colours) or 3 (per RGB channel).
        init: initial threshold (log-intensity units): one float, ``(theta_+, theta_-)``, or a
            ``[2, channels]`` array (row 0 ON, row 1 OFF; e.g. from ``fusiongs calibrate``).
        grid: optional ``(gh, gw)`` size of the spatial log-offset grid (e.g. ``(6, 8)``).
        image_size: ``(H, W)`` of the sensor in pixels; needed for flat pixel indices.
        time_knots: number of drift knots (0 = no drift, else >= 2).
        time_range: ``(t0, t1)`` seconds spanned by the drift knots.
    """

    def __init__(
        self,
        channels: int = 1,
        init: float | tuple[float, float] = 0.25,
        grid: tuple[int, int] | None = None,
        image_size: tuple[int, int] | None = None,
        time_knots: int = 0,
        time_range: tuple[float, float] = (0.0, 1.0),
    ):
        super().__init__()
        if isinstance(init, int | float):
            init = (init, init)
        s0 = torch.as_tensor(init, dtype=torch.float64, device="cpu")  # checked on the host, once
        if s0.ndim == 1 and s0.shape == (2,):
            s0 = s0[:, None].expand(2, channels)
        if (channels not in (1, 3) or s0.shape != (2, channels) or not bool(torch.isfinite(s0).all())
                or not bool((s0 > 0).all())):
            raise InputError("ContrastThreshold", "channels/init",
                             "1 or 3 channels, init > 0 as a float, a pair or [2, channels]",
                             f"{channels}, {init}")
        if time_knots == 1 or time_knots < 0 or (time_knots and not time_range[1] > time_range[0]):
            raise InputError("ContrastThreshold", "time_knots/time_range", "0 or >= 2 knots, t1 > t0",
                             f"{time_knots}, {time_range}")
        s0 = torch.log(s0).to(torch.float32).contiguous()
        self.register_buffer("log_theta_init", s0)
        self.log_theta = nn.Parameter(s0.clone())  # [2, C]
        self.image_size = image_size
        z = dict(device=s0.device)  # built on the host; move the module with .to(device)
        self.field = None if grid is None else nn.Parameter(torch.zeros(2, channels, *grid, **z))
        self.drift = None if not time_knots else nn.Parameter(torch.zeros(time_knots, 2, channels, **z))
        self.time_range = (float(time_range[0]), float(time_range[1]))

    @property
    def channels(self) -> int:
        return self.log_theta.shape[1]

    def freeze(self) -> ContrastThreshold:
        """Stop learning (warm-up); returns self."""
        return self.requires_grad_(False)

    def unfreeze(self) -> ContrastThreshold:
        """Resume learning; returns self."""
        return self.requires_grad_(True)

    def _pixel_xy(self, pixels: torch.Tensor) -> torch.Tensor:
        if pixels.ndim == 2 and pixels.shape[1] == 2:
            return pixels.to(self.log_theta.dtype)
        if pixels.ndim != 1 or self.image_size is None:
            raise InputError("ContrastThreshold.theta", "pixels",
                             "[P] flat indices (with image_size set) or [P, 2] (x, y)", tuple(pixels.shape))
        w = self.image_size[1]
        return torch.stack((pixels % w, pixels // w), -1).to(self.log_theta.dtype)

    def _field_at(self, xy: torch.Tensor) -> torch.Tensor:
        h, w = self.image_size if self.image_size is not None else (None, None)
        if h is None:
            raise InputError("ContrastThreshold", "image_size", "(H, W) when a spatial grid is used")
        norm = torch.stack((2 * (xy[:, 0] + 0.5) / w - 1, 2 * (xy[:, 1] + 0.5) / h - 1), -1)
        f = self.field.reshape(1, -1, *self.field.shape[-2:])  # [1, 2C, gh, gw]
        out = F.grid_sample(f, norm[None, :, None], mode="bilinear", padding_mode="border",
                            align_corners=False)  # [1, 2C, P, 1]
        return out[0, :, :, 0].reshape(2, self.channels, -1).permute(0, 2, 1)  # [2, P, C]

    def _drift_at(self, t: float | torch.Tensor) -> torch.Tensor:
        k = self.drift.shape[0]
        t0, t1 = self.time_range
        if isinstance(t, int | float):  # one instant: knots and weight found on the host
            u = min(max((float(t) - t0) / (t1 - t0), 0.0), 1.0) * (k - 1)
            lo = min(math.floor(u), k - 2)
            return self.drift[lo] * (1 - (u - lo)) + self.drift[lo + 1] * (u - lo)  # [2, C]
        tt = torch.as_tensor(t, dtype=torch.float64, device=self.drift.device)
        u = ((tt - t0) / (t1 - t0)).clamp(0, 1) * (k - 1)
        lo = u.floor().clamp(max=k - 2).long()
        frac = (u - lo).to(self.drift.dtype)[..., None, None]
        d = self.drift[lo] * (1 - frac) + self.drift[lo + 1] * frac  # [..., 2, C]
        return d.movedim(-2, 0)  # [2, ..., C]

    def log_theta_at(
        self, pixels: torch.Tensor | None = None, t: float | torch.Tensor | None = None
    ) -> torch.Tensor:
        """Log thresholds ``[2, P, C]`` (``[2, C]`` without pixels); index 0 = positive."""
        s = self.log_theta
        if pixels is not None:
            s = s[:, None, :].expand(2, pixels.shape[0], self.channels)
            if self.field is not None:
                s = s + self._field_at(self._pixel_xy(pixels))
        elif self.field is not None:
            raise InputError("ContrastThreshold.theta", "pixels", "pixel positions when a grid is used")
        if self.drift is not None and t is not None:
            d = self._drift_at(t)
            s = s + (d[:, None, :] if (pixels is not None and d.ndim == 2) else d)
        return s

    def scalar(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``(theta_pos [C], theta_neg [C])`` without the field and drift (their means are pinned
        to zero by :meth:`smoothness`, so this is the sensor's mean threshold)."""
        th = torch.exp(self.log_theta)
        return th[0], th[1]

    def theta(
        self,
        pixels: torch.Tensor | None = None,
        t: float | torch.Tensor | None = None,
        channel: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Thresholds at sampled pixels and time.

        Args:
            pixels: ``[P]`` int64 flat indices ``y * W + x`` (needs ``image_size``) or ``[P, 2]``
                pixel column/row ``(x, y)``; None for the scalar per channel (no spatial grid).
            t: time in seconds, a float or ``[P]`` (e.g. window mid-times); ignored without drift.
            channel: optional ``[P]`` int64 CFA channel per pixel (colour mask mode, 3 channels).

        Returns:
            ``(theta_pos, theta_neg)``, each ``[P, C]``, ``[P, 1]`` with ``channel``, or ``[C]``
            without ``pixels``.
        """
        s = self.log_theta_at(pixels, t)
        if channel is not None:
            if pixels is None or self.channels != 3:
                raise InputError("ContrastThreshold.theta", "channel", "pixels and 3 channels")
            s = s.gather(-1, channel.reshape(1, -1, 1).expand(2, -1, 1).to(torch.int64))
        th = torch.exp(s)
        return th[0], th[1]

    def regularisation(self) -> torch.Tensor:
        """Squared log-distance of the scalar thresholds to their initial values (event-only mode).

        Returns:
            Scalar ``sum (s - s0)^2`` over polarities and channels.
        """
        return ((self.log_theta - self.log_theta_init) ** 2).sum()

    def smoothness(self) -> torch.Tensor:
        """Smoothness of the spatial field and the drift (0 when neither is used).

        Sum of squared differences of 4-neighbour grid cells and of consecutive drift knots, plus
        the squared mean of each offset map (pins the offsets' mean to the scalar threshold, which
        would otherwise be unidentifiable).

        Returns:
            Scalar.
        """
        total = self.log_theta.new_zeros(())
        if self.field is not None:
            f = self.field
            total = total + ((f[..., 1:, :] - f[..., :-1, :]) ** 2).sum()
            total = total + ((f[..., :, 1:] - f[..., :, :-1]) ** 2).sum()
            total = total + (f.mean(dim=(-2, -1)) ** 2).sum()
        if self.drift is not None:
            d = self.drift
            total = total + ((d[1:] - d[:-1]) ** 2).sum() + (d.mean(0) ** 2).sum()
        return total
