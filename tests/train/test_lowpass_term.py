"""The low-pass term of one step against its definition, window pair by window pair.

``lowpass_term`` takes every pair's counts from one cumulative count over the step's instants
(``TrainData.cumulative_counts``) and every render's log once; the reference
(``tests.reference.lowpass_pairwise``) is the term as first written: ``count_maps``,
``censored_map`` and ``delta_log`` for each pair.
"""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from fusiongs.io import load_scene
from fusiongs.losses.threshold import ContrastThreshold
from fusiongs.pipeline.deblur import resolve_config
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene
from fusiongs.train.data import prepare_data, square_dilate
from fusiongs.train.lowpass_term import lowpass_term
from tests.reference.lowpass_pairwise import lowpass_term_pairwise

CPU = torch.device("cpu")


@pytest.fixture(scope="module", params=[None, "RGGB"], ids=["grey", "rggb"])
def data(request, tmp_path_factory):
    root = tmp_path_factory.mktemp("lp")
    cfg = SimConfig(preset="wall", width=32, height=24, duration=0.15, frames=0, novel=1,
                    dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=7, cfa=request.param)
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, root, overwrite=True)
    d = prepare_data(load_scene(root), CPU, True)
    # a fifth of the events marked fast at random (what matters here is the bookkeeping)
    d.fast = torch.rand(len(d.events), generator=torch.Generator().manual_seed(2)) < 0.2
    return d


def _times(data, n, seed):
    t0, t1 = data.t_range
    g = np.random.default_rng(seed)
    return sorted(float(t) for t in g.uniform(t0, t1, n))


def test_cumulative_counts_are_the_count_and_censored_maps_of_every_window(data):
    times = _times(data, 5, 0)
    counts, fast = data.cumulative_counts(times, CPU)
    h, w = data.camera.height, data.camera.width
    assert counts.shape == (5, 2, h * w) and fast.shape == (5, h * w)
    assert float(counts[0].abs().sum()) == 0 and float(fast[0].abs().sum()) == 0
    for a, b in itertools.combinations(range(5), 2):
        ref = data.count_maps(times[a], times[b], CPU).reshape(2, -1)
        assert torch.equal(counts[b] - counts[a], ref)
        diff = (fast[b] - fast[a]).reshape(h, w)
        for radius in (0, 1):
            assert torch.equal(square_dilate(diff, radius) > 0, data.censored_map(times[a], times[b], radius))
    assert float(counts[-1].sum()) > 0 and float(fast[-1].sum()) > 0
    saved, data.fast = data.fast, None
    try:
        assert data.cumulative_counts(times, CPU)[1] is None
    finally:
        data.fast = saved


@pytest.mark.parametrize("radius", [0, 1])
def test_lowpass_term_matches_the_pair_by_pair_reference_with_gradients(data, radius):
    cfg = resolve_config("event_only", [f"events.censor_radius={radius}"])
    h, w = data.camera.height, data.camera.width
    channels = 1 if data.cfa_index is None else 3
    state = SimpleNamespace(threshold=ContrastThreshold(channels=channels, init=(0.2, 0.3)))
    t = _times(data, 6, 1)
    # three windows' ends, two of them at one instant (snapped read-outs can coincide)
    ends = [(0, t[0], 0), (1, t[3], 0), (2, t[1], 1), (3, t[5], 1), (4, t[2], 2), (5, t[3], 2)]
    g = torch.Generator().manual_seed(3)
    lin = (0.05 + torch.rand(6, h, w, 3, generator=g)).requires_grad_(True)
    fast = lowpass_term(state, data, cfg, lin, ends, 0.0)
    slow = lowpass_term_pairwise(state, data, cfg, lin, ends, 0.0)
    assert torch.allclose(fast, slow, rtol=1e-6, atol=0)
    params = [lin, *state.threshold.parameters()]
    grads_fast, grads_slow = torch.autograd.grad(fast, params), torch.autograd.grad(slow, params)
    for gf, gs in zip(grads_fast, grads_slow):
        assert torch.allclose(gf, gs, rtol=1e-5, atol=1e-9)
    assert all(float(gf.abs().sum()) > 0 for gf in grads_fast)


def test_kept_ends_of_earlier_steps_match_the_reference_and_carry_no_gradient(data):
    """``events.lowpass_history``: a step's ends against those of the two steps before it (kept as
    log images) give the reference's loss on the renders of all three steps, the earlier ones
    detached; pairs of two kept ends are left out, and the history keeps two steps."""
    from fusiongs.train.lowpass_term import LowpassHistory, cross_pairs

    cfg = resolve_config("event_only", ["events.censor_radius=1", "events.lowpass_history=2"])
    h, w = data.camera.height, data.camera.width
    channels = 1 if data.cfa_index is None else 3
    state = SimpleNamespace(threshold=ContrastThreshold(channels=channels, init=(0.2, 0.3)))
    g = torch.Generator().manual_seed(5)
    history = LowpassHistory(2)
    steps = []
    for k in range(4):  # the first step keeps nothing, the fourth forgets the first
        t = _times(data, 4, 10 + k)
        ends = [(0, t[0], 0), (1, t[2], 0), (2, t[1], 1), (3, t[3], 1)]
        lin = (0.05 + torch.rand(4, h, w, 3, generator=g)).requires_grad_(True)
        kept = list(steps[-2:])
        fast = lowpass_term(state, data, cfg, lin, ends, 0.0, history)
        steps.append((lin.detach(), [t for _, t, _ in ends]))
        if not kept:
            assert torch.allclose(fast, lowpass_term_pairwise(state, data, cfg, lin, ends, 0.0), rtol=1e-6)
            continue
        past_lin = torch.cat([p for p, _ in kept])
        past_t = [t for _, ts in kept for t in ts]
        all_ends = ends + [(4 + i, tp, 2 + i) for i, tp in enumerate(past_t)]
        slow = lowpass_term_pairwise(state, data, cfg, torch.cat([lin, past_lin]), all_ends, 0.0, n_current=4)
        assert len(cross_pairs(all_ends, 0.0, 4)) == 4 + 4 * len(past_t)  # none of two kept ends
        assert torch.allclose(fast, slow, rtol=1e-6, atol=0)
        params = [lin, *state.threshold.parameters()]
        for gf, gs in zip(torch.autograd.grad(fast, params), torch.autograd.grad(slow, params)):
            assert torch.allclose(gf, gs, rtol=1e-5, atol=1e-9)
    assert len(history.ends()) == 8 and [t for t, _ in history.ends()] == steps[-2][1] + steps[-1][1]


def test_lowpass_history_setting_is_an_integer_at_least_zero():
    from fusiongs.errors import ConfigError

    with pytest.raises(ConfigError, match=r"events.lowpass_history: expected an integer >= 0"):
        resolve_config("event_only", ["events.lowpass_history=-1"])
    assert resolve_config("event_only", []).events.lowpass_history == 0
