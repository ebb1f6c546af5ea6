"""Adam for Gaussians, and editing Gaussians together with the optimiser state.

When Gaussians are added or removed the parameter tensors change size, so each is replaced by a
new ``nn.Parameter`` and every optimiser that held the old one is re-pointed to the new one, with
its per-element state (Adam's ``exp_avg``, ``exp_avg_sq``, ``max_exp_avg_sq``) edited the same way
(kept rows index-selected, new rows zero, as in 3DGS). Scalar state (``step``) is kept.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass

import torch
from torch import nn

from fusiongs.scene.gaussians import PARAM_NAMES, SH_C0, GaussianModel

Optimizers = torch.optim.Optimizer | Iterable[torch.optim.Optimizer] | Mapping[str, torch.optim.Optimizer]


@dataclass(frozen=True)
class GaussianLR:
    """Adam learning rates per parameter group (3DGS defaults; ``means`` is multiplied by the
    scene scale in :func:`make_optimizer`; its exponential decay is the trainer's schedule)."""

    means: float = 1.6e-4
    log_scales: float = 5e-3
    quats: float = 1e-3
    opacity_logits: float = 5e-2
    sh0: float = 2.5e-3
    shN: float = 2.5e-3 / 20


def make_optimizer(model: GaussianModel, lr: GaussianLR = GaussianLR(), scene_scale: float = 1.0,
                   eps: float = 1e-15) -> torch.optim.Adam:
    """One Adam with one group per parameter; each group carries ``"name"`` (a ``PARAM_NAMES``
    entry) so schedules can find it: ``{g["name"]: g for g in opt.param_groups}``."""
    rates = asdict(lr)
    rates["means"] *= scene_scale
    groups = [{"params": [p], "lr": rates[name], "name": name}
              for name, p in model.parameter_groups().items()]
    return torch.optim.Adam(groups, eps=eps)


def _as_list(optimizers: Optimizers | None) -> list[torch.optim.Optimizer]:
    if optimizers is None:
        return []
    if isinstance(optimizers, torch.optim.Optimizer):
        return [optimizers]
    if isinstance(optimizers, Mapping):
        return list(optimizers.values())
    return list(optimizers)


def replace_parameters(model: GaussianModel, optimizers: Optimizers | None,
                       param_fn: Callable[[str, torch.Tensor], torch.Tensor],
                       state_fn: Callable[[str, torch.Tensor], torch.Tensor],
                       names: Iterable[str] = PARAM_NAMES) -> None:
    """Replace the named parameters by ``param_fn(name, old_data)`` and every optimiser's
    per-element state ``v`` of them by ``state_fn(name, v)``. Other parameters are untouched."""
    opts = _as_list(optimizers)
    for name in names:
        old = getattr(model, name)
        new = nn.Parameter(param_fn(name, old.detach()), requires_grad=old.requires_grad)
        for opt in opts:
            for group in opt.param_groups:
                for i, p in enumerate(group["params"]):
                    if p is not old:
                        continue
                    group["params"][i] = new
                    state = opt.state.pop(old, None)
                    if state is not None:
                        opt.state[new] = {k: state_fn(name, v) if torch.is_tensor(v) and v.shape == old.shape
                                          and v.ndim > 0 else v for k, v in state.items()}
        setattr(model, name, new)


def edit_gaussians(model: GaussianModel, optimizers: Optimizers | None, keep: torch.Tensor,
                   new: Mapping[str, torch.Tensor] | None = None) -> None:
    """Keep the Gaussians ``keep`` (bool mask ``[N]`` or indices ``[M]``, in that order) and append
    ``new`` (a full set of raw tensors by parameter name, same row count each; zero optimiser
    state). Covers pruning (``new=None``), cloning (``keep=all``) and splitting."""
    idx = keep.nonzero()[:, 0] if keep.dtype == torch.bool else keep.long()
    if new is not None and set(new) != set(PARAM_NAMES):
        raise ValueError(f"new Gaussians need exactly {PARAM_NAMES}, got {sorted(new)}")

    def param_fn(name: str, x: torch.Tensor) -> torch.Tensor:
        kept = x[idx]
        return kept if new is None else torch.cat([kept, new[name].to(x)])

    def state_fn(name: str, v: torch.Tensor) -> torch.Tensor:
        kept = v[idx]
        if new is None:
            return kept
        return torch.cat([kept, v.new_zeros((new[name].shape[0],) + v.shape[1:])])

    replace_parameters(model, optimizers, param_fn, state_fn)


def reset_opacity(model: GaussianModel, optimizers: Optimizers | None, value: float) -> None:
    """Clamp opacities to at most ``value`` (``logit <= logit(value)``) and zero their Adam state
    (3DGS opacity reset)."""
    limit = math.log(value / (1.0 - value))  # logit(value)
    replace_parameters(model, optimizers, lambda _, x: x.clamp_max(limit),
                       lambda _, v: torch.zeros_like(v), names=("opacity_logits",))


def relative_colour_step(model: GaussianModel, step: Callable[[], None], floor: float,
                         reference: float = 0.5) -> None:
    """Run ``step`` (an optimiser step that moves the colours) with each colour's step scaled by
    its own level: the change of ``sh0`` (and of ``shN``) is multiplied by
    ``max(c, floor) / reference``, ``c = sh0 * C0 + 0.5`` the Gaussian's linear base colour per
    channel, ``reference`` the level whose step is left as ``step`` made it (the grey start, or
    the frame's fill level whose colour rates are already scaled to it).

    An Adam step is a roughly fixed change of its parameter. On the linear colour that changes
    log intensity, where the event loss acts, by ``lr / c``: large for a dark Gaussian, small for a
    bright one, so a scene that spans several log units (a dim room with lit objects) is fitted
    slowly at the bright end and noisily at the dark end. Scaled by ``c / 0.5`` the step changes
    ``log c`` by about ``lr / 0.5`` at every level (Adam on ``log c``, to first order), and by the
    same as before at the reference level. Below ``floor`` (linear, > 0) the step stops shrinking: a
    colour at or below zero stays movable, and ``floor = 0.5`` keeps the linear step below the
    grey start (fast toward black) while steps above it grow with the colour. Runs without
    gradients; every tensor stays on the model's device.
    """
    with torch.no_grad():
        scale = (model.sh0.detach() * SH_C0 + 0.5).clamp_min(floor) / reference  # [N, 1, 3]
        old0, oldN = model.sh0.detach().clone(), model.shN.detach().clone()
    step()
    with torch.no_grad():
        model.sh0.copy_(old0 + (model.sh0 - old0) * scale)
        if model.shN.numel():
            model.shN.copy_(oldN + (model.shN - oldN) * scale)
