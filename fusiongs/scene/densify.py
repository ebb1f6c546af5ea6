"""Adaptive density control of 3D Gaussians (Kerbl et al. 2023, §5; gsplat's default strategy).

Every step (before ``refine_stop``) the norm of each visible Gaussian's view-space position
gradient is accumulated. Gradient normalisation: ``meta.means2d`` is in pixels, while 3DGS
thresholds (``grow_grad2d = 2e-4``) were set on gradients w.r.t. NDC coordinates in [-1, 1], so
``d/d ndc = d/d pixel * [W/2, H/2]``. A loss that is a mean over the ``C = n_cameras`` renders of one
rasterise call scales each render's gradient by ``1/C``; gsplat multiplies by ``C`` to undo it, and
so do we. ``n_views`` extends this to a loss that averages renders of *separate* calls, e.g. the
N virtual views of an exposure-integrated blurry frame (``B = mean_k L(T(t_k))``): each render
then carries ``1/N`` of a sharp render's gradient, and multiplying by ``N`` while counting each
render once is the same as dividing the threshold by ``N`` (BAD-Gaussians). If the N views are
rendered in one call with ``C = N`` cameras, ``n_cameras`` already covers it: pass ``n_views=1``.

At refinement steps Gaussians with mean gradient ``> grow_grad2d`` are cloned (if their largest
scale is ``<= grow_scale3d * scene_scale``) or split into 2 (otherwise): children means are
sampled from the Gaussian, scales divided by 1.6. With ``max_gaussians > 0`` each of them adds one
Gaussian, and when there are more candidates than room below the cap, only those with the largest
mean gradients grow, so the count never exceeds the cap (pruning then frees room again). Then
Gaussians with opacity ``< prune_opacity`` are removed, and after the first opacity reset also
those with largest scale ``> prune_scale3d * scene_scale``. Every ``reset_opacity_every`` steps
opacities are clamped to ``2 * prune_opacity`` (disable with ``reset_opacity_every=0`` or
:meth:`DensifyStrategy.disable_opacity_reset`, e.g. once the event loss is on: Event-3DGS).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import torch

from fusiongs.camera.lie import quat_to_matrix
from fusiongs.scene.gaussians import PARAM_NAMES, GaussianModel
from fusiongs.scene.optim import Optimizers, edit_gaussians, reset_opacity


def should_refine(step: int, start: int, stop: int, every: int, reset_every: int = 0,
                  pause_after_reset: int = 0) -> bool:
    """Grow/prune at ``step``: ``start < step < stop``, ``step % every == 0``, and not within
    ``pause_after_reset`` steps after an opacity reset (every ``reset_every`` steps)."""
    if every <= 0 or not start < step < stop or step % every != 0:
        return False
    return not (reset_every > 0 and step % reset_every < pause_after_reset)


def should_reset_opacity(step: int, every: int, stop: int, enabled: bool = True) -> bool:
    """Reset opacities at ``step``: enabled, ``every > 0``, ``0 < step < stop`` and
    ``step % every == 0``."""
    return bool(enabled) and every > 0 and 0 < step < stop and step % every == 0


@dataclass(frozen=True)
class DensifyConfig:
    """Thresholds and schedule (3DGS / gsplat defaults; steps as the trainer counts them)."""

    prune_opacity: float = 0.005
    grow_grad2d: float = 0.0002
    grow_scale3d: float = 0.01  # x scene_scale
    prune_scale3d: float = 0.1  # x scene_scale
    grow_scale2d: float = 0.05  # x max(W, H); split also on screen size while step < refine_scale2d_stop
    prune_scale2d: float = 0.15  # x max(W, H); prune on screen size while step < refine_scale2d_stop
    refine_scale2d_stop: int = 0
    refine_start: int = 500
    refine_stop: int = 15_000
    refine_every: int = 100
    reset_opacity_every: int = 3000
    pause_refine_after_reset: int = 0
    split_scale_factor: float = 1.6
    max_gaussians: int = 0  # growth stops at this many Gaussians (0: no cap); see _grow


@dataclass(frozen=True)
class DensifyReport:
    """What one ``step_post_backward`` did."""

    n_cloned: int = 0
    n_split: int = 0
    n_pruned: int = 0
    opacity_reset: bool = False


def _get(meta: Any, name: str) -> Any:
    return meta[name] if isinstance(meta, Mapping) else getattr(meta, name)


class DensifyStrategy:
    """Stateful densification (see the module docstring).

    Typical use::

        optimizer = make_optimizer(model, GaussianLR(), scene_scale)
        strategy = DensifyStrategy(DensifyConfig(), scene_scale, seed=0)
        colors, alphas, meta = rasterize(...)
        strategy.step_pre_backward(meta)
        loss.backward()
        optimizer.step()
        strategy.step_post_backward(model, optimizer, meta, step, n_views=1)
        optimizer.zero_grad(set_to_none=True)

    (Calling ``step_post_backward`` before ``optimizer.step()`` also works, as in 3DGS; the
    replaced parameters then have no gradient and skip that one Adam step.)

    Args:
        config: thresholds and schedule.
        scene_scale: scene extent (world units) the 3D scale thresholds are relative to.
        seed: seed of the generator that samples split children.
        reset_opacity: whether opacity resets are on (also :meth:`disable_opacity_reset`).
    """

    def __init__(self, config: DensifyConfig = DensifyConfig(), scene_scale: float = 1.0,
                 seed: int = 0, reset_opacity: bool = True):
        self.config, self.scene_scale, self.seed = config, float(scene_scale), seed
        self.reset_opacity_enabled = bool(reset_opacity)
        self._generator: torch.Generator | None = None
        self.grad2d: torch.Tensor | None = None  # [N] summed gradient norms (NDC units)
        self.count: torch.Tensor | None = None  # [N] number of renders each was visible in
        self.max_radii: torch.Tensor | None = None  # [N] largest radius / max(W, H)

    def disable_opacity_reset(self) -> None:
        """Stop resetting opacities from now on."""
        self.reset_opacity_enabled = False

    def state_dict(self) -> dict[str, Any]:
        """What a resumed run needs to refine as this one would: the statistics gathered since the
        last refinement (``None`` when none), the split generator's state (``None`` before the
        first split) and whether opacity resets are on. Tensors are copies on the CPU."""
        def cpu(x: torch.Tensor | None) -> torch.Tensor | None:
            return None if x is None else x.detach().cpu().clone()

        gen = self._generator
        return {"grad2d": cpu(self.grad2d), "count": cpu(self.count), "max_radii": cpu(self.max_radii),
                "generator": None if gen is None else {"device": gen.device.type, "state": gen.get_state()},
                "reset_opacity_enabled": self.reset_opacity_enabled}

    def load_state_dict(self, state: Mapping[str, Any], device: torch.device | str = "cpu") -> None:
        """Continue from :meth:`state_dict`; statistics go to ``device`` (the model's). A generator
        saved on another kind of device is not restored (split children are then drawn afresh
        from ``seed``)."""
        def on(x: torch.Tensor | None) -> torch.Tensor | None:
            return None if x is None else x.to(device=device, dtype=torch.float32).clone()

        self.grad2d, self.count = on(state["grad2d"]), on(state["count"])
        self.max_radii = on(state["max_radii"])
        self.reset_opacity_enabled = bool(state["reset_opacity_enabled"])
        self._generator = None
        saved = state.get("generator")
        if saved is not None and saved["device"] == torch.device(device).type:
            self._generator = torch.Generator(device=device)
            self._generator.set_state(saved["state"])

    def step_pre_backward(self, meta: Any | Sequence[Any]) -> None:
        """Keep the gradient of ``meta.means2d`` (one meta or a sequence of them)."""
        for m in meta if isinstance(meta, (list, tuple)) else [meta]:
            means2d = _get(m, "means2d")
            if means2d.requires_grad and not means2d.is_leaf:
                means2d.retain_grad()

    def step_post_backward(self, model: GaussianModel, optimizers: Optimizers, meta: Any | Sequence[Any],
                           step: int, n_views: int = 1) -> DensifyReport:
        """Accumulate statistics from ``meta`` (one or a sequence) and refine / reset when due.

        Args:
            model: the Gaussians (its parameters are replaced when refining).
            optimizers: the optimiser(s) holding the model's parameters (edited in place).
            meta: rasteriser meta(s) with ``means2d`` (``[C, N, 2]`` with ``.grad``), ``radii``
                (``[C, N, 2]`` or ``[C, N]``, 0 = culled), ``width``, ``height``, ``n_cameras``.
            step: current training step.
            n_views: number of separately rendered views the loss averages (module docstring).
        """
        cfg = self.config
        if step >= cfg.refine_stop:
            return DensifyReport()
        for m in meta if isinstance(meta, (list, tuple)) else [meta]:
            self._accumulate(model, m, n_views)
        report = DensifyReport()
        if should_refine(step, cfg.refine_start, cfg.refine_stop, cfg.refine_every,
                         cfg.reset_opacity_every, cfg.pause_refine_after_reset):
            n_clone, n_split = self._grow(model, optimizers, step)
            n_prune = self._prune(model, optimizers, step)
            report = DensifyReport(n_clone, n_split, n_prune)
            self.grad2d = self.count = self.max_radii = None
        if should_reset_opacity(step, cfg.reset_opacity_every, cfg.refine_stop,
                                self.reset_opacity_enabled):
            reset_opacity(model, optimizers, 2 * cfg.prune_opacity)
            report = DensifyReport(report.n_cloned, report.n_split, report.n_pruned, True)
        return report

    def _accumulate(self, model: GaussianModel, meta: Any, n_views: int) -> None:
        means2d, radii = _get(meta, "means2d"), _get(meta, "radii")
        if means2d.grad is None:
            raise RuntimeError("meta.means2d has no gradient: call step_pre_backward(meta) before "
                               "backward")
        n = model.n
        if self.grad2d is None or self.grad2d.shape[0] != n:
            if self.grad2d is not None:
                raise RuntimeError(f"densification state holds {self.grad2d.shape[0]} Gaussians, "
                                   f"the model {n}: edit Gaussians only through the strategy")
            z = dict(device=model.means.device, dtype=torch.float32)
            self.grad2d, self.count, self.max_radii = (torch.zeros(n, **z) for _ in range(3))
        grad = means2d.grad.reshape(-1, n, 2).float()
        r = radii.reshape(grad.shape[0], n, -1)
        w, h = float(_get(meta, "width")), float(_get(meta, "height"))
        scale = float(_get(meta, "n_cameras")) * n_views
        grad = torch.stack([grad[..., 0] * (w / 2 * scale), grad[..., 1] * (h / 2 * scale)], -1)
        # masked sums over the cameras, not indexing of the visible pairs: no nonzero(), which
        # would wait for the GPU every step
        visible = (r > 0).all(-1)  # [C, N]
        self.grad2d += (grad.norm(dim=-1) * visible).sum(0)
        self.count += visible.sum(0)
        rad = r.amax(-1).float() / max(w, h) * visible
        self.max_radii = torch.maximum(self.max_radii, rad.amax(0))

    @torch.no_grad()
    def _grow(self, model: GaussianModel, optimizers: Optimizers, step: int) -> tuple[int, int]:
        cfg = self.config
        if self.grad2d is None:
            return 0, 0
        high = self.grad2d / self.count.clamp_min(1) > cfg.grow_grad2d
        small = model.scales.amax(-1) <= cfg.grow_scale3d * self.scene_scale
        clone, split = high & small, high & ~small
        if step < cfg.refine_scale2d_stop:
            split |= self.max_radii > cfg.grow_scale2d
        if cfg.max_gaussians > 0:
            clone, split = self._within_cap(clone, split, model.n)
        params = model.parameter_groups()
        new = {name: torch.cat([params[name][clone]] + [params[name][split]] * 2) for name in PARAM_NAMES}
        # Split children: means sampled from N(mu, R S^2 R^T), scales / 1.6 (3DGS §5).
        scales, R = model.scales[split], quat_to_matrix(model.quats[split])
        noise = torch.randn((2,) + scales.shape, generator=self._gen(model), device=scales.device,
                            dtype=scales.dtype)
        offsets = (R @ (scales * noise)[..., None])[..., 0].reshape(-1, 3)
        n_clone = int(clone.sum())
        new["means"][n_clone:] += offsets
        new["log_scales"][n_clone:] = torch.log(scales / cfg.split_scale_factor).repeat(2, 1)
        edit_gaussians(model, optimizers, ~split, new)
        mr = self.max_radii
        self.max_radii = torch.cat([mr[~split], mr[clone], mr[split], mr[split]])
        return n_clone, int(split.sum())

    def _within_cap(self, clone: torch.Tensor, split: torch.Tensor, n: int
                    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Keep the ``max_gaussians - n`` grow candidates with the largest mean gradients."""
        grow = clone | split
        room = max(self.config.max_gaussians - n, 0)
        if int(grow.sum()) <= room:
            return clone, split
        cand = grow.nonzero().squeeze(1)
        score = (self.grad2d / self.count.clamp_min(1))[cand]
        keep = torch.zeros_like(grow)
        keep[cand[torch.topk(score, room).indices]] = True
        return clone & keep, split & keep

    @torch.no_grad()
    def _prune(self, model: GaussianModel, optimizers: Optimizers, step: int) -> int:
        cfg = self.config
        prune = model.opacities < cfg.prune_opacity
        if step > cfg.reset_opacity_every:
            prune |= model.scales.amax(-1) > cfg.prune_scale3d * self.scene_scale
        if step < cfg.refine_scale2d_stop and self.max_radii is not None:
            prune |= self.max_radii > cfg.prune_scale2d
        if bool(prune.any()):
            edit_gaussians(model, optimizers, ~prune)
        return int(prune.sum())

    def _gen(self, model: GaussianModel) -> torch.Generator:
        if self._generator is None or self._generator.device != model.means.device:
            self._generator = torch.Generator(device=model.means.device).manual_seed(self.seed)
        return self._generator
