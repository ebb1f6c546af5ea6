"""benchmarks/bench_exposure_ratio.py: a finished run's deblurred frames rescored per pixel and
carried by the fitted motion."""

from __future__ import annotations

import json
import shutil

import pytest

from benchmarks.bench_exposure_ratio import main, parse_iterations


def test_the_default_reproduces_the_runs_own_score_and_every_count_is_printed(tiny_scene, tiny_run,
                                                                             tmp_path, capsys):
    """0 iterations is the per-pixel ratio the run's metrics.json scored ("fusiongs" before session
    45's default); the run's default (3) is its "fusiongs" now."""
    out = tmp_path / "rows.json"
    assert main([str(tiny_run), str(tiny_scene), "--iterations", "1,3", "--json", str(out)]) == 0
    table = capsys.readouterr().out
    assert "0 it." in table and "3 it." in table and "gain over 0: smallest" in table
    rows = json.loads(out.read_text())
    assert rows["iterations"] == [0, 1, 3]
    got = rows["runs"][str(tiny_run)]["psnr"]
    metrics = json.loads((tiny_run / "metrics.json").read_text())["mean"]["deblur"]
    assert got["3"] == pytest.approx(metrics["fusiongs"]["psnr"], abs=1e-6)
    assert got["0"] != pytest.approx(got["3"], abs=1e-3)


def test_bad_input_is_one_line_and_exit_2(tiny_scene, tiny_run, tmp_path, capsys):
    assert main([str(tiny_run)]) == 2
    assert "pairs of a run folder and its scene folder" in capsys.readouterr().err
    assert main([str(tiny_run), str(tiny_scene), "--iterations", "1,-2"]) == 2
    assert "--iterations" in capsys.readouterr().err
    assert main([str(tmp_path), str(tiny_scene)]) == 2
    assert "checkpoint" in capsys.readouterr().err
    no_truth = tmp_path / "scene"
    shutil.copytree(tiny_scene, no_truth)
    shutil.rmtree(no_truth / "gt")
    assert main([str(tiny_run), str(no_truth)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "deblur_<stem>.png" in err


def test_parse_iterations_always_includes_the_reference():
    assert parse_iterations("3,1,3") == [0, 1, 3]


def test_novel_reproduces_the_runs_own_novel_scores(tiny_scene, tiny_run, tmp_path, capsys):
    """--novel: with the run's default (output.ratio_between on) the renders between the exposures
    score as the run's metrics.json scored them, and as rendered as its "fusiongs_render"."""
    out = tmp_path / "novel.json"
    assert main([str(tiny_run), str(tiny_scene), "--novel", "--json", str(out)]) == 0
    assert "smallest gain" in capsys.readouterr().out
    row = json.loads(out.read_text())["runs"][str(tiny_run)]
    novel = json.loads((tiny_run / "metrics.json").read_text())["mean"]["novel"]
    assert row["n"] == 1
    assert row["between"] == pytest.approx(novel["fusiongs"]["psnr"], abs=1e-6)
    assert row["render"] == pytest.approx(novel["fusiongs_render"]["psnr"], abs=1e-6)
    assert row["between"] != pytest.approx(row["render"], abs=1e-3)


def test_novel_without_truth_between_exposures_is_one_line_and_exit_2(tiny_scene, tiny_run, tmp_path, capsys):
    no_novel = tmp_path / "scene"
    shutil.copytree(tiny_scene, no_novel)
    for p in (no_novel / "gt").glob("novel_*.png"):
        p.unlink()
    assert main([str(tiny_run), str(no_novel), "--novel"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "outside every exposure" in err
