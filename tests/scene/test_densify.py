from dataclasses import dataclass

import pytest
import torch

from fusiongs.scene.densify import DensifyConfig, DensifyStrategy, should_refine, should_reset_opacity
from fusiongs.scene.gaussians import PARAM_NAMES, GaussianModel
from fusiongs.scene.optim import edit_gaussians, make_optimizer, reset_opacity


@dataclass
class FakeMeta:
    means2d: torch.Tensor
    radii: torch.Tensor
    width: int
    height: int
    n_cameras: int


def _model(n=6, scale=0.001, opacity=0.5):
    xyz = torch.arange(n * 3, dtype=torch.float32).reshape(n, 3)
    m = GaussianModel.from_points(xyz, sh_degree=1, init_opacity=opacity)
    with torch.no_grad():
        m.log_scales.fill_(torch.log(torch.tensor(scale)))
    return m


def _meta_with_grad(model, pixel_grad, radii, width=100, height=50):
    """A meta whose means2d.grad equals ``pixel_grad`` [C, N, 2], as after a backward pass."""
    means2d = (model.means[None, :, :2] * 0).expand(pixel_grad.shape[0], -1, -1).clone()
    meta = FakeMeta(means2d, radii, width, height, pixel_grad.shape[0])
    DensifyStrategy().step_pre_backward(meta)
    (meta.means2d * pixel_grad).sum().backward()
    return meta


def _adam_step(model, opt):
    loss = sum(p.square().sum() for p in model.parameter_groups().values())
    loss.backward()
    opt.step()
    opt.zero_grad()


def test_should_refine_boundaries():
    args = dict(start=500, stop=15000, every=100)
    assert [s for s in range(0, 20000, 50) if should_refine(s, **args)] == list(range(600, 15000, 100))
    assert not should_refine(100, 0, 1000, 0)
    paused = [s for s in range(0, 7000, 100) if should_refine(s, 0, 15000, 100, 3000, 300)]
    assert 3000 not in paused and 3200 not in paused and 3300 in paused and 2900 in paused


def test_should_reset_opacity_fires_every_k_steps_before_stop():
    steps = range(0, 20000)
    assert [s for s in steps if should_reset_opacity(s, 3000, 15000)] == [3000, 6000, 9000, 12000]
    assert [s for s in steps if should_reset_opacity(s, 3000, 7000)] == [3000, 6000]
    assert not any(should_reset_opacity(s, 3000, 15000, enabled=False) for s in steps)
    assert not any(should_reset_opacity(s, 0, 15000) for s in steps)


@pytest.mark.parametrize("as_dict", [False, True])
def test_edit_gaussians_keeps_adam_state_in_step_with_parameters(as_dict):
    m = _model()
    if as_dict:
        opt = {name: torch.optim.Adam([p], lr=1e-3) for name, p in m.parameter_groups().items()}
        opts, adam = opt, opt["means"]
    else:
        opt = make_optimizer(m)
        opts, adam = opt, opt
    for o in (opt.values() if as_dict else [opt]):
        _adam_step(m, o)
    old_avg = adam.state[m.means]["exp_avg"].clone()
    keep = torch.tensor([True, False, True, True, False, True])
    new = {name: p.detach()[:2].clone() for name, p in m.parameter_groups().items()}
    edit_gaussians(m, opts, keep, new)
    assert m.n == 6
    state = adam.state[m.means]
    assert torch.equal(state["exp_avg"][:4], old_avg[keep])
    assert torch.equal(state["exp_avg"][4:], torch.zeros(2, 3))
    assert state["exp_avg_sq"].shape == (6, 3)
    groups = [g for o in (opt.values() if as_dict else [opt]) for g in o.param_groups]
    held = {id(p) for g in groups for p in g["params"]}
    assert held == {id(p) for p in m.parameter_groups().values()}
    for o in (opt.values() if as_dict else [opt]):
        _adam_step(m, o)  # no shape mismatch after the edit


def test_reset_opacity_clamps_and_zeros_state():
    m = _model(opacity=0.5)
    opt = make_optimizer(m)
    _adam_step(m, opt)
    reset_opacity(m, opt, 0.01)
    assert torch.allclose(m.opacities, torch.full((6,), 0.01))
    assert torch.count_nonzero(opt.state[m.opacity_logits]["exp_avg"]) == 0
    assert torch.count_nonzero(opt.state[m.means]["exp_avg"]) > 0


def test_accumulated_gradient_is_scaled_to_ndc_cameras_and_views():
    m = _model(n=3)
    g = torch.zeros(2, 3, 2)
    g[:, 0] = torch.tensor([1e-4, 0.0])
    g[0, 1] = torch.tensor([0.0, 2e-4])
    radii = torch.ones(2, 3, 2, dtype=torch.int32)
    radii[1, 1] = 0  # Gaussian 1 culled in camera 1
    radii[:, 2] = 0  # Gaussian 2 never visible
    for meta in (_meta_with_grad(m, g, radii), vars(_meta_with_grad(m, g, radii))):  # dataclass or dict
        s = DensifyStrategy(DensifyConfig(refine_start=10))
        s.step_post_backward(m, None, meta, step=1, n_views=3)
        factor = 2 * 3  # n_cameras x n_views
        assert torch.allclose(s.grad2d, torch.tensor([2 * 1e-4 * 50 * factor, 2e-4 * 25 * factor, 0]))
        assert torch.equal(s.count, torch.tensor([2.0, 1.0, 0.0]))


