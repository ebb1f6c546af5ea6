"""Checkpoints hold tensors and plain data only: a crafted pickle is refused unread, and a corrupt
file is one named error (also through ``fusiongs deblur --resume``)."""

from __future__ import annotations

import json
import pickle
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest
import torch

from fusiongs.cli import main
from fusiongs.errors import InputError
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene
from fusiongs.train.checkpoint import FORMAT, VERSION, load_checkpoint, plain_data, save_checkpoint


class _Exploit:
    """Unpickling this creates ``marker`` (``open(marker, "w")``): the side effect must not happen."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _payload(**extra):
    model = torch.nn.Linear(2, 3).state_dict()
    return {"iteration": 7, "config": {"seed": 1, "grid": (2, 3), "name": "x", "none": None},
            "camera": {"fx": 10.0, "distortion": None}, "model": model,
            "trajectory": {"t": np.linspace(0, 1, 4), "c2w": np.eye(4)[None].repeat(4, 0),
                           "mode": "linear", "spacing": np.float64(0.5)},
            "threshold": {"log_theta": torch.zeros(2)}, "generator": torch.Generator().get_state(),
            **extra}


def _crafted_files(tmp_path: Path, marker: Path) -> list[Path]:
    """Raw pickles (protocols 2 and 5) and a ``torch.save`` zip in the checkpoint format, each
    carrying the exploit."""
    files = []
    for proto in (2, 5):
        raw = tmp_path / f"raw{proto}" / "checkpoint.pt"
        raw.parent.mkdir()
        exploit = {"format": FORMAT, "version": VERSION, "x": _Exploit(marker)}
        raw.write_bytes(pickle.dumps(exploit, protocol=proto))
        files.append(raw)
    zipped = tmp_path / "zip" / "checkpoint.pt"
    zipped.parent.mkdir()
    torch.save({"format": FORMAT, "version": VERSION, **_payload(config=_Exploit(marker))}, zipped)
    return [*files, zipped]


def test_round_trip_reads_tensors_and_plain_data(tmp_path):
    payload = _payload(count=np.int64(3), flag=np.bool_(True))
    save_checkpoint(tmp_path / "checkpoint.pt", payload)
    ck = load_checkpoint(tmp_path / "checkpoint.pt")
    assert ck["format"] == FORMAT and ck["iteration"] == 7 and ck["config"]["grid"] == (2, 3)
    tj = ck["trajectory"]
    assert tj["t"].dtype == torch.float64 and np.array_equal(np.asarray(tj["t"]), np.linspace(0, 1, 4))
    assert np.array_equal(np.asarray(tj["c2w"]), payload["trajectory"]["c2w"])
    assert type(tj["spacing"]) is float and ck["count"] == 3 and ck["flag"] is True
    assert isinstance(ck["model"], OrderedDict) and torch.equal(ck["model"]["weight"],
                                                                payload["model"]["weight"])
    layer = torch.nn.Linear(2, 3)
    layer.load_state_dict(ck["model"])
    g = torch.Generator()
    g.set_state(ck["generator"])
    assert [p.name for p in tmp_path.iterdir()] == ["checkpoint.pt"]


def test_saving_an_object_that_would_not_load_back_names_its_key():
    with pytest.raises(TypeError, match=r"payload/config/where: PosixPath"):
        plain_data({"config": {"where": Path("/tmp")}})
    with pytest.raises(TypeError, match=r"payload/a\[1\]: numpy array of dtype object"):
        plain_data({"a": [1, np.array([None])]})


def test_crafted_pickle_is_refused_without_running_it(tmp_path):
    marker = tmp_path / "pwned"
    for path in _crafted_files(tmp_path, marker):
        with pytest.raises(InputError) as e:
            load_checkpoint(path)
        msg = str(e.value)
        assert msg.startswith(f"{path}: checkpoint: ") and "refused" in msg and "\n" not in msg
        assert "io.open" in msg or "raw5" in msg  # protocol 5 pickles name no global to torch
        assert not marker.exists(), "loading ran the pickled code"
    pickle.loads((tmp_path / "raw2" / "checkpoint.pt").read_bytes())  # what an unsafe load does
    assert marker.exists()


def test_checkpoint_with_numpy_arrays_is_refused(tmp_path):
    """Files pickling numpy arrays (as older fusiongs checkpoints did) are refused, not read."""
    torch.save({"format": FORMAT, "version": VERSION, "t": np.zeros(3)}, tmp_path / "c.pt")
    with pytest.raises(InputError, match=r"c\.pt: checkpoint: .*numpy.*refused"):
        load_checkpoint(tmp_path / "c.pt")


@pytest.mark.parametrize("cut", [0.5, 0.1])
def test_truncated_checkpoint_is_one_named_error(tmp_path, cut):
    save_checkpoint(tmp_path / "full.pt", _payload())
    data = (tmp_path / "full.pt").read_bytes()
    (tmp_path / "checkpoint.pt").write_bytes(data[: int(len(data) * cut)])
    with pytest.raises(InputError, match=r"checkpoint\.pt: checkpoint: .*unreadable") as e:
        load_checkpoint(tmp_path / "checkpoint.pt")
    assert "\n" not in str(e.value)


@pytest.fixture(scope="module")
def tiny_scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("scene")
    cfg = SimConfig(preset="boxes", width=16, height=12, duration=0.08, frames=2, exposure=0.02,
                    dvs_rate_hz=500.0, blur_samples=3, supersample=1, novel=0, seed=1)
    res = run_simulation(cfg)
    write_simulated_scene(res.scene, res.gt, root, stats=res.stats, overwrite=True)
    return root


def _deblur_resume(scene: Path, out: Path, capsys) -> str:
    args = ["deblur", str(scene), "-o", str(out), "--resume", "init.n_points=50",
            "optim.iterations=2", "output.progress=false", "output.checkpoint_every=0"]
    assert main(args) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1, captured.err
    assert str(out / "checkpoint.pt") in err[0]
    assert not (out / "model.ply").exists(), "the run went on after the bad checkpoint"
    return err[0]


def test_deblur_resume_refuses_a_crafted_checkpoint(tiny_scene, tmp_path, capsys):
    marker = tmp_path / "pwned"
    crafted = _crafted_files(tmp_path, marker)[-1]
    line = _deblur_resume(tiny_scene, crafted.parent, capsys)
    assert "refused" in line and not marker.exists()


def test_deblur_resume_on_a_truncated_checkpoint_is_one_line(tiny_scene, tmp_path, capsys):
    save_checkpoint(tmp_path / "full.pt", _payload())
    (tmp_path / "checkpoint.pt").write_bytes((tmp_path / "full.pt").read_bytes()[:300])
    assert "unreadable" in _deblur_resume(tiny_scene, tmp_path, capsys)


@pytest.mark.parametrize("edit", ["generator", "densify", "model"])
def test_deblur_resume_on_a_foreign_checkpoint_is_one_line(tiny_scene, tiny_run, tmp_path, capsys, edit):
    # readable, of the right format, but not what this run saved: one line naming the file
    ckpt = load_checkpoint(tiny_run / "checkpoint.pt")
    if edit == "generator":
        ckpt["generator"] = torch.zeros(3, dtype=torch.uint8)
    elif edit == "densify":
        ckpt["densify"] = {"grad2d": "not a tensor"}
    else:
        ckpt["model"] = {}  # no Gaussian parameters
    save_checkpoint(tmp_path / "checkpoint.pt", ckpt)
    assert "a complete fusiongs checkpoint" in _deblur_resume(tiny_scene, tmp_path, capsys)


def test_the_calibration_warning_is_said_once_when_a_run_starts(tiny_scene, tmp_path, capsys):
    # the tiny scene's refractory gate leaves nothing to fit: its calibration warns (calibrate.py)
    args = ["deblur", str(tiny_scene), "-o", str(tmp_path), "init.n_points=50", "optim.iterations=2",
            "output.progress=false"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert err.count("fusiongs: calibration warning: the refractory gate left too few pixel pairs") == 1
    doc = json.loads((tmp_path / "calibration.json").read_text())
    assert len(doc["thresholds"]["details"]["warnings"]) == 1
    assert main([*args, "--resume"]) == 0  # said when the run started, not again
    assert "calibration warning" not in capsys.readouterr().err
