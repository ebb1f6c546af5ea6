"""The relative colour step: each colour's optimiser step scaled by its own level (``optim.colour_step``)."""

import pytest
import torch

from fusiongs.scene.gaussians import SH_C0, GaussianModel
from fusiongs.scene.optim import GaussianLR, make_optimizer, relative_colour_step


def _model(levels: torch.Tensor, sh_degree: int = 1) -> GaussianModel:
    """Gaussians whose base colour is ``levels`` ``[N, 3]`` (linear)."""
    xyz = torch.arange(levels.shape[0] * 3, dtype=torch.float32).reshape(-1, 3)
    m = GaussianModel.from_points(xyz, sh_degree=sh_degree)
    with torch.no_grad():
        m.sh0.copy_(((levels - 0.5) / SH_C0)[:, None, :])
    return m


def test_each_colour_change_is_scaled_by_its_level_and_nothing_else_is():
    levels = torch.tensor([[0.5, 0.5, 0.5], [0.05, 0.2, 2.0], [-0.3, 0.0, 1e-4]])
    m = _model(levels)
    with torch.no_grad():
        m.shN.normal_()
    opt = torch.optim.SGD(list(m.parameter_groups().values()), lr=0.1)
    before = {k: p.detach().clone() for k, p in m.parameter_groups().items()}
    grads = {k: torch.randn_like(p) for k, p in m.parameter_groups().items()}
    for k, p in m.parameter_groups().items():
        p.grad = grads[k].clone()
    floor = 1e-3
    relative_colour_step(m, opt.step, floor)
    scale = levels.clamp_min(floor)[:, None, :] / 0.5  # [N, 1, 3]
    torch.testing.assert_close(m.sh0 - before["sh0"], -0.1 * grads["sh0"] * scale)
    torch.testing.assert_close(m.shN - before["shN"], -0.1 * grads["shN"] * scale)
    for k in ("means", "log_scales", "quats", "opacity_logits"):
        torch.testing.assert_close(m.parameter_groups()[k] - before[k], -0.1 * grads[k])
    # at the grey start (0.5) the step is the linear one
    torch.testing.assert_close(m.sh0[0] - before["sh0"][0], -0.1 * grads["sh0"][0])


def _fit_log_colour(levels: torch.Tensor, relative: bool, steps: int = 200) -> torch.Tensor:
    """``steps`` Adam steps on ``sum (log c - log(2 c0))^2``; returns the change of ``log c`` ``[N, 3]``."""
    m = _model(levels, sh_degree=0)
    opt = make_optimizer(m, GaussianLR())
    target = torch.log(2 * levels)
    for _ in range(steps):
        loss = (torch.log(m.base_colors()) - target).square().sum()
        loss.backward()
        if relative:
            relative_colour_step(m, opt.step, 1e-3)
        else:
            opt.step()
        opt.zero_grad(set_to_none=True)
    return torch.log(m.base_colors().detach()) - torch.log(levels)


def test_relative_steps_move_log_colour_alike_at_every_level():
    # Adam on the linear colour changes log c by about lr / c a step: 10x faster at 0.05 than at
    # 0.5. With the relative step the same loss in log c moves every level alike (Adam on log c).
    levels = torch.tensor([[0.05, 0.05, 0.05], [0.5, 0.5, 0.5], [3.0, 3.0, 3.0]])
    rel = _fit_log_colour(levels, relative=True)
    lin = _fit_log_colour(levels, relative=False)
    assert (rel[1] > 0.2).all()  # it moves: 200 steps of ~C0 lr / 0.5 in log c (0.28), toward 0.69
    torch.testing.assert_close(rel[0], rel[1], rtol=0.05, atol=0)
    torch.testing.assert_close(rel[2], rel[1], rtol=0.05, atol=0)
    assert (lin[0] > 3 * lin[1]).all() and (lin[2] < lin[1] / 3).all()


def test_relative_step_floor_keeps_non_positive_colours_movable():
    m = _model(torch.tensor([[-0.2, 0.0, 0.3]]), sh_degree=0)
    opt = torch.optim.SGD([m.sh0], lr=1.0)
    m.sh0.grad = -torch.ones_like(m.sh0)
    before = m.sh0.detach().clone()
    relative_colour_step(m, opt.step, 0.01)
    torch.testing.assert_close(m.sh0 - before, torch.tensor([[[0.02, 0.02, 0.6]]]))
    assert ((m.sh0 * SH_C0 + 0.5) > (before * SH_C0 + 0.5)).all()


def test_colour_step_is_a_checked_config_choice():
    from fusiongs.configs.load import load_config
    from fusiongs.errors import ConfigError
    from fusiongs.train.settings import DeblurConfig

    assert load_config(DeblurConfig, None, ["optim.colour_step=relative"]).optim.colour_step == "relative"
    with pytest.raises(ConfigError, match=r"optim.colour_step.*'linear', 'relative'.*'log'"):
        load_config(DeblurConfig, None, ["optim.colour_step=log"])
    with pytest.raises(ConfigError, match=r"optim.colour_step_floor: expected a finite number > 0"):
        load_config(DeblurConfig, None, ["optim.colour_step_floor=0"])
    with pytest.raises(ConfigError, match=r"optim.colour_step_start: expected a finite number >= 0"):
        load_config(DeblurConfig, None, ["optim.colour_step_start=-1"])


def test_trainer_applies_the_relative_step_to_the_gaussians_only_when_configured():
    from types import SimpleNamespace

    from fusiongs.configs.load import load_config
    from fusiongs.train.settings import DeblurConfig
    from fusiongs.train.trainer import _optimise

    levels = torch.tensor([[0.05, 0.5, 2.0]])
    linear, relative = torch.ones(1, 1, 3), levels[:, None, :] / 0.5
    floored = levels.clamp_min(0.5)[:, None, :] / 0.5
    cases = (("linear", 0, [], linear), ("relative", 0, [], relative),
             ("relative", 0, ["optim.colour_step_floor=0.5"], floored),
             ("relative", 99, ["optim.colour_step_start=100"], linear),
             ("relative", 100, ["optim.colour_step_start=100"], relative))
    for step, it, extra, expected in cases:
        m = _model(levels, sh_degree=0)
        opts = {"gaussians": torch.optim.SGD([m.sh0], lr=1.0)}
        m.sh0.grad = -torch.ones_like(m.sh0)
        cfg = load_config(DeblurConfig, None, [f"optim.colour_step={step}", *extra])
        before = m.sh0.detach().clone()
        _optimise(opts, cfg, it, SimpleNamespace(model=m))
        torch.testing.assert_close(m.sh0 - before, expected)
        assert m.sh0.grad is None


def test_relative_step_is_the_configured_one_at_the_reference_level():
    # a start from a frame's fill: the colour rates are already scaled to the fill's level, so the
    # relative step leaves that level's change as the optimiser made it
    from types import SimpleNamespace

    from fusiongs.configs.load import load_config
    from fusiongs.train.settings import DeblurConfig
    from fusiongs.train.trainer import _optimise

    levels = torch.tensor([[0.1, 0.2, 0.8]])
    m = _model(levels, sh_degree=0)
    opts = {"gaussians": torch.optim.SGD([m.sh0], lr=1.0)}
    m.sh0.grad = -torch.ones_like(m.sh0)
    before = m.sh0.detach().clone()
    cfg = load_config(DeblurConfig, None, ["optim.colour_step=relative"])
    _optimise(opts, cfg, 0, SimpleNamespace(model=m), colour_scale=0.4)  # fill level 0.2
    torch.testing.assert_close(m.sh0 - before, levels[:, None, :] / 0.2)