def test_refine_clones_small_splits_large_and_prunes_transparent():
    m = _model(n=4, scale=0.001)
    with torch.no_grad():
        m.log_scales[1] = torch.log(torch.tensor(0.5))  # large: split
        m.opacity_logits[3] = -10.0  # transparent: pruned
    opt = make_optimizer(m)
    _adam_step(m, opt)
    g = torch.zeros(1, 4, 2)
    g[0, :2] = 1e-3  # Gaussians 0 (small) and 1 (large) have high gradients
    meta = _meta_with_grad(m, g, torch.ones(1, 4, 2, dtype=torch.int32))
    parent_mean, parent_scale = m.means[1].detach().clone(), m.scales[1].detach().clone()
    s = DensifyStrategy(DensifyConfig(refine_start=0, refine_every=10), seed=0)
    report = s.step_post_backward(m, opt, meta, step=10)
    assert (report.n_cloned, report.n_split, report.n_pruned) == (1, 1, 1)
    assert m.n == 5  # 4, +1 clone, +1 split (parent replaced by 2 children), -1 pruned
    # Order after the edit: kept [0, 2] then clone of 0, then the two children of 1.
    children = m.means[-2:].detach()
    assert torch.allclose(m.scales[-2:], (parent_scale / 1.6).expand(2, 3))
    assert not torch.equal(children[0], children[1])
    assert ((children - parent_mean).abs() < 5 * 0.5).all()
    assert torch.equal(m.means[2], m.means[0])
    assert s.grad2d is None  # statistics restart after a refinement
    _adam_step(m, opt)


@pytest.mark.parametrize("cap, grown", [(8, [4, 5]), (6, []), (0, [0, 1, 2, 3, 4, 5])])
def test_growth_stops_exactly_at_the_cap_with_the_largest_gradients_first(cap, grown):
    m = _model(n=6, scale=0.001)
    with torch.no_grad():
        m.log_scales[5] = torch.log(torch.tensor(0.5))  # large: split (one more Gaussian, as a clone)
    opt = make_optimizer(m)
    g = torch.zeros(1, 6, 2)
    g[0, :, 0] = torch.tensor([1.0, 2.0, 3.0, 4.0, 6.0, 5.0]) * 1e-3  # all above the threshold
    meta = _meta_with_grad(m, g, torch.ones(1, 6, 2, dtype=torch.int32))
    s = DensifyStrategy(DensifyConfig(refine_start=0, refine_every=10, max_gaussians=cap), seed=0)
    report = s.step_post_backward(m, opt, meta, step=10)
    assert report.n_cloned + report.n_split == len(grown)
    assert report.n_split == int(5 in grown)
    assert m.n == 6 + len(grown)
    if cap:
        assert m.n <= max(cap, 6)


def test_opacity_reset_happens_over_several_steps_and_can_be_disabled():
    cfg = DensifyConfig(refine_start=100, refine_stop=10, reset_opacity_every=3, prune_opacity=0.005)
    for enabled in (True, False):
        m = _model(n=3, opacity=0.5)
        opt = make_optimizer(m)
        s = DensifyStrategy(cfg, reset_opacity=enabled)
        resets = []
        for step in range(12):
            meta = _meta_with_grad(m, torch.zeros(1, 3, 2), torch.ones(1, 3, 2, dtype=torch.int32))
            if step == 7:
                s.disable_opacity_reset()
            report = s.step_post_backward(m, opt, meta, step)
            if report.opacity_reset:
                resets.append(step)
                assert torch.allclose(m.opacities, torch.full((3,), 0.01))
            with torch.no_grad():
                m.opacity_logits.fill_(0.0)  # "training" raises opacity again
        assert resets == ([3, 6] if enabled else [])


def test_missing_gradient_is_reported():
    m = _model(n=2)
    meta = FakeMeta(torch.zeros(1, 2, 2), torch.ones(1, 2, 2), 10, 10, 1)
    with pytest.raises(RuntimeError, match="step_pre_backward"):
        DensifyStrategy().step_post_backward(m, None, meta, step=1)


def test_param_names_cover_the_model():
    assert set(PARAM_NAMES) == {name for name, _ in _model().named_parameters()}


def test_a_strategy_continued_from_its_state_dict_refines_as_the_original():
    """What a resumed run relies on: the statistics since the last refinement and the split
    generator come back, so the next refinement grows the same Gaussians with the same children."""
    cfg = DensifyConfig(refine_start=0, refine_every=10, prune_opacity=0.0)

    def run(restart: str) -> GaussianModel:
        m = _model(n=4, scale=0.001)
        with torch.no_grad():
            m.log_scales[1] = torch.log(torch.tensor(0.5))  # large: split at 10 and 20
        opt = make_optimizer(m)
        s = DensifyStrategy(cfg, seed=3)
        for step, grad in ((5, 1e-3), (10, 1e-3), (15, 1e-3), (20, 0.0)):
            if step == 20 and restart != "none":  # a new strategy, as in a run resumed here
                saved = s.state_dict()
                s = DensifyStrategy(cfg, seed=3)
                if restart == "state_dict":
                    s.load_state_dict(saved)
            g = torch.full((1, m.n, 2), grad)
            meta = _meta_with_grad(m, g, torch.ones(1, m.n, 2, dtype=torch.int32))
            s.step_post_backward(m, opt, meta, step=step)
        return m

    original, resumed, fresh = run("none"), run("state_dict"), run("fresh")
    assert original.n > 6  # grown at 20 from the statistics of step 15
    assert resumed.n == original.n and torch.equal(resumed.means, original.means)
    assert fresh.n != original.n  # without them the refinement at 20 differs
