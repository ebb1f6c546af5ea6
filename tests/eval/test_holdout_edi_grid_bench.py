"""benchmarks/bench_holdout_edi_grid.py: EDI carried to held-out frames over a threshold grid."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from benchmarks.bench_holdout_edi_grid import held_out_scores, main
from fusiongs.edi import edi_deblur
from fusiongs.eval.holdout import carried_exposure, kept_neighbours
from fusiongs.eval.metrics import psnr
from fusiongs.frames.response import linear_to_response
from fusiongs.io.scene_io import save_scene
from fusiongs.pipeline.deblur import split_holdout
from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.simulate import SimConfig, run_simulation

TRUE = (0.2, 0.3)


@pytest.fixture(scope="module")
def scene():
    dvs = DVSParams(theta_on=TRUE[0], theta_off=TRUE[1], theta_sigma=0.0, refractory_s=0.0, ba_rate_hz=0.0)
    cfg = SimConfig(preset="wall", width=64, height=48, duration=0.6, frames=7, exposure=0.05,
                    dvs_rate_hz=1000.0, blur_samples=8, supersample=1, novel=0, seed=3, dvs=dvs)
    return run_simulation(cfg).scene


def test_precomputed_counts_give_the_pipelines_prediction(scene):
    """The grid reuses counts across thresholds; one cell equals the straightforward prediction of
    ``score_holdout`` (EDI of each kept neighbour, carried, averaged, encoded, scored)."""
    held, kept = split_holdout(scene, 3)
    th = (0.25, 0.35)
    got = held_out_scores(scene, held, kept, [th])[0]
    fs, ev = scene.frames, scene.events
    lin, mids = fs.to_linear(), fs.mid_times()
    want = []
    for i in held:
        sides = [j for j in kept_neighbours(kept, int(i)) if j is not None]
        carried = [carried_exposure(edi_deblur(lin[j], ev, float(fs.t_start[j]), float(fs.t_end[j]), th),
                                    ev, float(mids[j]), float(fs.t_start[i]), float(fs.t_end[i]), 9, th)
                   for j in sides]
        pred = linear_to_response(np.clip(np.mean(carried, axis=0), 0, 1), fs.response)
        want.append(psnr(pred, fs.images[i]))
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_the_true_thresholds_predict_better_than_far_ones(scene):
    held, kept = split_holdout(scene, 3)
    s = held_out_scores(scene, held, kept, [TRUE, (0.6, 0.9), (0.07, 0.1)]).mean(axis=1)
    assert s[0] > s[1] + 1.0 and s[0] > s[2] + 1.0


def test_main_prints_the_table_and_writes_every_cell(scene, tmp_path, capsys):
    path = save_scene(scene, tmp_path / "scene")
    out = tmp_path / "grid.json"
    assert main([str(path), "--holdout", "3", "--grid", "0.1,0.2,0.3,0.6", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "estimated from the kept frames" in text and "nearest kept frame" in text
    doc = json.loads(out.read_text())
    assert len(doc["grid"]) == 16 and doc["held"] == [2, 5]
    best = max(doc["grid"], key=lambda c: np.mean(c["psnr"]))
    assert (best["theta_pos"], best["theta_neg"]) == (doc["best"]["theta_pos"], doc["best"]["theta_neg"])


@pytest.mark.parametrize("argv, words", [
    (["--grid", "0.2,x"], ("--grid", "positive thresholds")),
    (["--grid", "0.2,-0.1"], ("--grid", "positive thresholds")),
    (["--holdout", "1"], ("--holdout", ">= 2")),
])
def test_bad_options_are_refused_in_one_line(scene, tmp_path, capsys, argv, words):
    path = save_scene(scene, tmp_path / "scene")
    with pytest.raises(SystemExit) as exc:
        main([str(path), *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert all(w in err for w in words)


def test_a_missing_scene_or_one_without_events_is_refused_in_one_line(scene, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([str(tmp_path / "nowhere")])
    assert exc.value.code == 2 and "nowhere" in capsys.readouterr().err.strip().splitlines()[-1]
    frames_only = replace(scene, events=None)
    path = save_scene(frames_only, tmp_path / "frames_only")
    with pytest.raises(SystemExit) as exc:
        main([str(path)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert exc.value.code == 2 and "events" in err and "frames_only" in err
