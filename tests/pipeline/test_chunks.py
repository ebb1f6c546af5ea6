"""A long recording in overlapping time chunks: the plan, the cut, the stitch, resume."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from fusiongs.cli import main
from fusiongs.errors import ConfigError
from fusiongs.io.scene_io import load_scene, recording_span
from fusiongs.pipeline.chunks import (
    CHUNKS_FILE,
    calibration_window,
    check_chunks,
    chunk_scene,
    owners,
    plan_chunks,
    scene_span,
)
from fusiongs.pipeline.pieces import PIECE_FILE
from fusiongs.train.checkpoint import load_checkpoint
from tests.conftest import TINY, simulated_scene
from tests.kill import run_killed

CHUNKED = ["chunk.seconds=0.3", "chunk.overlap=0.1"]


@pytest.mark.parametrize(("length", "seconds", "overlap"),
                         [(20.0, 6.0, 1.0), (0.6, 0.3, 0.1), (10.0, 4.0, 0.0)])
def test_chunks_cover_the_recording_share_the_overlap_and_respect_the_length(length, seconds, overlap):
    spans = plan_chunks(2.0, 2.0 + length, seconds, overlap)
    assert spans[0][0] == 2.0 and spans[-1][1] == pytest.approx(2.0 + length)
    assert all(t1 - t0 <= seconds + 1e-9 for t0, t1 in spans)
    assert all(a[1] - b[0] == pytest.approx(overlap) for a, b in zip(spans, spans[1:]))
    assert len(plan_chunks(0.0, 5.0, 6.0, 1.0)) == 1 and len(plan_chunks(0.0, 50.0, 0.0, 1.0)) == 1


def test_an_instant_belongs_to_the_chunk_in_whose_middle_it_lies():
    spans = [(0.0, 4.0), (3.0, 7.0), (6.0, 10.0)]
    assert owners(np.array([0.5, 3.4, 3.6, 5.0, 6.6, 9.9, 12.0]), spans).tolist() == [0, 0, 1, 1, 2, 2, 2]


@pytest.fixture(scope="module")
def long_scene(tmp_path_factory):
    """A 32x24 boxes recording of 0.6 s with 8 frames, events, trajectory and truth."""
    return simulated_scene(tmp_path_factory.mktemp("long"), duration=0.6, frames=8, dvs_rate_hz=400.0,
                           blur_samples=4, novel=2, seed=2)


def test_a_chunk_holds_its_whole_exposures_its_events_and_a_path_around_it(long_scene):
    scene = load_scene(long_scene)
    t0, t1 = 0.2, 0.45
    part = chunk_scene(scene, t0, t1)
    fs = scene.frames
    inside = [n for n, a, b in zip(fs.names, fs.t_start, fs.t_end) if a >= t0 and b <= t1]
    assert list(part.frames.names) == inside and len(inside) >= 2
    assert part.events.t[0] >= t0 * 1e6 and part.events.t[-1] <= t1 * 1e6 + 1
    assert len(part.events) == int(((scene.events.t >= t0 * 1e6) & (scene.events.t <= t1 * 1e6 + 1)).sum())
    assert part.poses.t[0] <= t0 and part.poses.t[-1] >= t1


def test_a_chunked_recording_is_calibrated_on_its_middle_exposures(long_scene):
    scene = load_scene(long_scene)
    assert calibration_window(scene, 8) is scene
    part = calibration_window(scene, 4)
    assert list(part.frames.names) == list(scene.frames.names[2:6])
    assert part.events.t[0] >= scene.frames.t_start[2] * 1e6
    assert part.events.t[-1] <= scene.frames.t_end[5] * 1e6 + 1


def test_a_chunk_shorter_than_two_exposures_is_refused(long_scene, tmp_path, capsys):
    scene = load_scene(long_scene)
    with pytest.raises(ConfigError, match="chunk.seconds"):
        check_chunks(scene, 0.05, 0.01)
    code = main(["deblur", str(long_scene), "-o", str(tmp_path / "out"), "chunk.seconds=0.05",
                 "chunk.overlap=0.01", *TINY])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "chunk.seconds" in err[0]


@pytest.mark.slow
def test_a_chunked_run_stitches_every_frame_and_resumes_only_the_unfinished_chunk(long_scene, tmp_path,
                                                                                   capsys):
    out = tmp_path / "out"
    assert main(["deblur", str(long_scene), "-o", str(out), "--jobs", "2", *TINY, *CHUNKED]) == 0
    scene = load_scene(long_scene)
    index = json.loads((out / CHUNKS_FILE).read_text())["chunks"]
    spans = plan_chunks(*scene_span(scene), 0.3, 0.1)
    assert len(index) == len(spans) == 3
    # every frame stitched once, from the chunk in whose middle it lies
    assert sorted(n for c in index for n in c["frames"]) == sorted(scene.frames.names)
    mine = owners(scene.frames.mid_times(), spans)
    for c in index:
        assert c["frames"] == [n for n, o in zip(scene.frames.names, mine) if o == c["index"]]
        assert (out / c["ply"]).is_file()
    for name, k in zip(scene.frames.names, mine):
        stitched = (out / "deblurred" / f"{name}.png").read_bytes()
        assert stitched == (out / index[k]["run"] / "deblurred" / f"{name}.png").read_bytes()
    assert (out / "deblurred.mp4").is_file() and (out / "calibration.json").is_file()
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mean"]["deblur"]["fusiongs"]["n"] == len(scene.frames)
    assert {"blurry", "edi", "edi_true_theta"} <= set(metrics["mean"]["deblur"])
    path = np.loadtxt(out / "trajectory.txt", comments="#")
    assert np.all(np.diff(path[:, 0]) > 0) and path[0, 0] <= scene.frames.mid_times()[0]
    assert path[-1, 0] >= scene.frames.mid_times()[-1]
    # a run killed while chunk 1 was training: --resume runs chunk 1 only
    (out / "chunks" / "001" / "run" / PIECE_FILE).unlink()
    stamps = {k: (out / "chunks" / k / "run" / PIECE_FILE).stat().st_mtime_ns for k in ("000", "002")}
    capsys.readouterr()
    assert main(["deblur", str(long_scene), "-o", str(out), "--resume", *TINY, *CHUNKED]) == 0
    printed = capsys.readouterr().out
    assert "chunk 000: finished earlier (kept)" in printed and "chunk 002: finished earlier (kept)" in printed
    assert "1 to run" in printed and (out / "chunks" / "001" / "run" / PIECE_FILE).is_file()
    assert {k: (out / "chunks" / k / "run" / PIECE_FILE).stat().st_mtime_ns for k in ("000", "002")} == stamps


def test_the_span_that_decides_chunking_is_read_without_loading_the_recording(long_scene):
    assert recording_span(long_scene) == pytest.approx(scene_span(load_scene(long_scene)), abs=1e-6)


@pytest.mark.slow
def test_a_long_recording_of_a_dataset_is_cut_into_chunks(long_scene, tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "walk").symlink_to(long_scene, target_is_directory=True)
    out = tmp_path / "out"
    assert main(["deblur", str(data), "-o", str(out), "--executor", "serial", *TINY, *CHUNKED]) == 0
    index = json.loads((out / "walk" / CHUNKS_FILE).read_text())
    assert len(index["chunks"]) == 3 and (out / "walk" / "deblurred.mp4").is_file()
    row = json.loads((out / "summary.json").read_text())["recordings"][0]
    stitched = json.loads((out / "walk" / "metrics.json").read_text())["mean"]["deblur"]
    assert row["status"] == "done" and row["psnr"]["fusiongs"] == stitched["fusiongs"]["psnr"]


@pytest.mark.slow
def test_the_chunks_of_a_recording_run_on_a_dask_cluster_started_for_the_run(long_scene, tmp_path):
    pytest.importorskip("distributed")
    out = tmp_path / "out"
    assert main(["deblur", str(long_scene), "-o", str(out), "--executor", "dask", "--jobs", "2",
                 *TINY, *CHUNKED]) == 0
    index = json.loads((out / CHUNKS_FILE).read_text())["chunks"]
    assert len(index) == 3
    assert all((out / "chunks" / f"{k:03d}" / "run" / PIECE_FILE).is_file() for k in range(3))
    assert sorted(n for c in index for n in c["frames"]) == sorted(load_scene(long_scene).frames.names)


def test_a_recording_no_longer_than_a_chunk_runs_in_one_piece(long_scene, tmp_path):
    out = tmp_path / "out"
    assert main(["deblur", str(long_scene), "-o", str(out), "chunk.seconds=5", *TINY]) == 0
    assert (out / "metrics.json").is_file() and (out / "model.ply").is_file()
    assert not (out / CHUNKS_FILE).exists() and not (out / "chunks").exists()


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "killpg"), reason="needs POSIX process groups")
def test_a_chunked_run_killed_mid_chunk_resumes_to_the_uninterrupted_result(long_scene, tmp_path):
    # chunks one after another in one process (so the kill point is exact), checkpoints every 3
    # iterations: killed just after chunk 001 wrote its first checkpoint, chunk 000 finished
    args = [*TINY, *CHUNKED, "output.checkpoint_every=3", "--executor", "serial"]
    reference = tmp_path / "reference"
    assert main(["deblur", str(long_scene), "-o", str(reference), *args]) == 0

    out = tmp_path / "out"
    argv = ["deblur", str(long_scene), "-o", str(out), *args]
    assert run_killed(argv, out, "chunks/001/run/checkpoint.pt:1:after") == "killed"
    first = out / "chunks" / "000" / "run" / PIECE_FILE
    assert first.is_file() and not (out / "chunks" / "001" / "run" / PIECE_FILE).exists()
    assert load_checkpoint(out / "chunks" / "001" / "run" / "checkpoint.pt")["iteration"] == 3
    assert not (out / "metrics.json").exists()
    stamp = first.stat().st_mtime_ns

    assert main([*argv, "--resume"]) == 0
    assert first.stat().st_mtime_ns == stamp  # the finished chunk was kept, not redone
    psnr = [json.loads((o / "metrics.json").read_text())["mean"]["deblur"]["fusiongs"]["psnr"]
            for o in (out, reference)]
    assert abs(psnr[0] - psnr[1]) <= 0.1, psnr
    assert sorted(p.name for p in (out / "deblurred").iterdir()) == \
        sorted(p.name for p in (reference / "deblurred").iterdir())
