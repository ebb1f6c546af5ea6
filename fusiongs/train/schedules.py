"""Schedules and window sampling: small pure functions of the step (docs/method.md sections 3, 4, 6).

Steps count from 0. Every function is pure; randomness takes an explicit ``torch.Generator``, and
random draws are made on that generator's device (the CPU without one).
"""

from __future__ import annotations

import math
from typing import Literal

import torch

from fusiongs.errors import InputError


def _device(generator: torch.Generator | None) -> torch.device:
    """Where a draw from ``generator`` is made: its device, the CPU without one."""
    return torch.device("cpu") if generator is None else generator.device


def _ramp(step: int, start: int, ramp: int) -> float:
    """0 before ``start``, then linear from 0 at ``start`` to 1 at ``start + ramp`` (1 if ramp 0)."""
    if step < start:
        return 0.0
    if ramp <= 0:
        return 1.0
    return min(1.0, (step - start) / ramp)


def event_weight(step: int, warmup: int, lam: float, ramp: int = 0) -> float:
    """Event-loss weight ``lambda_ev(step)``: 0 during the warm-up, then ``lam``.

    With ``ramp > 0`` the weight grows linearly from 0 at ``step == warmup`` to ``lam`` at
    ``step == warmup + ramp``. docs/method.md section 3: warm-up ~1000 iterations, ``lam`` ~0.1.

    Args:
        step: iteration index (0-based).
        warmup: first step at which events may count.
        lam: final weight.
        ramp: length of the linear ramp in steps (0 = jump).

    Returns:
        The weight (float).
    """
    return lam * _ramp(step, warmup, ramp)


def event_only_alpha(step: int, warmup: int, alpha_final: float, ramp: int = 0) -> float:
    """Event-only mode's mix ``alpha * L_event + (1 - alpha) * L_intensity`` (Event-3DGS).

    ``alpha`` is 0 during the warm-up (intensity prior only), then ``alpha_final`` (0.9-0.99),
    optionally reached by a linear ramp as in :func:`event_weight`.

    Returns:
        ``alpha`` in [0, alpha_final].
    """
    if not 0.0 <= alpha_final <= 1.0:
        raise InputError("event_only_alpha", "alpha_final", "a value in [0, 1]", alpha_final)
    return alpha_final * _ramp(step, warmup, ramp)


def log_linear_lr(step: int, start: float, end: float, max_steps: int) -> float:
    """Exponential (log-linear) decay from ``start`` at step 0 to ``end`` at ``max_steps``.

    ``lr = start * (end / start) ** clamp(step / max_steps, 0, 1)``; e.g. camera refinement
    1e-3 -> 1e-5 (BAD-Gaussians, Zhao et al., ECCV 2024). Constant ``end`` after ``max_steps``.

    Returns:
        The learning rate (float).
    """
    if not (start > 0 and end > 0 and max_steps > 0):
        raise InputError("log_linear_lr", "start/end/max_steps", "positive values",
                         f"{start}, {end}, {max_steps}")
    u = min(max(step / max_steps, 0.0), 1.0)
    return math.exp((1.0 - u) * math.log(start) + u * math.log(end))


