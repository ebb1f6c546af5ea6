"""The pixel model test of ``fusiongs calibrate``: the coefficient on a reset pixel's extra crossings."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.calibrate.data import frame_pairs
from fusiongs.calibrate.estimate import estimate_thresholds
from fusiongs.calibrate.fit import PairData
from fusiongs.calibrate.options import CalibrateOptions
from fusiongs.calibrate.pixel_model import excess_coefficient
from fusiongs.errors import InputError
from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.simulate import SimConfig, run_simulation


def _pairs_data(rng, theta, beta, n_frames=8, n_pix=3000, max_gap=3):
    """A plain and a weighted :class:`PairData` whose log changes follow
    ``theta_+ (N_+ + beta E_+) - theta_- (N_- + beta E_-)`` plus noise; the instruments are the
    true counts and excesses with noise of their own (the neighbours' view of the same change)."""
    tp, tn = theta
    rate = rng.gamma(2.0, 1.5, size=(1, 2, n_pix))  # busy and quiet pixels
    k = rng.poisson(rate, size=(n_frames - 1, 2, n_pix)).astype(np.float64)
    e = rng.gamma(1.0, 0.3 * rate, size=k.shape) * (k > 0)  # the excess grows with the pixel's rate
    change = tp * (k[:, 0] + beta * e[:, 0]) - tn * (k[:, 1] + beta * e[:, 1])
    log_s = np.concatenate([np.zeros((1, n_pix)), np.cumsum(change + rng.normal(0, 0.05, change.shape), 0)])
    log_s += rng.normal(0, 0.1, (1, n_pix)) + rng.normal(0, 0.2, (n_frames, 1))  # pixel and frame offsets
    pairs = frame_pairs(n_frames, max_gap)

    def span(v):  # counts between the two frames of every pair
        c = np.concatenate([np.zeros((1, *v.shape[1:])), np.cumsum(v, 0)])
        return torch.as_tensor(c[pairs[:, 1]] - c[pairs[:, 0]], dtype=torch.float32)

    zk = k + rng.normal(0, 0.7, k.shape)
    ze = e + rng.normal(0, 0.3, e.shape)
    n = torch.zeros(n_frames, 1, 2, n_pix)  # instantaneous exposures: no EDI term
    common = dict(log_s=torch.as_tensor(log_s, dtype=torch.float32), n=n, pairs=torch.as_tensor(pairs),
                  valid=torch.ones(len(pairs), n_pix, dtype=torch.bool),
                  tile=torch.zeros(n_pix, dtype=torch.int64), n_tiles=1)
    plain = PairData(dn=span(k), z=span(zk), **common)
    weighted = PairData(dn=span(k + e), z=span(zk + ze), **common)
    return plain, weighted


@pytest.mark.parametrize("beta", [0.0, 1.0])
def test_excess_coefficient_recovers_the_pixel_model(beta):
    rng = np.random.default_rng(3)
    channels = []
    for theta in ((0.2, 0.3), (0.25, 0.35)):  # two channels, each with its own thresholds
        plain, weighted = _pairs_data(rng, theta, beta)
        channels.append((plain, weighted, (0.8 * theta[0], 1.2 * theta[1])))  # a rough start
    est = excess_coefficient(channels)
    assert abs(est - beta) < 0.1, est
    # a channel's start does not decide it: the thresholds are re-solved with beta
    assert abs(excess_coefficient(channels[:1]) - beta) < 0.15


def test_excess_coefficient_without_channels_or_signal_is_nan():
    assert np.isnan(excess_coefficient([]))
    rng = np.random.default_rng(0)
    plain, weighted = _pairs_data(rng, (0.2, 0.3), 1.0)
    same = (plain, plain, (0.2, 0.3))  # no excess at all: the coefficient is not identified
    assert np.isnan(excess_coefficient([same]))


def _scene(reset: bool):
    dvs = DVSParams(theta_on=0.2, theta_off=0.3, theta_sigma=0.02, refractory_s=6e-4,
                    refractory_reset=reset, ba_rate_hz=0.2)
    cfg = SimConfig(preset="wall", width=96, height=72, duration=0.5, frames=6, exposure=0.04,
                    dvs_rate_hz=1000.0, blur_samples=8, supersample=1, novel=0, seed=4, dvs=dvs)
    return run_simulation(cfg).scene


@pytest.mark.parametrize("reset", [False, True])
def test_auto_keeps_the_pixel_model_the_sensor_has(reset):
    """The same scene and sensor, its pixel held in reset during the dead time or not: "auto"
    measures the frames' coefficient on the reset model's extra crossings and keeps that model."""
    sc = _scene(reset)
    th = estimate_thresholds(sc.frames, sc.events)
    test = th.details["pixel_model_test"]
    assert test["channels"] == ["grey"] and test["cut"] == 0.5 and test["max"] == 2.0
    assert (test["coefficient"] > 0.5) == reset, test
    assert th.details["pixel_model"] == ("reset (auto)" if reset else "step (auto)")
    forced = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(pixel_model="step" if not reset
                                                                        else "reset"))
    np.testing.assert_array_equal(th.theta_pos, forced.theta_pos)
    assert forced.details["pixel_model_test"] is None  # a forced model makes no test
    assert th.details.get("reset_burst_end") is (True if reset else None)  # for deblur and edi
    if reset:  # the burst's end reaches the fit, and is written with it
        plain = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(pixel_model="reset",
                                                                           reset_burst_end=False))
        assert plain.details["reset_burst_end"] is False
        assert not np.array_equal(plain.theta_pos, th.theta_pos)


def test_a_coefficient_beyond_the_reset_value_is_a_failed_measurement():
    """Above ``excess_max`` the coefficient says the test failed, not that the pixel is held in
    reset: "auto" keeps the step model (the same coefficient, measured again, just inside keeps
    the reset model)."""
    sc = _scene(True)
    beta = estimate_thresholds(sc.frames, sc.events).details["pixel_model_test"]["coefficient"]
    assert beta > 0.9
    below = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(excess_max=0.9 * beta))
    inside = estimate_thresholds(sc.frames, sc.events, CalibrateOptions(excess_max=beta))
    assert below.details["pixel_model"] == "step (auto)"
    assert inside.details["pixel_model"] == "reset (auto)"
    assert below.details["pixel_model_test"]["coefficient"] == beta


@pytest.mark.parametrize("field, value", [("excess_cut", float("nan")), ("excess_cut", "0.5"),
                                          ("excess_min_pairs", 0), ("excess_min_pairs", 10.5),
                                          ("excess_max", float("nan")), ("excess_max", 0.4),
                                          ("excess_max", "2"), ("excess_max", float("inf")),
                                          ("reset_burst_end", 1), ("reset_burst_end", "true")])
def test_bad_test_options_are_refused_by_name(field, value):
    sc = _scene(False)
    with pytest.raises(InputError, match=field):
        estimate_thresholds(sc.frames, sc.events, CalibrateOptions(**{field: value}))
