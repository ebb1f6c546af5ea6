"""Colour from events alone: the one-frame colour anchor, ΔE00 after the affine fit, the
event loss across the α schedule, and bad event-only input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from fusiongs.cli import main
from fusiongs.eval.metrics import psnr
from fusiongs.frames.image_io import read_image
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene

SMALL = ["init.n_points=300", "densify.enabled=false", "event_only.hpf_readouts=20",
         "output.progress=false", "output.checkpoint_every=0"]


def _wall(root, frames):
    """32x24 textured wall, 0.15 s of grey events, ``frames`` blurry frames of 20 ms, 2 novel views."""
    cfg = SimConfig(preset="wall", width=32, height=24, duration=0.15, frames=frames, exposure=0.02,
                    novel=2, dvs_rate_hz=600.0, blur_samples=4, supersample=1, seed=4)
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, root, overwrite=True)
    return root


@pytest.fixture(scope="module")
def events_only(tmp_path_factory):
    return _wall(tmp_path_factory.mktemp("eo0"), 0)


@pytest.fixture(scope="module")
def one_frame(tmp_path_factory):
    return _wall(tmp_path_factory.mktemp("eo1"), 1)


def _deblur(scene, out, *extra):
    assert main(["deblur", str(scene), "-o", str(out), "--config", "event_only", *SMALL, *extra]) == 0
    return json.loads((out / "metrics.json").read_text())


def test_one_frame_fixes_each_channels_gain_and_offset(one_frame, tmp_path, capsys):
    # 8 iterations: the blur loss has not yet pulled the colours to the frame's, so what the anchor
    # does is visible. On this 32x24 scene the anchored raw PSNR came within 0.35 dB of the affine
    # fit (which is fitted to the truth itself, per view, in sRGB: an upper bound), and 13 dB above
    # the same renders without the anchor; 1 dB and 5 dB leave room for other platforms' rounding.
    # The random start (not the default events' stereo of a one-frame scene) keeps the renders far
    # from the frame's colours after 8 iterations, the state this test is about.
    m = _deblur(one_frame, tmp_path, "optim.iterations=8", "events.pixels=256", "events.warmup=4",
                "init.method=random")
    anchor = m["colour_anchor"]
    assert anchor["anchor"] == "frame" and anchor["frames"] == ["000000"] and anchor["space"] == "linear"
    assert "frame anchor" in capsys.readouterr().out
    raw, fit = m["mean"]["novel"]["fusiongs"], m["affine_fit"]["mean"]["novel"]["fusiongs"]
    before = anchor["before"]["novel"]["fusiongs"]
    assert raw["psnr"] == pytest.approx(fit["psnr"], abs=1.0)
    assert raw["psnr"] > before["psnr"] + 5.0
    assert raw["delta_e00"] < before["delta_e00"] / 2 and fit["delta_e00"] <= raw["delta_e00"] + 0.5
    assert m["mean"]["deblur"]["fusiongs"]["psnr"] == pytest.approx(
        m["affine_fit"]["mean"]["deblur"]["fusiongs"]["psnr"], abs=1.0)
    # the files hold the anchored images that were scored (written once, anchored before writing)
    novel = [n for n in m["views"] if n.startswith("novel")]
    assert novel
    for name in novel:
        png = read_image(tmp_path / "renders" / f"{name}.png")
        gt = read_image(one_frame / "gt" / f"{name}.png")
        assert psnr(png, gt) == pytest.approx(m["views"][name]["fusiongs"]["psnr"], abs=0.05)
    # the anchor is kept beside the outputs, and `fusiongs render` gives the run's own colours
    kept = json.loads((tmp_path / "colour_anchor.json").read_text())
    assert kept["gain"] == anchor["gain"] and kept["offset"] == anchor["offset"]
    times = {r["name"]: r["t"] for r in json.loads((one_frame / "scene.json").read_text())["renders"]}
    assert main(["render", str(tmp_path), "--t", repr(times[novel[0]]), "-o", str(tmp_path / "r")]) == 0
    again = read_image(next((tmp_path / "r").glob("t_*.png")))
    np.testing.assert_allclose(again, read_image(tmp_path / "renders" / f"{novel[0]}.png"), atol=1.5 / 255)


def test_event_loss_ends_below_its_value_at_the_start_of_the_alpha_ramp(events_only, tmp_path):
    # No loss term may jump at a schedule change and stay there: the event loss enters at the first
    # iteration with α > 0 and must end lower than it entered. Means over 20 iterations: single
    # values swing by 2x with the random window lengths (here 0.63 at the start, 0.42 at the end).
    warmup, ramp, k = 20, 20, 20
    m = _deblur(events_only, tmp_path, "optim.iterations=200", "events.pixels=768", "events.windows_free=4",
                f"event_only.alpha_warmup={warmup}", f"event_only.alpha_ramp={ramp}")
    rows = [json.loads(line) for line in (tmp_path / "history.jsonl").read_text().splitlines()]
    alpha = [r["event_weight"] for r in rows]
    event = [r["event"] for r in rows]
    first = next(i for i, a in enumerate(alpha) if a > 0)
    assert first == warmup + 1 and all(e is None for e in event[:first])  # no event term before α > 0
    assert all(e is not None and math.isfinite(e) for e in event[first:])
    start, end = np.mean(event[first:first + k]), np.mean(event[-k:])
    assert end < start, (start, end)
    # every term is recorded: the intensity anchor's too, on every iteration while 1 − α > 0
    assert all(r["intensity"] is not None and math.isfinite(r["intensity"]) for r in rows)
    # the truth probe scored the novel views every 100 iterations and after the last one; its last
    # figure is the renders that metrics.json scores (no frame: no correction, no anchor)
    probed = [r["iteration"] for r in rows if r["psnr_truth"] is not None]
    assert probed == [99, 199]
    novel = m["affine_fit"]["mean"]["novel"]["fusiongs"]["psnr"]
    assert rows[-1]["psnr_truth_fit"] == pytest.approx(novel, abs=0.01)
    assert rows[-1]["psnr_truth"] == pytest.approx(m["mean"]["novel"]["fusiongs"]["psnr"], abs=0.01)
    # the metrics of an event-only run: raw and affine-fit PSNR, ΔE00 after the fit, no anchor
    assert m["colour_anchor"]["anchor"] == "none" and "affine fit only" in m["colour_anchor"]["label"]
    assert "delta_e00" in m["affine_fit"]["mean"]["novel"]["fusiongs"]
    assert "delta_e00" not in m["mean"]["novel"]["fusiongs"]  # raw colours of events alone mean nothing


def test_event_only_renders_are_exposed_by_one_gain_and_render_reuses_it(events_only, one_frame, tmp_path,
                                                                          capfd):
    """Without a frame the renders' level is arbitrary: one linear gain puts their 99.5th
    percentile at 0.9 before the clip (exposure.json), `fusiongs render` applies the same gain,
    output.exposure=none writes them as rendered, and a run with a frame writes no gain (and
    removes an earlier run's from its folder)."""
    from fusiongs.frames.response import srgb_to_linear
    from fusiongs.train.render_io import EXPOSURE_LEVEL, exposure_gain, render_linear
    from fusiongs.train.restore import restore_state

    short = ["optim.iterations=6", "events.pixels=256"]
    run = tmp_path / "auto"
    _deblur(events_only, run, *short)
    gain = json.loads((run / "exposure.json").read_text())["gain"]
    meta = json.loads((events_only / "scene.json").read_text())
    names = [r["name"] for r in meta["renders"]]
    times = [r["t"] for r in meta["renders"]]
    state, camera, _ = restore_state(run / "checkpoint.pt")
    lin = render_linear(state, camera, times, "auto")
    assert gain == pytest.approx(exposure_gain(lin)) and gain != pytest.approx(1.0, abs=0.05)
    written = np.stack([srgb_to_linear(read_image(run / "renders" / f"{n}.png")) for n in names])
    assert np.percentile(written, 99.5) == pytest.approx(EXPOSURE_LEVEL, abs=0.02)
    np.testing.assert_allclose(written, np.clip(lin * gain, 0, 1), atol=0.01)
    # fusiongs render of the same instant matches the written render
    assert main(["render", str(run), "--t", repr(times[0]), "-o", str(tmp_path / "r")]) == 0
    again = read_image(next((tmp_path / "r").glob("*.png")))
    np.testing.assert_allclose(again, read_image(run / "renders" / f"{names[0]}.png"), atol=1.5 / 255)
    # a corrupt or wrong exposure.json: one line naming the file and the key, exit 2
    saved = (run / "exposure.json").read_text()
    for bad in ("{not json", '{"gain": -2}', '["gain"]'):
        (run / "exposure.json").write_text(bad)
        capfd.readouterr()
        assert main(["render", str(run), "--t", repr(times[0]), "-o", str(tmp_path / "bad")]) == 2
        err = capfd.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "exposure.json: gain: expected" in err[0], err
    (run / "exposure.json").write_text(saved)
    # as rendered when asked
    plain = tmp_path / "plain"
    _deblur(events_only, plain, *short, "output.exposure=none")
    assert not (plain / "exposure.json").exists()
    ref = np.stack([srgb_to_linear(read_image(plain / "renders" / f"{n}.png")) for n in names])
    np.testing.assert_allclose(ref, np.clip(lin, 0, 1), atol=0.01)
    # a frame fixes the level: no gain, and none left over from the event-only run in that folder
    assert not (run / "colour_anchor.json").exists()  # no frame: nothing to anchor to
    _deblur(one_frame, run, *short)
    assert not (run / "exposure.json").exists()
    assert (run / "colour_anchor.json").is_file()
    # a damaged anchor file: one line naming the file and the key, exit 2
    for bad, key in (("{not json", "(file)"), ('{"anchor": "frame", "gain": [1, 2]}', "gain"),
                     ('{"anchor": "grey-world"}', "anchor")):
        (run / "colour_anchor.json").write_text(bad)
        capfd.readouterr()
        assert main(["render", str(run), "--t", repr(times[0]), "-o", str(tmp_path / "bad")]) == 2
        err = capfd.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"colour_anchor.json: {key}: expected" in err[0], err
    _deblur(events_only, run, *short)  # an event-only run in the same folder removes it
    assert not (run / "colour_anchor.json").exists()
    from fusiongs.errors import ConfigError
    from fusiongs.train.settings import OutputSettings

    with pytest.raises(ConfigError, match="output.exposure"):
        OutputSettings(exposure="max")


def test_total_variation_prior_is_recorded_and_smooths_the_renders(events_only, tmp_path):
    """event_only.tv_weight adds the renders' total variation to the loss: history.jsonl records
    the term on every iteration (null when off), and a heavy weight leaves smoother renders."""
    from fusiongs.losses.priors import total_variation_prior
    from fusiongs.train.render_io import render_linear
    from fusiongs.train.restore import restore_state

    short = ["optim.iterations=40", "events.pixels=256", "event_only.alpha_warmup=5",
             "event_only.alpha_ramp=5", "output.exposure=none"]
    tv = {}
    for weight in (0, 30):
        run = tmp_path / f"tv{weight}"
        _deblur(events_only, run, *short, f"event_only.tv_weight={weight}")
        rows = [json.loads(line) for line in (run / "history.jsonl").read_text().splitlines()]
        if weight:
            assert all(r["tv"] is not None and math.isfinite(r["tv"]) for r in rows)
        else:
            assert all(r["tv"] is None for r in rows)
        state, camera, _ = restore_state(run / "checkpoint.pt")
        times = [r["t"] for r in json.loads((events_only / "scene.json").read_text())["renders"]]
        lin = torch.as_tensor(render_linear(state, camera, times, "auto"))
        tv[weight] = float(total_variation_prior(lin, "log"))
    assert tv[30] < 0.7 * tv[0], tv


def test_gradient_blur_changes_event_only_training_and_only_it(events_only, one_frame, tmp_path):
    """event_only.gradient_blur reshapes the renders' gradient (the loss is the same): the run's
    Gaussians end elsewhere than without it, and a scene with a frame is trained as before."""
    from fusiongs.train.restore import restore_state

    short = ["optim.iterations=12", "events.pixels=256", "event_only.alpha_warmup=2",
             "event_only.alpha_ramp=2", "events.warmup=2"]

    def means(scene, name, *extra):
        _deblur(scene, tmp_path / name, *short, *extra)
        return restore_state(tmp_path / name / "checkpoint.pt")[0].model.means.detach().clone()

    plain, again = means(events_only, "a"), means(events_only, "b")
    torch.testing.assert_close(plain, again)  # the comparison below is not run-to-run noise
    blurred = means(events_only, "c", "event_only.gradient_blur=3")
    assert not torch.allclose(plain, blurred)
    framed = means(one_frame, "d")
    torch.testing.assert_close(means(one_frame, "e", "event_only.gradient_blur=3"), framed)


def _one_line_exit_2(argv, capfd) -> str:
    assert main(argv) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("fusiongs deblur: error: ")
    return err[0]


def _edit_scene(src, dst, edit):
    import shutil

    shutil.copytree(src, dst)
    doc = json.loads((dst / "scene.json").read_text())
    edit(doc)
    (dst / "scene.json").write_text(json.dumps(doc))
    return dst


def test_event_only_scene_without_events_is_one_line(events_only, tmp_path, capfd):
    scene = _edit_scene(events_only, tmp_path / "scene", lambda doc: doc.pop("events"))
    line = _one_line_exit_2(["deblur", str(scene), "-o", str(tmp_path / "out"), "--config", "event_only"],
                            capfd)
    assert "scene.json" in line and "an event stream or at least one frame, got neither" in line


def test_event_only_scene_with_an_empty_event_file_is_one_line(events_only, tmp_path, capfd):
    import h5py

    scene = _edit_scene(events_only, tmp_path / "scene", lambda doc: None)
    with h5py.File(scene / "events.h5", "r+") as f:
        for k in ("t", "x", "y", "p"):
            dtype = f["events"][k].dtype
            del f["events"][k]
            f["events"].create_dataset(k, data=np.zeros(0, dtype))
    line = _one_line_exit_2(["deblur", str(scene), "-o", str(tmp_path / "out"), "--config", "event_only"],
                            capfd)
    assert "events.h5" in line and "at least one event, got 0 events" in line


@pytest.mark.parametrize("cfa", ["RGB", "RRGGRRGGGGBBGGBB", "rggb"])  # 3 cells, a 4x4 quad Bayer, case
def test_event_only_cfa_that_is_not_a_2x2_bayer_cell_is_one_line(events_only, tmp_path, capfd, cfa):
    scene = _edit_scene(events_only, tmp_path / "scene", lambda doc: doc["events"].__setitem__("cfa", cfa))
    line = _one_line_exit_2(["deblur", str(scene), "-o", str(tmp_path / "out"), "--config", "event_only"],
                            capfd)
    assert "scene.json: events.cfa:" in line and "RGGB, BGGR, GRBG, GBRG" in line and repr(cfa) in line
