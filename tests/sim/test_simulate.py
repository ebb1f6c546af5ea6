"""End to end: simulate_scene, the written folder, the CLI and its argument errors."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

import fusiongs.cli as cli
from fusiongs.events.cfa import cfa_channel_index
from fusiongs.io import load_scene
from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.exposure import blur_frame, exposure_times
from fusiongs.sim.presets import get_preset
from fusiongs.sim.simulate import run_simulation, simulate_scene
from fusiongs.sim.write import write_simulated_scene

from .conftest import tiny_config


def _same(a, b):
    ea, eb = a.scene.events, b.scene.events
    return (all(np.array_equal(getattr(ea, k), getattr(eb, k)) for k in "txyp")
            and np.array_equal(a.scene.frames.images, b.scene.frames.images)
            and all(np.array_equal(a.gt[k], b.gt[k]) for k in a.gt))


def test_same_seed_gives_identical_files_and_another_seed_differs(tiny_result, tmp_path):
    cfg = tiny_config(seed=3, dvs=DVSParams(ba_rate_hz=5.0))
    again = run_simulation(cfg)
    assert _same(tiny_result, again)
    for name, res in (("a", tiny_result), ("b", again)):
        write_simulated_scene(res.scene, res.gt, tmp_path / name)
    for f in sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file()):
        if f.name != "events.h5":  # HDF5 may hold object timestamps; its arrays are compared above
            assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    other = run_simulation(dataclasses.replace(cfg, seed=4))
    assert len(other.scene.events) != len(tiny_result.scene.events) or not _same(other, tiny_result)
    assert not np.array_equal(other.scene.frames.images, tiny_result.scene.frames.images)


def test_events_are_sorted_in_range_with_both_polarities(tiny_result):
    ev = tiny_result.scene.events
    cfg = tiny_result.stats["config"]
    assert len(ev) > 500 and ev.t.dtype == np.int64
    assert np.all(np.diff(ev.t) >= 0)
    assert ev.t.min() >= 0 and ev.t.max() <= round(cfg["duration"] * 1e6)
    assert int(ev.x.max()) < cfg["width"] and int(ev.y.max()) < cfg["height"]
    assert 0.2 < ev.polarity_balance < 0.8


def test_scene_has_frames_renders_and_truth_consistent(tiny_result):
    sc, gt = tiny_result.scene, tiny_result.gt
    fs = sc.frames
    assert fs.images.shape == (2, 24, 32, 3) and fs.images.dtype == np.float32
    assert np.allclose(fs.t_end - fs.t_start, 0.03)
    names = [r.name for r in sc.renders]
    assert names == ["deblur_000000", "deblur_000001", "novel_000"]
    mids = (fs.t_start + fs.t_end) / 2
    assert np.allclose([r.t for r in sc.renders[:2]], mids)
    assert fs.t_end[0] < sc.renders[2].t < fs.t_start[1]  # novel instant held out between exposures
    assert set(gt) == set(names) and all(g.shape == (24, 32, 3) for g in gt.values())
    assert sc.poses is not None and sc.poses.t[0] == 0.0 and abs(sc.poses.t[-1] - 0.12) < 1e-9


def test_blur_frame_is_the_mean_of_sharp_renders_over_the_exposure():
    base = torch.rand(4, 5, 3, generator=torch.Generator().manual_seed(0))
    seen = []

    def render(t):
        seen.append(t)
        return base * (1 + 10 * t)

    out = blur_frame(render, 0.1, 0.2, 8)
    times = list(seen)
    assert np.allclose(times, exposure_times(0.1, 0.2, 8))
    assert np.allclose(times, 0.1 + (np.arange(8) + 0.5) / 80)
    assert torch.allclose(out, torch.stack([render(t) for t in times]).mean(0), atol=1e-6)
    assert torch.allclose(out, base * (1 + 10 * 0.15), atol=1e-6)


def test_red_only_texture_fires_events_at_red_cfa_pixels_only():
    preset = get_preset("wall")
    red = tuple(t * np.array([1.0, 0.0, 0.0], dtype=np.float32) for t in preset.world.textures)
    world = dataclasses.replace(preset.world, textures=red, background=(0.02, 0.0, 0.0))
    red_preset = dataclasses.replace(preset, world=world)
    for pattern, cell in (("RGGB", (0, 0)), ("BGGR", (1, 1))):
        cfg = tiny_config(cfa=pattern, dvs=DVSParams(ba_rate_hz=0.0))
        ev = run_simulation(cfg, preset=red_preset).scene.events
        ch = cfa_channel_index(pattern, 24, 32)[ev.y, ev.x]
        assert len(ev) > 200 and np.mean(ch == 0) > 0.99
        assert np.all(ev.y[ch == 0] % 2 == cell[0]) and np.all(ev.x[ch == 0] % 2 == cell[1])


def test_events_target_scales_thresholds_to_reach_the_count():
    target = 6000
    res = run_simulation(tiny_config(events_target=target, dvs=DVSParams(ba_rate_hz=0.0, refractory_s=0.0)))
    assert abs(len(res.scene.events) - target) < 0.05 * target
    assert res.stats["theta_on"] / res.stats["theta_off"] == pytest.approx(0.25 / 0.22)


def test_written_scene_folder_holds_every_referenced_file(tiny_result, tmp_path):
    out = tmp_path / "scene"
    write_simulated_scene(tiny_result.scene, tiny_result.gt, out, stats=tiny_result.stats)
    doc = json.loads((out / "scene.json").read_text())
    paths = [doc["events"]["path"], doc["trajectory"]] + [f["path"] for f in doc["frames"]]
    assert all((out / p).is_file() for p in paths)
    assert all((out / "gt" / f"{r['name']}.png").is_file() for r in doc["renders"])
    back = load_scene(out)
    assert np.array_equal(back.events.t, tiny_result.scene.events.t)
    assert np.array_equal(back.frames.images, tiny_result.scene.frames.images)
    assert [r.name for r in back.renders] == [r.name for r in tiny_result.scene.renders]
    with pytest.raises(Exception, match="scene.json exists"):
        write_simulated_scene(tiny_result.scene, tiny_result.gt, out)


def test_simulate_scene_returns_scene_and_truth():
    scene, gt = simulate_scene(tiny_config(frames=1, novel=2, duration=0.05, exposure=0.02))
    assert len(scene.frames) == 1 and sorted(gt) == ["deblur_000000", "novel_000", "novel_001"]


@pytest.fixture
def only_simulate_verb(monkeypatch):
    monkeypatch.setattr(cli, "VERBS", ("simulate",))  # other verbs are not needed here


def test_cli_writes_a_scene_and_exits_zero(tmp_path, capsys, only_simulate_verb):
    out = tmp_path / "s"
    rc = cli.main(["simulate", "-o", str(out), "--size", "24x16", "--duration", "0.06", "--frames", "1",
                   "--exposure", "0.02", "--dvs-rate", "400", "--blur-samples", "4", "--supersample", "1",
                   "--novel", "1", "--cfa", "GRBG", "--preset", "corridor", "--threads", "1"])
    assert rc == 0
    assert "events" in capsys.readouterr().out
    assert json.loads((out / "scene.json").read_text())["events"]["cfa"] == "GRBG"
    assert (out / "gt" / "deblur_000000.png").is_file() and (out / "gt" / "novel_000.png").is_file()


_TINY_CLI = ["--size", "24x16", "--duration", "0.06", "--frames", "1", "--dvs-rate", "400",
             "--blur-samples", "4", "--supersample", "1", "--novel", "1", "--threads", "1"]


def test_cli_sensor_options_and_linear_frames_reach_the_scene(tmp_path, only_simulate_verb):
    import cv2

    out = tmp_path / "s"
    rc = cli.main(["simulate", "-o", str(out), *_TINY_CLI, "--exposure", "0.02", "--preset", "dark",
                   "--hot-pixels", "0.01", "--hot-rate", "300", "--leak-rate", "0.4",
                   "--frame-response", "linear", "--theta-on", "0.15", "--theta-off", "0.3",
                   "--motion-scale", "0.8"])
    assert rc == 0
    doc = json.loads((out / "scene.json").read_text())
    assert doc["frame_response"] == "linear"
    assert cv2.imread(str(out / doc["frames"][0]["path"]), cv2.IMREAD_UNCHANGED).dtype == np.uint16
    sim = json.loads((out / "gt" / "sim.json").read_text())
    assert sim["hot_pixel_fraction"] == 0.01 and sim["hot_pixel_rate_hz"] == 300.0
    assert sim["leak_rate_hz"] == 0.4 and sim["preset"] == "dark" and sim["motion_scale"] == 0.8
    assert sim["theta_on"] == 0.15 and sim["theta_off"] == 0.3 and sim["hot_pixels"] == 4


def test_cli_sweep_seed_draws_the_scene_and_records_the_truth(tmp_path, capsys, only_simulate_verb):
    from fusiongs.sim.sweep import sweep_scene_config

    out = tmp_path / "s"
    rc = cli.main(["simulate", "-o", str(out), "--sweep-seed", "1004", "--split", "test", *_TINY_CLI])
    assert rc == 0 and "sweep seed 1004, test" in capsys.readouterr().out
    cfg = sweep_scene_config(1004, "test")
    sim = json.loads((out / "gt" / "sim.json").read_text())
    assert sim["sweep"] == {"seed": 1004, "split": "test"}
    assert sim["theta_on"] == cfg.dvs.theta_on and sim["theta_off"] == cfg.dvs.theta_off
    assert sim["preset"] == cfg.preset and sim["exposure"] == cfg.exposure
    assert sim["config"]["width"] == 24 and sim["config"]["frames"] == 1
    assert json.loads((out / "scene.json").read_text())["frame_response"] == cfg.frame_response


@pytest.mark.parametrize("args, option", [
    (["--preset", "moon"], "--preset"), (["--size", "100"], "--size"), (["--size", "4x4"], "--size"),
    (["--cfa", "RGBG"], "--cfa"), (["--seed", "x"], "--seed"), (["--duration", "-1"], "--duration"),
    (["--hot-pixels", "2"], "--hot-pixels"), (["--hot-rate", "x"], "--hot-rate"),
    (["--leak-rate", "-1"], "--leak-rate"), (["--frame-response", "log"], "--frame-response"),
    (["--motion-scale", "0"], "--motion-scale"), (["--split", "test"], "--split"),
    (["--sweep-seed", "5", "--split", "test"], "--sweep-seed"), (["--sweep-seed", "x"], "--sweep-seed"),
    (["--sweep-seed", "1000"], "--sweep-seed"), (["--sweep-seed", "3", "--split", "dev"], "--split"),
    (["--sweep-seed", "3", "--theta-on", "0.2"], "--theta-on"),
    (["--sweep-seed", "3", "--preset", "wall"], "--preset"),
    (["--sweep-seed", "3", "--frames", "40"], "--frames"),
])
def test_cli_bad_arguments_exit_2_with_one_line(tmp_path, capsys, only_simulate_verb, args, option):
    rc = cli.main(["simulate", "-o", str(tmp_path / "s"), *args])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and option in err
    assert not (tmp_path / "s").exists()


def test_simulate_is_a_registered_verb():
    assert "simulate" in cli.VERBS


def test_linear_frames_are_16_bit_and_load_back_as_the_linear_exposure_mean(tmp_path):
    import cv2

    from fusiongs.sim.simulate import frame_windows, scene_renderer

    cfg = tiny_config(frame_response="linear", read_noise=0.0, shot_gain=0.0, novel=0)
    res = run_simulation(cfg)
    assert res.scene.frames.response == "linear" and res.stats["frame_response"] == "linear"
    write_simulated_scene(res.scene, res.gt, tmp_path / "s", stats=res.stats)
    doc = json.loads((tmp_path / "s" / "scene.json").read_text())
    assert doc["frame_response"] == "linear"
    assert cv2.imread(str(tmp_path / "s" / doc["frames"][0]["path"]), cv2.IMREAD_UNCHANGED).dtype == np.uint16
    back = load_scene(tmp_path / "s").frames
    renderer = scene_renderer(cfg)
    t_start, t_end = frame_windows(cfg)
    for i in range(len(back)):
        mean = blur_frame(renderer.render, float(t_start[i]), float(t_end[i]), cfg.blur_samples).numpy()
        assert np.abs(back.to_linear()[i] - np.clip(mean, 0, 1)).max() <= 0.5 / 65535 + 1e-7
    # The same scene in sRGB decodes to the same radiance up to 8-bit sRGB quantisation.
    srgb = run_simulation(dataclasses.replace(cfg, frame_response="srgb")).scene.frames
    assert np.abs(srgb.to_linear() - back.to_linear()).max() < 0.01


@pytest.mark.parametrize("change, field", [
    (dict(frame_response="log"), "frame_response"), (dict(motion_scale=0.0), "motion_scale"),
    (dict(dvs=DVSParams(hot_pixel_fraction=1.5)), "dvs.hot_pixel_fraction"),
    (dict(dvs=DVSParams(leak_rate_hz=-1.0)), "dvs.leak_rate_hz"),
    (dict(dvs=DVSParams(theta_off=0.0)), "dvs.theta_off"),
])
def test_config_validation_names_the_bad_field(change, field):
    from fusiongs.errors import InputError

    with pytest.raises(InputError, match=field.replace(".", r"\.")):
        tiny_config(**change).validate()
