"""The loss history of a run: per-iteration records kept on the device and read back in batches.

On a GPU the training loop does not wait for the device: each iteration's record
(:func:`history_row`) stays there and :func:`flush_pending` reads ``FLUSH_EVERY`` of them back at
once (one synchronisation), and at checkpoints. ``history.jsonl`` is written from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import torch

from fusiongs.errors import InputError
from fusiongs.train.state import FusionState

FLUSH_EVERY = 25  # iterations whose records are read back from the device at once (one sync)
TERMS = ("blur", "event", "event_lowpass", "edi", "intensity", "tv")  # terms recorded (StepResult.parts keys)


@dataclass
class History:
    """Per-iteration curves kept for the report (one entry per iteration; read back from the
    device every ``FLUSH_EVERY`` iterations and at checkpoints). ``step_seconds`` and the render /
    backward times are host times: on a GPU they count kernel launches, not the device's work."""

    iteration: list[int] = field(default_factory=list)
    loss: list[float] = field(default_factory=list)
    blur: list[float] = field(default_factory=list)
    event: list[float] = field(default_factory=list)
    event_lowpass: list[float] = field(default_factory=list)  # low-pass term of long windows
    edi: list[float] = field(default_factory=list)
    intensity: list[float] = field(default_factory=list)  # event-only mode's HPF anchor term
    tv: list[float] = field(default_factory=list)  # event-only mode's total-variation prior (off by default)
    theta_pos: list[list[float]] = field(default_factory=list)
    theta_neg: list[list[float]] = field(default_factory=list)
    n_gaussians: list[int] = field(default_factory=list)
    event_weight: list[float] = field(default_factory=list)  # λ_ev (α in event-only mode)
    psnr_input: list[float] = field(default_factory=list)    # running PSNR of re-rendered blurry frames
    step_seconds: list[float] = field(default_factory=list)  # wall time of each iteration
    # the truth probe (fusiongs.train.truth_probe): iterations probed, PSNR as rendered / affine-fit
    truth_iteration: list[int] = field(default_factory=list)
    psnr_truth: list[float] = field(default_factory=list)
    psnr_truth_fit: list[float] = field(default_factory=list)
    seconds: float = 0.0
    render_seconds: float = 0.0      # rasteriser forward passes
    backward_seconds: float = 0.0    # backward through losses and rasteriser

    def __post_init__(self) -> None:
        # a checkpoint written before the intensity term was recorded: its iterations had none
        missing = len(self.iteration) - len(self.intensity)
        if missing > 0:
            self.intensity = [math.nan] * missing + list(self.intensity)


@dataclass
class PendingRow:
    """An iteration recorded but not yet read back: ``row`` from :func:`history_row`, on the device."""

    iteration: int
    row: torch.Tensor
    n_gaussians: int
    event_weight: float


def history_row(loss: torch.Tensor, parts: dict[str, torch.Tensor], state: FusionState,
         psnr: torch.Tensor | None) -> torch.Tensor:
    """``[2 + len(TERMS) + 2C]`` float32 on the device: loss, the ``TERMS`` (NaN when
    off), running PSNR, θ+ ``[C]`` and θ− ``[C]`` (C channels of the threshold)."""
    nan = loss.new_full((), math.nan, dtype=torch.float32)
    terms = [loss, *(parts.get(k, nan) for k in TERMS), nan if psnr is None else psnr]
    with torch.no_grad():
        tp, tn = state.threshold.scalar()
    return torch.cat([torch.stack([t.float() for t in terms]), tp.reshape(-1).float(),
                      tn.reshape(-1).float()])


def flush_pending(h: History, pending: list[PendingRow], bar) -> None:
    """Read the pending rows back from the device at once (one sync) into ``h``; update ``bar``.

    Raises:
        InputError: a recorded loss is NaN or infinite (the training diverged; the rasteriser's own
            value checks are off in the loop).
    """
    if not pending:
        return
    head = ("loss", *TERMS, "psnr_input")  # the row's leading values, then θ+ [C], θ− [C]
    for p, v in zip(pending, torch.stack([p.row for p in pending]).tolist()):
        for name, x in zip(head, v):
            getattr(h, name).append(x)
        c = (len(v) - len(head)) // 2
        h.theta_pos.append(v[len(head):len(head) + c])
        h.theta_neg.append(v[len(head) + c:])
        h.iteration.append(p.iteration)
        h.n_gaussians.append(p.n_gaussians)
        h.event_weight.append(float(p.event_weight))
        if not math.isfinite(v[0]):
            raise InputError("training", "loss", "finite values (the training diverged: lower the "
                             "learning rates?)", f"{v[0]} at iteration {p.iteration}")
    pending.clear()
    bar.set_postfix(loss=f"{h.loss[-1]:.4f}", psnr=f"{h.psnr_input[-1]:.2f}", n=h.n_gaussians[-1])


HISTORY_KEYS = ("iteration", "loss", *TERMS, "event_weight", "theta_pos", "theta_neg",
                "n_gaussians", "psnr_input", "step_seconds")


def history_rows(h: History) -> list[dict]:
    """One plain dict per recorded iteration: total loss, each term (NaN when off), the event weight
    (λ_ev, or α in event-only mode), θ per polarity and channel, the number of Gaussians, the
    running PSNR of the re-rendered blurry frames, the step time and, on the iterations the truth
    probe scored, ``psnr_truth`` / ``psnr_truth_fit`` (None elsewhere)."""
    probed = {it: j for j, it in enumerate(h.truth_iteration)}
    rows = []
    for i in range(len(h.iteration)):
        row = {}
        for k in HISTORY_KEYS:
            v = getattr(h, k)
            row[k] = v[i] if i < len(v) else None
        j = probed.get(h.iteration[i])
        row["psnr_truth"] = h.psnr_truth[j] if j is not None else None
        row["psnr_truth_fit"] = h.psnr_truth_fit[j] if j is not None else None
        rows.append(row)
    return rows


def write_history(h: History, path: Path) -> None:
    """``history.jsonl`` (one JSON object per recorded iteration; NaN written as null), atomically."""
    import json

    from fusiongs.atomic import json_ready, write_text

    lines = [json.dumps(json_ready(row)) for row in history_rows(h)]
    write_text(path, "\n".join(lines) + ("\n" if lines else ""))
