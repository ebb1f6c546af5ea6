"""Every event-loss form and colour mode trains: finite losses, θ moves after the warm-up only."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fusiongs.pipeline.deblur import resolve_config
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.train.trainer import train

BASE = ["init.n_points=200", "blur.n_samples=3", "events.warmup=3", "events.pixels=128",
        "optim.iterations=6", "densify.enabled=false", "output.progress=false",
        "output.checkpoint_every=0", "optim.refine_poses=false"]


@pytest.fixture(scope="module")
def colour_scene():
    cfg = SimConfig(preset="boxes", width=24, height=18, duration=0.1, frames=2, exposure=0.03,
                    dvs_rate_hz=500.0, blur_samples=4, supersample=1, novel=1, seed=2, cfa="RGGB")
    return run_simulation(cfg).scene


@pytest.mark.parametrize("loss", ["mse", "band", "pvc"])
@pytest.mark.parametrize("mode", ["mask", "demosaic"])
def test_colour_event_losses_train_and_learn_theta_after_warmup(colour_scene, tmp_path, loss, mode):
    cfg = resolve_config(None, BASE + [f"events.loss={loss}", f"events.colour_mode={mode}"])
    tr = train(colour_scene, cfg, tmp_path)
    h = tr.history
    assert all(math.isfinite(v) for v in h.loss)
    assert all(math.isnan(v) for v in h.event[:3]) and all(math.isfinite(v) for v in h.event[3:])
    assert h.theta_pos[0] == h.theta_pos[2], "θ is frozen during the warm-up (recorded after each step)"
    assert h.theta_pos[-1] != h.theta_pos[2], "θ is learned once events are on"
    assert len(h.theta_pos[-1]) == 3  # one threshold per colour channel


def test_events_disabled_trains_on_frames_only(colour_scene, tmp_path):
    cfg = resolve_config(None, BASE + ["events.enabled=false"])
    tr = train(colour_scene, cfg, tmp_path)
    assert all(math.isnan(v) for v in tr.history.event)
    assert all(math.isfinite(v) for v in tr.history.blur)


def test_lowpass_term_is_off_with_frames(colour_scene, tmp_path):
    """The low-pass term of long windows is for scenes without frames (with frames the blur loss
    fixes the large scales): asked for on a scene with frames, no step adds it."""
    cfg = resolve_config(None, BASE + ["events.lowpass_weight=1", "events.windows_free=2",
                                       "events.max_window=0.01"])
    tr = train(colour_scene, cfg, tmp_path)
    assert any(math.isfinite(v) for v in tr.history.event)  # the event windows ran
    assert all(math.isnan(v) for v in tr.history.event_lowpass)


def test_edi_prior_weight_decays_to_zero_at_its_end():
    from fusiongs.train.step import edi_prior_weight

    cfg = resolve_config(None, ["priors.edi_weight=0.5", "priors.edi_until=100"])
    assert edi_prior_weight(cfg, 0) == 0.5
    assert edi_prior_weight(cfg, 50) == pytest.approx(0.25)
    assert edi_prior_weight(cfg, 100) == 0.0 and edi_prior_weight(cfg, 1000) == 0.0
    assert edi_prior_weight(resolve_config(None, []), 0) == 0.0  # off by default


def test_edi_prior_is_used_while_on(colour_scene, tmp_path):
    cfg = resolve_config(None, BASE + ["priors.edi_weight=1.0", "priors.edi_until=4",
                                       "priors.edi_theta=0.2"])
    tr = train(colour_scene, cfg, tmp_path)
    assert tr.data.edi is not None and tr.data.edi.shape[-1] == 3
    assert all(math.isfinite(v) for v in tr.history.loss)
    assert all(math.isfinite(v) for v in tr.history.edi[:4])
    assert all(math.isnan(v) for v in tr.history.edi[4:])


def test_threshold_starts_from_the_calibration_unless_disabled(colour_scene):
    from fusiongs.calibrate.estimate import estimate_thresholds
    from fusiongs.events.thresholds import SensorThresholds
    from fusiongs.train.data import prepare_data
    from fusiongs.train.trainer import initial_theta

    expected = estimate_thresholds(colour_scene.frames, colour_scene.events)
    data = prepare_data(colour_scene, torch.device("cpu"), True)
    got = initial_theta(colour_scene, data, resolve_config(None, []))
    assert got.channels == ("R", "G", "B")
    np.testing.assert_allclose(got.as_array(), expected.as_array())
    off = resolve_config(None, ["threshold.estimate=false", "threshold.init=0.3"])
    np.testing.assert_allclose(initial_theta(colour_scene, data, off).as_array(), 0.3)
    given = SensorThresholds.uniform(0.2, 0.4, None)  # a grey calibration serves every channel
    np.testing.assert_allclose(initial_theta(colour_scene, data, off, given).as_array(),
                               [[0.2] * 3, [0.4] * 3])


def test_censored_counts_train_on_a_refractory_sensor(tmp_path):
    """``events.censor``: the fast events of a sensor with a dead time mark censored counts and the
    run trains (grey and mask mode); with ``events.censor=0`` nothing is marked."""
    from fusiongs.sim.dvs import DVSParams

    def scene(refractory, cfa):
        dvs = DVSParams(theta_on=0.1, theta_off=0.1, refractory_s=refractory)
        return run_simulation(SimConfig(preset="boxes", width=24, height=18, duration=0.1, frames=2,
                                        exposure=0.03, dvs_rate_hz=2000.0, blur_samples=4,
                                        supersample=1, novel=1, seed=2, cfa=cfa, dvs=dvs)).scene

    cfg = resolve_config(None, BASE + ["events.censor=2.0", "threshold.estimate=false"])
    for cfa in (None, "RGGB"):
        tr = train(scene(2e-3, cfa), cfg, tmp_path / str(cfa))
        assert tr.data.fast is not None and bool(tr.data.fast.any())
        assert all(math.isfinite(v) for v in tr.history.loss)
        assert all(math.isfinite(v) for v in tr.history.event[3:])
        # the window map marks exactly the pixels of the fast events in it, and radius 1 their
        # 3x3 neighbourhoods (scipy's maximum filter as the reference)
        from scipy.ndimage import maximum_filter

        from fusiongs.events.dead_time import dead_time_us
        from tests.reference.event_kernels import fast_event_mask

        ev = tr.data.events  # threshold.estimate=false: the trainer measured the dead time itself
        fast = fast_event_mask(ev, 2.0 * dead_time_us(ev))
        assert np.array_equal(tr.data.fast.numpy(), fast)
        t0, t1 = 0.02, 0.06
        sel = fast & (ev.t >= t0 * 1e6) & (ev.t < t1 * 1e6)
        ref = np.zeros(24 * 18, bool)
        ref[ev.y[sel].astype(np.int64) * 24 + ev.x[sel]] = True
        ref = ref.reshape(18, 24)
        assert ref.any()
        assert np.array_equal(tr.data.censored_map(t0, t1).numpy(), ref)
        assert np.array_equal(tr.data.censored_map(t0, t1, 1).numpy(),
                              maximum_filter(ref, size=3, mode="constant"))
    off = resolve_config(None, BASE + ["events.censor=0", "threshold.estimate=false"])
    assert train(scene(2e-3, None), off, tmp_path / "off").data.fast is None

    # the band loss (event-only's) gets the censored pixels too, in grey and mask mode
    import fusiongs.train.step as step

    seen = []
    real = step.event_loss_band

    def spy(*args, censored=None, **kwargs):
        seen.append(censored)
        return real(*args, censored=censored, **kwargs)

    band = resolve_config(None, BASE + ["events.censor=2.0", "threshold.estimate=false", "events.loss=band"])
    try:
        step.event_loss_band = spy
        for cfa in (None, "RGGB"):
            seen.clear()
            train(scene(2e-3, cfa), band, tmp_path / f"band{cfa}")
            assert seen and all(c is not None for c in seen)
            assert any(bool(c.any()) for c in seen) and not all(bool(c.all()) for c in seen)
    finally:
        step.event_loss_band = real


def test_threshold_pull_is_for_scenes_without_frames_only():
    """``threshold.regularise`` pulls θ toward its start only when no frame fixes its scale: with a
    frame in the scene the same θ offset costs nothing (the pull would hold one-frame scenes
    at an assumed scale 26-44 % off)."""
    from types import SimpleNamespace

    from fusiongs.losses.threshold import ContrastThreshold
    from fusiongs.train.trainer import _regularisers

    ct = ContrastThreshold(channels=3, init=(0.2, 0.25))
    with torch.no_grad():
        ct.log_theta.add_(0.1)
    state = SimpleNamespace(threshold=ct, log_gain=torch.zeros(3))
    cfg = resolve_config("event_only", [])
    assert cfg.threshold.regularise > 0
    assert _regularisers(state, cfg, n_frames=0).item() == pytest.approx(cfg.threshold.regularise * 6 * 0.01)
    assert _regularisers(state, cfg, n_frames=1).item() == 0.0
