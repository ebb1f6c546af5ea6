"""The ON/OFF ratio from pixel round trips (:func:`fusiongs.calibrate.fit.with_round_trip_ratio`).

Ideal DVS pixels follow random walks of log intensity; the frames are sharp (no events inside an
exposure), so each frame's EDI log intensity is the walk's value. The counts between frames, and
so the round trips, are then exactly what a pixel with thresholds ``theta_+ / theta_-`` makes.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.calibrate.data import frame_pairs
from fusiongs.calibrate.estimate import estimate_thresholds
from fusiongs.calibrate.fit import PairData, ratio_from_sums, round_trip_sums, with_round_trip_ratio
from fusiongs.calibrate.options import CalibrateOptions
from fusiongs.errors import InputError


def ideal_pairs(theta_pos: float, theta_neg: float, n_pixels: int = 3000, n_frames: int = 12,
                steps: int = 400, seed: int = 0) -> PairData:
    """Random walks (log steps of 0.02, ``steps`` between frames) seen by ideal DVS pixels."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0.0, 0.02, (n_frames * steps, n_pixels)), axis=0)
    ref = np.zeros(n_pixels)
    on = np.zeros(n_pixels)
    off = np.zeros(n_pixels)
    cum = np.zeros((n_frames, 2, n_pixels))
    for k in range(walk.shape[0]):  # one vectorised step over all pixels at a time
        while True:
            up, down = walk[k] - ref >= theta_pos, ref - walk[k] >= theta_neg
            if not (up.any() or down.any()):
                break
            ref = ref + up * theta_pos - down * theta_neg
            on += up
            off += down
        if k % steps == steps - 1:
            cum[k // steps] = on, off
    log_s = walk[steps - 1::steps]  # the frames, at the counts' instants
    pairs = frame_pairs(n_frames, n_frames - 1)
    dn = cum[pairs[:, 1]] - cum[pairs[:, 0]]
    return PairData(torch.as_tensor(log_s, dtype=torch.float32), torch.zeros(n_frames, 4, 2, n_pixels),
                    torch.as_tensor(pairs), torch.as_tensor(dn, dtype=torch.float32),
                    torch.ones(len(pairs), n_pixels, dtype=torch.bool),
                    torch.as_tensor(np.arange(n_pixels) % 16), 16, torch.as_tensor(dn, dtype=torch.float32))


def test_ratio_from_sums_is_exact_on_consistent_sums():
    for tp, tn, n_on, n_off in ((0.2, 0.3, 150.0, 90.0), (0.45, 0.15, 40.0, 130.0), (0.25, 0.25, 60.0, 60.0)):
        sums = torch.tensor([n_on, n_off, tp * n_on - tn * n_off], dtype=torch.float64)
        assert float(ratio_from_sums(sums, float(np.sqrt(tp * tn)))) == pytest.approx(tn / tp, rel=1e-9)
    assert np.isnan(float(ratio_from_sums(torch.tensor([5.0, 0.0, 0.1], dtype=torch.float64), 0.2)))


@pytest.mark.parametrize("theta_pos, theta_neg", [(0.2, 0.35), (0.4, 0.2)])
def test_round_trips_give_the_ratio_that_a_wrong_fit_missed(theta_pos, theta_neg):
    data = ideal_pairs(theta_pos, theta_neg)
    scale = np.sqrt(theta_pos * theta_neg)
    wrong = {"theta_pos": scale / 1.25, "theta_neg": scale * 1.25, "std_pos": 0.01, "std_neg": 0.01}
    out = with_round_trip_ratio(wrong, data, CalibrateOptions(), np.random.default_rng(0))
    info = out["round_trip"]
    assert info["used"] and info["pairs"] >= 100
    assert info["iv_ratio"] == pytest.approx(1.25 ** 2)
    assert out["theta_neg"] / out["theta_pos"] == pytest.approx(theta_neg / theta_pos, rel=0.05)
    assert np.sqrt(out["theta_pos"] * out["theta_neg"]) == pytest.approx(scale)  # the scale is kept
    assert 0 < info["std_log_ratio"] < 0.05
    assert (out["std_pos"], out["std_neg"]) == (0.01, 0.01)  # the fit's uncertainties are kept


def test_too_few_round_trips_keep_the_fit():
    data = ideal_pairs(0.2, 0.3, n_pixels=200)
    fit = {"theta_pos": 0.2, "theta_neg": 0.3}
    sums, n = round_trip_sums(data, 0.2, 0.3, 0.1, 6.0)
    assert sums.shape == (16, 3) and 0 < n
    opts = CalibrateOptions(round_trip_min_pairs=n + 1)
    out = with_round_trip_ratio(fit, data, opts, np.random.default_rng(0))
    assert not out["round_trip"]["used"]
    assert (out["theta_pos"], out["theta_neg"]) == (0.2, 0.3)


def test_an_unknown_ratio_source_is_refused_by_name():
    with pytest.raises(InputError, match="ratio"):
        estimate_thresholds(None, None, CalibrateOptions(ratio="balance"))


def test_calibrate_with_round_trips_records_them_and_keeps_the_fits_scale(tmp_path, capsys):
    # A small simulated scene: the IV estimate and the round-trip one share their common scale
    # before the spread correction, which both then get alike; the per-channel details say which.
    import json

    from fusiongs.cli import main
    from fusiongs.sim.simulate import SimConfig, run_simulation
    from fusiongs.sim.write import write_simulated_scene

    res = run_simulation(SimConfig(preset="wall", width=64, height=48, duration=0.5, frames=6, exposure=0.03,
                                   dvs_rate_hz=500.0, blur_samples=6, supersample=1, novel=0, seed=3))
    write_simulated_scene(res.scene, res.gt, tmp_path / "scene", stats=res.stats, overwrite=True)
    docs = {}
    for ratio in ("iv", "round_trip"):
        assert main(["calibrate", str(tmp_path / "scene"), "--ratio", ratio, "--json",
                     "-o", str(tmp_path / f"{ratio}.json")]) == 0
        docs[ratio] = json.loads(capsys.readouterr().out)["thresholds"]
    iv, rt = docs["iv"], docs["round_trip"]
    g = [np.sqrt(a * b) for a, b in zip(iv["theta_pos"], iv["theta_neg"])]
    h = [np.sqrt(a * b) for a, b in zip(rt["theta_pos"], rt["theta_neg"])]
    np.testing.assert_allclose(h, g, rtol=1e-6)
    assert "round trips" in rt["method"] and "round trips" not in iv["method"]
    ratios = [d["theta_neg"][0] / d["theta_pos"][0] for d in (iv, rt)]
    assert ratios[0] != pytest.approx(ratios[1], rel=1e-4)  # the round trips' ratio was used
    with pytest.raises(SystemExit):
        main(["calibrate", str(tmp_path / "scene"), "--ratio", "balance"])


def test_auto_takes_the_round_trips_ratio_only_where_the_two_disagree():
    data = ideal_pairs(0.2, 0.35)
    scale = np.sqrt(0.2 * 0.35)
    rng = np.random.default_rng(0)
    opts = CalibrateOptions(ratio="auto")
    far = {"theta_pos": scale / 1.25, "theta_neg": scale * 1.25}  # 56 % off: replaced
    out = with_round_trip_ratio(far, data, opts, rng)
    assert out["round_trip"]["used"]
    assert out["theta_neg"] / out["theta_pos"] == pytest.approx(0.35 / 0.2, rel=0.05)
    near = {"theta_pos": 0.2 * 1.01, "theta_neg": 0.35 / 1.01}  # 2 % off: within the switch, kept
    out = with_round_trip_ratio(near, data, opts, rng)
    assert not out["round_trip"]["used"] and (out["theta_pos"], out["theta_neg"]) == (0.2 * 1.01, 0.35 / 1.01)
    with pytest.raises(InputError, match="ratio_switch"):
        estimate_thresholds(None, None, CalibrateOptions(ratio="auto", ratio_switch=-1.0))
