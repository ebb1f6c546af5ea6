"""benchmarks/bench_event_only_sweep.py's sensor twins: the spec, the folder name and the change table."""

from __future__ import annotations

import pytest

from benchmarks._sweep import parse_sensor
from benchmarks.bench_event_only_sweep import format_change, main, sensor_tag


def test_parse_sensor_reads_fields_and_refuses_others():
    assert parse_sensor("refractory_s=0,ba_rate_hz=0.5") == {"refractory_s": 0.0, "ba_rate_hz": 0.5}
    with pytest.raises(ValueError, match="refactory_s"):
        parse_sensor("refactory_s=0")
    with pytest.raises(ValueError, match="expected a number"):
        parse_sensor("refractory_s=x")


def test_sensor_tag_is_a_plain_folder_name():
    assert sensor_tag("refractory_s=0") == "refractory_s0"
    assert sensor_tag("refractory_s=0,ba_rate_hz=0.5") == "refractory_s0_ba_rate_hz0p5"
    assert sensor_tag("theta_gradient=-0.2") == "theta_gradientm0p2"


def _row(name: str, psnr: float, events: int) -> dict:
    return {"scene": name, "preset": "wall", "cfa": "grey", "events": events, "row": {"affine_psnr": psnr}}


def test_format_change_rows_and_mean():
    rows = [_row("test_1", 20.0, 100), _row("test_2", 18.0, 50)]
    twins = [_row("test_1_r", 21.5, 130), _row("test_2_r", 17.5, 60)]
    lines = format_change(rows, twins, "refractory_s=0").splitlines()
    assert len(lines) == 4
    assert lines[1].split()[-3:] == ["20.00", "21.50", "+1.50"]
    assert lines[2].split()[-3:] == ["18.00", "17.50", "-0.50"]
    assert lines[3].split()[-3:] == ["19.00", "19.50", "+0.50"]
    assert "130" in lines[1] and "60" in lines[2]


def test_bad_sensor_spec_stops_before_any_run(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["--sensor", "refractory_s=slow", "--root", str(tmp_path)])
    assert e.value.code == 2
    assert "refractory_s" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())  # nothing simulated


def test_twin_scene_changes_only_the_sensor_and_is_reused(tmp_path):
    import json

    from benchmarks.bench_event_only_sweep import twin_scene
    from fusiongs.cli import main as cli
    from fusiongs.io.scene_io import load_scene

    scene = tmp_path / "scenes" / "tuning_0"
    assert cli(["simulate", "--sweep-seed", "0", "--split", "tuning", "--size", "32x24", "--duration", "0.2",
                "--frames", "0", "--novel", "1", "--threads", "1", "-o", str(scene)]) == 0
    twin = twin_scene(scene, "refractory_s=0")
    assert twin == tmp_path / "scenes" / "tuning_0_refractory_s0"
    cfg = {p: json.loads((p / "gt" / "sim.json").read_text())["config"] for p in (scene, twin)}
    assert cfg[scene]["dvs"]["refractory_s"] > 0 and cfg[twin]["dvs"]["refractory_s"] == 0
    assert {k: v for k, v in cfg[twin]["dvs"].items() if k != "refractory_s"} == \
        {k: v for k, v in cfg[scene]["dvs"].items() if k != "refractory_s"}
    rest = [{k: v for k, v in cfg[p].items() if k != "dvs"} for p in (scene, twin)]
    assert rest[0] == rest[1]
    facts = [json.loads((p / "gt" / "sim.json").read_text()) for p in (scene, twin)]
    assert facts[1]["sweep"] == facts[0]["sweep"] == {"seed": 0, "split": "tuning"}
    assert facts[1]["preset"] == facts[0]["preset"]
    assert len(load_scene(twin).events) >= len(load_scene(scene).events)  # no dead time drops nothing more
    stamp = (twin / "scene.json").stat().st_mtime_ns
    assert twin_scene(scene, "refractory_s=0") == twin and (twin / "scene.json").stat().st_mtime_ns == stamp
