"""``fusiongs deblur FOLDER`` over a folder of scene folders: pieces in parallel, one table, a
failed piece isolated, ``--resume`` redoing only what had not finished."""

from __future__ import annotations

import json
import operator
import shutil

import pytest

from fusiongs.cli import main
from fusiongs.errors import InputError
from fusiongs.pipeline.dataset import SUMMARY_FILE, dataset_scenes, format_summary
from fusiongs.pipeline.executor import default_jobs, run_pieces, worker_threads
from fusiongs.pipeline.pieces import PIECE_FILE
from tests.conftest import TINY


def test_workers_share_the_cores():
    assert worker_threads(2, cores=2) == 1 and worker_threads(1, cores=2) == 2
    assert worker_threads(3, cores=2) == 1 and worker_threads(2, cores=16) == 8
    assert default_jobs(5, cores=2) == 2 and default_jobs(1, cores=16) == 1 and default_jobs(0, cores=4) == 1


def test_run_pieces_keeps_the_order_of_the_tasks_in_every_executor():
    tasks = [3, -1, 7, 0]
    seen = []
    local = run_pieces(operator.neg, tasks, jobs=2, on_done=seen.append)
    assert local == [-3, 1, -7, 0] and sorted(seen) == sorted(local)
    assert run_pieces(operator.neg, tasks, jobs=2, executor="serial") == local
    with pytest.raises(InputError, match="--executor"):
        run_pieces(operator.neg, tasks, jobs=2, executor="cluster")
    with pytest.raises(InputError, match="--jobs"):
        run_pieces(operator.neg, tasks, jobs=0)
    with pytest.raises(InputError, match="--address"):
        run_pieces(operator.neg, tasks, jobs=2, address="tcp://127.0.0.1:1")


def test_dask_runs_the_pieces_on_a_cluster_started_for_the_run_or_given_by_address():
    distributed = pytest.importorskip("distributed")
    tasks = [3, -1, 7]
    assert run_pieces(operator.neg, tasks, jobs=2, executor="dask") == [-3, 1, -7]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        assert run_pieces(operator.neg, tasks, jobs=1, executor="dask",
                          address=cluster.scheduler_address) == [-3, 1, -7]


def test_an_unreachable_dask_scheduler_is_one_line_and_exit_2(tmp_path, capsys):
    pytest.importorskip("distributed")
    data = tmp_path / "data"
    (data / "a").mkdir(parents=True)
    (data / "a" / "scene.json").write_text("{}")
    code = main(["deblur", str(data), "-o", str(tmp_path / "out"), "--executor", "dask",
                 "--address", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--address" in err[0] and "127.0.0.1:9" in err[0]


def test_dataset_scenes_are_the_subfolders_with_a_scene_json(tmp_path):
    for name in ("b", "a", "c"):
        (tmp_path / name).mkdir()
    (tmp_path / "a" / "scene.json").write_text("{}")
    (tmp_path / "b" / "scene.json").write_text("{}")
    assert [p.name for p in dataset_scenes(tmp_path)] == ["a", "b"]
    with pytest.raises(InputError, match="no scene.json"):
        dataset_scenes(tmp_path / "c")


def test_a_folder_without_scenes_is_one_line_and_exit_2(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["deblur", str(tmp_path / "empty"), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "empty" in err and "scene folders" in err


@pytest.mark.slow
def test_a_dataset_runs_in_parallel_isolates_a_failure_and_resumes(tiny_scene, tmp_path, capsys):
    data, out = tmp_path / "data", tmp_path / "out"
    shutil.copytree(tiny_scene, data / "first")
    shutil.copytree(tiny_scene, data / "second")
    (data / "second" / "scene.json").write_text("{not json")  # a broken recording
    assert main(["deblur", str(data), "-o", str(out), "--jobs", "2", *TINY]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "1 of 2 recording(s) failed" in err[0] and "second:" in err[0]
    summary = json.loads((out / SUMMARY_FILE).read_text())["recordings"]
    assert [(r["name"], r["status"]) for r in summary] == [("first", "done"), ("second", "failed")]
    first = json.loads((out / "first" / PIECE_FILE).read_text())
    metrics = json.loads((out / "first" / "metrics.json").read_text())
    assert first["psnr"]["fusiongs"] == metrics["mean"]["deblur"]["fusiongs"]["psnr"]
    assert (out / "first" / "deblurred.mp4").is_file() and not (out / "second" / PIECE_FILE).exists()
    stamp = (out / "first" / PIECE_FILE).stat().st_mtime_ns

    shutil.rmtree(data / "second")
    shutil.copytree(tiny_scene, data / "second")  # mended: --resume runs only this one
    assert main(["deblur", str(data), "-o", str(out), "--resume", *TINY]) == 0
    printed = capsys.readouterr().out
    assert "first: finished earlier (kept)" in printed and "1 to run" in printed
    assert (out / "first" / PIECE_FILE).stat().st_mtime_ns == stamp
    summary = json.loads((out / SUMMARY_FILE).read_text())["recordings"]
    assert [r["status"] for r in summary] == ["done", "done"] and summary[0].get("resumed")
    assert "first" in format_summary(summary) and "second" in format_summary(summary)


@pytest.mark.slow
def test_a_dataset_runs_on_a_dask_cluster_the_test_starts(tiny_scene, tmp_path):
    distributed = pytest.importorskip("distributed")
    data, out = tmp_path / "data", tmp_path / "out"
    for name in ("one", "two"):
        shutil.copytree(tiny_scene, data / name)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        assert main(["deblur", str(data), "-o", str(out), "--executor", "dask",
                     "--address", cluster.scheduler_address, *TINY]) == 0
    summary = json.loads((out / SUMMARY_FILE).read_text())["recordings"]
    assert [(r["name"], r["status"]) for r in summary] == [("one", "done"), ("two", "done")]
    for name in ("one", "two"):
        metrics = json.loads((out / name / "metrics.json").read_text())
        assert summary[0 if name == "one" else 1]["psnr"] == {
            m: v["psnr"] for m, v in metrics["mean"]["deblur"].items()}


@pytest.mark.parametrize(("args", "field"), [(["--jobs", "-1"], "--jobs"),
                                             (["--address", "tcp://127.0.0.1:9"], "--address")])
def test_bad_worker_options_are_one_line_and_exit_2_before_any_work(args, field, tmp_path, capsys):
    assert main(["deblur", str(tmp_path / "none"), "-o", str(tmp_path / "out"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0]
