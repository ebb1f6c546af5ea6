"""Chained free windows (``events.chain_windows``): n windows in n + 1 renders, the intensity
anchor between read-outs (``hpf_image_at``) against the filter itself, and the step's renders."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from fusiongs.cli import main
from fusiongs.configs import config_file
from fusiongs.errors import ConfigError, InputError
from fusiongs.events.hpf import high_pass_filter
from fusiongs.io import load_scene
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene
from fusiongs.train import trainer
from fusiongs.train.data import hpf_image_at, hpf_images, prepare_data
from fusiongs.train.schedules import sample_chained_windows
from fusiongs.train.settings import EventSettings

CPU = torch.device("cpu")


def test_chained_windows_share_ends_and_keep_log_uniform_lengths():
    g = torch.Generator().manual_seed(3)
    chains = torch.stack([sample_chained_windows(2, (0.0, 10.0), 0.05, g) for _ in range(3000)])
    assert chains.shape == (3000, 3) and chains.dtype == torch.float64
    assert (chains[:, 0] >= 0).all() and (chains[:, -1] <= 10.0).all()
    dur = chains.diff(dim=1)  # [3000, 2]: each window's length
    assert dur.min() >= 1e-3 - 1e-12 and dur.max() <= 0.05 + 1e-12
    for k in range(2):  # each window log-uniform, as sample_free_windows draws them
        assert dur[:, k].median().item() == pytest.approx(math.sqrt(1e-3 * 0.05), rel=0.1)
    # the two lengths are drawn independently
    assert abs(np.corrcoef(dur[:, 0].log().numpy(), dur[:, 1].log().numpy())[0, 1]) < 0.06
    # the start is spread over the whole range
    assert chains[:, 0].min() < 0.5 and chains[:, -1].max() > 9.5


def test_chained_windows_longer_than_the_range_are_scaled_into_it():
    g = torch.Generator().manual_seed(4)
    for _ in range(50):
        p = sample_chained_windows(3, (1.0, 1.004), 0.05, g, min_duration=0.003)
        assert p[0] >= 1.0 and p[-1] <= 1.004 and (p.diff() > 0).all()
        assert float(p[-1] - p[0]) == pytest.approx(0.004)  # 3 windows of >= 3 ms fill 4 ms


def test_chained_windows_need_one_window_at_least():
    with pytest.raises(InputError, match="sample_chained_windows"):
        sample_chained_windows(0, (0.0, 1.0), 0.05)


def test_chained_windows_are_refused_with_pvc_targets():
    with pytest.raises(ConfigError, match="events.chain_windows"):
        EventSettings(loss="pvc", chain_windows=True)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("chain")
    cfg = SimConfig(preset="wall", width=32, height=24, duration=0.15, frames=0, novel=2,
                    dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=5, cfa="RGGB")
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, root, overwrite=True)
    return root


def test_anchor_between_read_outs_follows_the_filter(scene):
    data = prepare_data(load_scene(scene), CPU, True)
    tau, c = 0.05, 0.22
    data.hpf_times, data.hpf = hpf_images(data.events, data.t_range, 20, tau, c, CPU)
    for g in (0, 7, 19):  # a read-out instant gives the read-out itself
        t = float(data.hpf_times[g])
        assert torch.equal(hpf_image_at(data, t, tau, c), data.hpf[g])
    step = float(data.hpf_times[1] - data.hpf_times[0])
    ts = [float(data.hpf_times[g]) + f * step for g in (3, 11) for f in (0.3, 0.8)]
    exact = torch.from_numpy(high_pass_filter(data.events, np.array(ts) * 1e6, tau=tau, contrast=c))
    h, w = data.camera.height, data.camera.width
    for t, v in zip(ts, exact):
        got = hpf_image_at(data, t, tau, c)[..., 0]
        g = int(np.searchsorted(data.hpf_times.numpy(), t, side="right")) - 1
        dt = t - float(data.hpf_times[g])
        n = data.events.slice_time(int(round(float(data.hpf_times[g]) * 1e6)), int(round(t * 1e6)))
        per_pixel = np.bincount(n.y.astype(np.int64) * w + n.x, minlength=h * w).reshape(h, w)
        assert per_pixel.sum() > 0  # the segment has events, so the read-out alone is stale
        # the midpoint decay is off by at most 1 - exp(-dt / 2τ) of each event's step
        bound = c * (1.0 - math.exp(-0.5 * dt / tau)) * torch.from_numpy(per_pixel) + 1e-5
        assert ((got - v).abs() <= bound).all()
        stale = (data.hpf[g][..., 0] * math.exp(-dt / tau) - v).abs().max()
        assert (got - v).abs().max() < 0.2 * stale


def test_a_chained_step_renders_one_instant_more_than_its_windows(scene, tmp_path, monkeypatch):
    counts = []
    real = trainer.training_step

    def step(*args, **kwargs):
        res = real(*args, **kwargs)
        counts.append(int(res.renders.shape[0]))
        return res

    monkeypatch.setattr(trainer, "training_step", step)
    args = ["deblur", str(scene), "-o", str(tmp_path), "--config", str(config_file("event_only.yaml")),
            "init.n_points=300", "events.pixels=256", "optim.iterations=8", "densify.enabled=false",
            "event_only.alpha_warmup=3", "event_only.alpha_ramp=2", "event_only.hpf_readouts=20",
            "output.progress=false", "output.checkpoint_every=0", "events.windows_free=3",
            "events.chain_windows=true", "events.max_window=0.03", "events.lowpass_weight=1"]
    assert main(args) == 0
    assert counts == [4] * 8  # 3 windows in 4 renders (6 unchained)
    rows = [json.loads(line) for line in (tmp_path / "history.jsonl").read_text().splitlines()]
    assert all(r.get("intensity") is not None for r in rows)
    assert any(r.get("event") is not None for r in rows)