def sample_exposure_pairs(
    n_instants: int, n: int, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Random pairs ``(j, k)``, ``j < k``, of the N blur instants of one exposure (E2NeRF).

    Distinct pairs while ``n`` <= N(N-1)/2, then drawn with replacement.

    Args:
        n_instants: N, the number of exposure instants (>= 2).
        n: number of pairs.
        generator: random generator.

    Returns:
        ``[n, 2]`` int64 instant indices, first < second, on the generator's device.
    """
    if n_instants < 2:
        raise InputError("sample_exposure_pairs", "n_instants", "at least 2", n_instants)
    device = _device(generator)
    pairs = torch.triu_indices(n_instants, n_instants, offset=1, device=device).T  # [N(N-1)/2, 2]
    m = pairs.shape[0]
    if n <= m:
        pick = torch.randperm(m, generator=generator, device=device)[:n]
    else:
        pick = torch.randint(m, (n,), generator=generator, device=device)
    return pairs[pick]


def sample_free_windows(
    n: int,
    t_range: tuple[float, float],
    frame_interval: float,
    generator: torch.Generator | None = None,
    min_duration: float = 1e-3,
    spacing: Literal["log", "linear"] = "log",
) -> torch.Tensor:
    """Free event windows: duration log-uniform in ``[min_duration, frame_interval]`` (or uniform,
    ``spacing="linear"``).

    The duration is clamped to the event time range, and the start is uniform so that the window
    lies inside ``t_range``.

    Args:
        n: number of windows.
        t_range: ``(t0, t1)`` seconds covered by events.
        frame_interval: longest duration in seconds (one frame interval).
        generator: random generator.
        min_duration: shortest duration in seconds (1 ms).
        spacing: ``"log"`` (the training's windows: short ones as often as long ones per octave)
            or ``"linear"`` (durations uniform; the threshold fit of ``train/render_threshold.py``).

    Returns:
        ``[n, 2]`` float64 ``(t_a, t_b)`` in seconds, ``t0 <= t_a < t_b <= t1``, on the
        generator's device.
    """
    t0, t1 = _check_windows("sample_free_windows", t_range, frame_interval, min_duration)
    if spacing not in ("log", "linear"):
        raise InputError("sample_free_windows", "spacing", "'log' or 'linear'", repr(spacing))
    u = torch.rand(n, 2, generator=generator, dtype=torch.float64, device=_device(generator))
    if spacing == "log":
        dur = _log_uniform(u[:, 0], min_duration, frame_interval)
    else:
        dur = min_duration + u[:, 0] * (frame_interval - min_duration)
    dur = dur.clamp(max=t1 - t0)
    start = t0 + u[:, 1] * (t1 - t0 - dur)
    return torch.stack((start, start + dur), -1)


def _check_windows(caller: str, t_range: tuple[float, float], longest: float, shortest: float
                   ) -> tuple[float, float]:
    """``(t0, t1)`` of ``t_range`` once ``t1 > t0`` and ``0 < shortest <= longest`` hold."""
    t0, t1 = float(t_range[0]), float(t_range[1])
    if not (t1 > t0 and 0 < shortest <= longest):
        raise InputError(caller, "t_range/frame_interval", "t1 > t0 and 0 < min_duration <= frame_interval",
                         f"{t_range}, {shortest}, {longest}")
    return t0, t1


def _log_uniform(u: torch.Tensor, shortest: float, longest: float) -> torch.Tensor:
    """Durations (s) log-uniform in ``[shortest, longest]`` from uniform draws ``u`` in [0, 1)."""
    lo, hi = math.log(shortest), math.log(longest)
    return torch.exp(lo + u * (hi - lo))


def sample_chained_windows(n: int, t_range: tuple[float, float], frame_interval: float,
                           generator: torch.Generator | None = None, min_duration: float = 1e-3
                           ) -> torch.Tensor:
    """``n`` consecutive free windows, each one's end the next one's start: ``n + 1`` instants.

    Each duration is log-uniform in ``[min_duration, frame_interval]`` as in
    :func:`sample_free_windows` (all scaled down together when their sum exceeds ``t_range``), and
    the chain's start is uniform so that it lies inside ``t_range``. ``n`` windows then need
    ``n + 1`` renders instead of ``2 n``.

    Returns:
        ``[n + 1]`` float64 instants ``p_0 < … < p_n`` in seconds (window ``i`` is
        ``[p_i, p_{i+1})``), ``t0 <= p_0`` and ``p_n <= t1``, on the generator's device.
    """
    if n < 1:
        raise InputError("sample_chained_windows", "n", "at least one window", n)
    t0, t1 = _check_windows("sample_chained_windows", t_range, frame_interval, min_duration)
    u = torch.rand(n + 1, generator=generator, dtype=torch.float64, device=_device(generator))
    dur = _log_uniform(u[:n], min_duration, frame_interval)
    dur = dur * ((t1 - t0) / dur.sum()).clamp(max=1.0)
    ends = torch.cumsum(dur, 0)
    start = t0 + u[n:] * (t1 - t0 - ends[-1]).clamp(min=0.0)
    return torch.cat((start, start + ends)).clamp(t0, t1)


def sample_windows(
    exposures: torch.Tensor,
    frame: int,
    n_inside: int,
    n_free: int,
    t_range: tuple[float, float],
    frame_interval: float,
    n_instants: int = 9,
    generator: torch.Generator | None = None,
    min_duration: float = 1e-3,
) -> torch.Tensor:
    """Event windows for one iteration: pairs of blur instants of frame ``frame``, then free ones.

    Rows ``[:n_inside]`` are ``(t_j, t_k)`` for :func:`sample_exposure_pairs` of the frame's
    :func:`~fusiongs.losses.blur.exposure_instants` (the trainer can reuse those renders by
    calling the two functions itself), clamped to ``t_range``; rows ``[n_inside:]`` come from
    :func:`sample_free_windows`. The generator is used in that order.

    Args:
        exposures: ``[F, 2]`` exposure ``(start, end)`` of every frame in seconds.
        frame: index of the current frame.
        n_inside, n_free: numbers of windows of each kind.
        t_range: ``(t0, t1)`` seconds covered by events.
        frame_interval: longest free-window duration in seconds.
        n_instants: N of the blur model.
        generator: random generator (on ``exposures``' device).
        min_duration: shortest free-window duration in seconds.

    Returns:
        ``[n_inside + n_free, 2]`` float64 windows ``(t_a, t_b)`` in seconds.
    """
    if exposures.ndim != 2 or exposures.shape[1] != 2 or not 0 <= frame < exposures.shape[0]:
        raise InputError("sample_windows", "exposures/frame", "[F, 2] exposures and 0 <= frame < F",
                         f"{tuple(exposures.shape)}, {frame}")
    s, e = exposures[frame].to(torch.float64)
    frac = (torch.arange(n_instants, dtype=torch.float64, device=exposures.device) + 0.5) / n_instants
    instants = s + frac * (e - s)  # same rule as losses.blur.exposure_instants
    inside = instants[sample_exposure_pairs(n_instants, n_inside, generator)].reshape(n_inside, 2)
    inside = inside.clamp(float(t_range[0]), float(t_range[1]))
    free = sample_free_windows(n_free, t_range, frame_interval, generator, min_duration)
    return torch.cat((inside, free), 0)
