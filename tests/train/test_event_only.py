"""Event-only reconstruction (no frames): grey and Bayer colour events, both CFA modes, θ field."""

from __future__ import annotations

import json

import pytest

from fusiongs.cli import main
from fusiongs.configs import config_file
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene
from fusiongs.train.checkpoint import load_checkpoint

TINY = ["init.n_points=300", "events.pixels=256", "optim.iterations=8", "densify.enabled=false",
        "event_only.alpha_warmup=3", "event_only.alpha_ramp=2", "event_only.hpf_readouts=20",
        "output.progress=false", "output.checkpoint_every=0"]


def _scene(root, cfa):
    cfg = SimConfig(preset="wall", width=32, height=24, duration=0.15, frames=0, novel=2,
                    dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=4, cfa=cfa)
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, root, overwrite=True)
    return root


@pytest.fixture(scope="module")
def grey_scene(tmp_path_factory):
    return _scene(tmp_path_factory.mktemp("eo_grey"), None)


@pytest.fixture(scope="module")
def colour_scene(tmp_path_factory):
    return _scene(tmp_path_factory.mktemp("eo_rggb"), "RGGB")


def _run(scene, out, *extra):
    args = ["deblur", str(scene), "-o", str(out), "--config", str(config_file("event_only.yaml")),
            *TINY, *extra]
    assert main(args) == 0
    return json.loads((out / "metrics.json").read_text())


def test_grey_event_only_reports_raw_and_affine_metrics(grey_scene, tmp_path, capsys):
    metrics = _run(grey_scene, tmp_path)
    assert "absolute brightness" in capsys.readouterr().out
    assert set(metrics["mean"]) == {"novel"} and set(metrics["mean"]["novel"]) == {"fusiongs"}
    raw, fit = metrics["mean"]["novel"]["fusiongs"], metrics["affine_fit"]["mean"]["novel"]["fusiongs"]
    assert fit["psnr"] >= raw["psnr"]  # the fit can only reduce the squared error
    assert "brightness" in metrics["note"]
    assert not (tmp_path / "deblurred").exists()  # no frames, no deblurred frames


@pytest.mark.parametrize("mode", ["mask", "demosaic"])
def test_colour_event_only_learns_three_channel_thresholds(colour_scene, tmp_path, mode):
    _run(colour_scene, tmp_path, f"events.colour_mode={mode}")
    theta = json.loads((tmp_path / "thresholds.json").read_text())
    assert theta["channels"] == ["R", "G", "B"]
    hist = load_checkpoint(tmp_path / "checkpoint.pt")["history"]
    assert hist["theta_pos"][0] != hist["theta_pos"][-1]  # learned once α > 0


def test_threshold_field_with_drift_trains_and_renders(grey_scene, tmp_path):
    _run(grey_scene, tmp_path, "threshold.grid=[3,4]", "threshold.time_knots=3")
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    assert tuple(ckpt["threshold"]["field"].shape) == (2, 1, 3, 4)
    assert float(ckpt["threshold"]["field"].abs().sum()) > 0  # the field moved from zero
    assert main(["render", str(tmp_path), "--t", "0.05", "-o", str(tmp_path / "r")]) == 0


@pytest.mark.parametrize("which", ["grey", "colour"])
def test_lowpass_term_of_long_windows_trains_and_is_recorded(grey_scene, colour_scene, tmp_path, which):
    scene = grey_scene if which == "grey" else colour_scene
    # windows of at most 30 ms in a 150 ms recording: most pairs of ends of two windows are longer
    _run(scene, tmp_path, "events.lowpass_weight=1", "events.windows_free=3", "optim.iterations=12",
         "events.max_window=0.03")
    rows = [json.loads(line) for line in (tmp_path / "history.jsonl").read_text().splitlines()]
    vals = [r["event_lowpass"] for r in rows if r.get("event_lowpass") is not None]
    assert vals and all(v >= 0 for v in vals) and max(vals) > 0  # some step had a long pair
    off = tmp_path / "off"
    _run(scene, off, "events.windows_free=3", "optim.iterations=12", "events.max_window=0.03",
         "events.lowpass_weight=0")
    rows = [json.loads(line) for line in (off / "history.jsonl").read_text().splitlines()]
    assert all(r.get("event_lowpass") is None for r in rows)
