"""Training is device-clean by construction: no tensor silently lands on the CPU.

``fusiongs deblur … device=cuda`` once crashed at the first event window because the trainer's
generator lived on the CPU while the event count maps lived on the GPU. On a CPU-only machine that
bug is invisible (every device is the CPU), so these tests check the *rule* that prevents it: while
a few iterations train, every tensor factory must be given ``device=``, every ``torch.Generator``
must name its device, and a generator must be on the device of the tensor it fills. Call sites that
are host-side by design are listed in ``HOST_SIDE`` with the reason.

The ``cuda`` tests train on the GPU under the same audit, also record host synchronisations made
by fusiongs in the loop, and compare the losses with the CPU run.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from dataclasses import dataclass, field

import numpy as np
import pytest
import torch
from torch.overrides import TorchFunctionMode

import fusiongs
from fusiongs.errors import ConfigError, InputError
from fusiongs.pipeline.deblur import resolve_config
from fusiongs.render.gsplat_backend import gsplat_available
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.train.data import prepare_data
from fusiongs.train.trainer import train
from tests.conftest import has_cuda

PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(fusiongs.__file__)))
FACTORIES = {getattr(torch, n): n for n in (
    "zeros", "ones", "full", "empty", "eye", "arange", "linspace", "logspace", "rand", "randn",
    "randint", "randperm", "tensor", "as_tensor", "scalar_tensor", "triu_indices", "tril_indices")}

#: Call sites (file, function; "*": the whole file) allowed to make tensors on an implicit (CPU)
#: device, and why. Everything else in ``train`` must name its device.
HOST_SIDE = {
    # threshold estimation (fusiongs calibrate) works on the numpy frames and events, once
    ("fusiongs/calibrate/estimate.py", "*"): "host estimate before the loop",
    ("fusiongs/calibrate/fit.py", "*"): "host estimate before the loop",
    ("fusiongs/calibrate/data.py", "*"): "host estimate before the loop",
    ("fusiongs/calibrate/pixel_model.py", "*"): "host estimate before the loop",
    # the plane-sweep stereo initialisation runs on the host by design (stereo_points moves its
    # inputs to the CPU), once; initial_gaussians moves its points to the device
    ("fusiongs/camera/stereo.py", "*"): "host plane sweep before the loop",
    # numpy interop in data preparation, once before the loop: arrays -> tensors -> .to(device)
    ("fusiongs/train/data.py", "prepare_data"): "numpy -> tensor, once",
    ("fusiongs/train/data.py", "event_indices"): "numpy -> tensor, once",
    ("fusiongs/train/data.py", "hpf_images"): "numpy -> tensor, once",
    ("fusiongs/train/data.py", "pvc_readouts"): "numpy -> tensor, once",
    ("fusiongs/train/data.py", "edi_images"): "numpy -> tensor, once",
    ("fusiongs/train/data.py", "fast_events"): "numpy -> tensor, once (the censored counts' events)",
    ("fusiongs/train/lowpass_term.py", "hot_map"): "numpy -> tensor, once (then .to(device))",
    ("fusiongs/train/trainer.py", "init_images"): "numpy -> tensor for the host stereo, once",
    ("fusiongs/train/trainer.py", "reset_event_weights"): "numpy -> tensor, once (then .to(device))",
    ("fusiongs/losses/colour.py", "cfa_index"): "numpy -> tensor, once (then .to(device))",
    # checkpoints hold host tensors by definition (written every checkpoint_every iterations)
    ("fusiongs/train/checkpoint.py", "*"): "serialisation",
    # crop offsets: two Python ints drawn from the trainer's host generator, whose device is the
    # CPU. crop.py is outside this change; it should say device=gen.device
    ("fusiongs/train/crop.py", "random"): "host draw of two ints",
}


def _site(frame) -> tuple[str, str, int]:
    path = os.path.relpath(os.path.abspath(frame.f_code.co_filename), PACKAGE)
    return path, frame.f_code.co_name, frame.f_lineno


@dataclass
class Audit:
    """What the audited run did, as ``file:line (function): what`` of fusiongs call sites (torch's
    and other libraries' internals are theirs): ``implicit`` devices, and ``syncs`` (host
    synchronisations the CUDA sync debug mode reported inside the loop, when watched)."""

    implicit: list[str] = field(default_factory=list)
    syncs: list[str] = field(default_factory=list)
    watch_syncs: bool = False  # set once the loop starts (the first training_step)
    scope: str = "fusiongs"  # the package whose call sites are audited

    def note(self, kind: list[str], what: str, depth: int = 2) -> None:
        frame = sys._getframe(depth)
        path, func, line = _site(frame)
        if not path.startswith(self.scope + os.sep):
            return
        if kind is self.implicit and ((path, func) in HOST_SIDE or (path, "*") in HOST_SIDE):
            return
        kind.append(f"{path}:{line} ({func}): {what}")


class _Mode(TorchFunctionMode):
    def __init__(self, audit: Audit):
        super().__init__()
        self.audit = audit

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = FACTORIES.get(func)
        if name and kwargs.get("device") is None and not (
                name in ("tensor", "as_tensor") and args and isinstance(args[0], torch.Tensor)):
            self.audit.note(self.audit.implicit, f"torch.{name} without device=")
        if not self.audit.watch_syncs:
            out = func(*args, **kwargs)
        else:  # torch.cuda.set_sync_debug_mode("warn") is on: a sync warns inside the call
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                out = func(*args, **kwargs)
            for w in caught:
                if "synchroniz" in str(w.message):
                    self.audit.note(self.audit.syncs, f"{getattr(func, '__name__', func)} synchronises")
                else:
                    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        gen = kwargs.get("generator")
        if gen is not None and isinstance(out, torch.Tensor) and gen.device != out.device:
            self.audit.note(self.audit.implicit, f"{gen.device} generator fills a {out.device} tensor")
        return out


def audited_train(scene, cfg, out, monkeypatch, watch_syncs: bool = False):
    """``train`` with every factory and generator recorded, and with ``watch_syncs`` (CUDA) the
    host synchronisations from the first training step on."""
    import fusiongs.train.trainer as trainer

    audit = Audit()
    real_generator, real_from_numpy, real_step = torch.Generator, torch.from_numpy, trainer.training_step

    class Generator(real_generator):  # isinstance(g, torch.Generator) still holds for real ones
        def __new__(cls, device=None):
            if device is None:
                audit.note(audit.implicit, "torch.Generator() without a device")
            return real_generator() if device is None else real_generator(device)

    def from_numpy(a):
        audit.note(audit.implicit, "torch.from_numpy (always the CPU)")
        return real_from_numpy(a)

    def training_step(*args, **kwargs):
        if watch_syncs and not audit.watch_syncs:
            torch.cuda.set_sync_debug_mode("warn")
            audit.watch_syncs = True
        return real_step(*args, **kwargs)

    monkeypatch.setattr(torch, "Generator", Generator)
    monkeypatch.setattr(torch, "from_numpy", from_numpy)
    monkeypatch.setattr(trainer, "training_step", training_step)
    try:
        with _Mode(audit):
            tr = train(scene, cfg, out)
    finally:
        if audit.watch_syncs:
            torch.cuda.set_sync_debug_mode(0)
        monkeypatch.undo()
    return tr, audit


BASE = ["init.n_points=200", "blur.n_samples=3", "events.warmup=2", "events.pixels=96",
        "optim.iterations=6", "output.progress=false", "output.checkpoint_every=3",
        "densify.start=2", "densify.every=2", "densify.stop=5", "densify.grad_threshold=1e-9",
        "optim.pose_start=1", "blur.learn_gain=true", "blur.coarse_until=2", "backend=torch"]

CASES = {  # scene, overrides: together every training-time stage
    "grey-mse-crop-edi": ("grey", ["events.windows_inside=2", "events.windows_free=2",
                                   "blur.crop=[16,16]", "priors.edi_weight=0.5", "priors.edi_until=4"]),
    "grey-band-field-drift": ("grey", ["events.loss=band", "threshold.grid=[2,3]",
                                       "threshold.time_knots=3", "init.method=random"]),
    "colour-pvc-demosaic": ("colour", ["events.loss=pvc", "events.colour_mode=demosaic"]),
    "colour-mse-mask": ("colour", ["events.colour_mode=mask"]),
    "event-only": ("events", ["event_only.alpha_warmup=1", "event_only.alpha_ramp=2",
                              "event_only.hpf_readouts=12", "threshold.regularise=0.1",
                              "events.windows_free=2", "events.max_window=0.02",
                              "events.lowpass_weight=1"]),
    "event-only-chain": ("events", ["event_only.alpha_warmup=1", "event_only.alpha_ramp=2",
                                    "event_only.hpf_readouts=12", "events.windows_free=2",
                                    "events.max_window=0.02", "events.lowpass_weight=1",
                                    "events.chain_windows=true", "events.lowpass_history=1"]),
}


@pytest.fixture(scope="module")
def scenes():
    def sim(frames, cfa, seed):
        return run_simulation(SimConfig(preset="boxes", width=26, height=20, duration=0.1,
                                        frames=frames, exposure=0.03, dvs_rate_hz=500.0, blur_samples=4,
                                        supersample=1, novel=1, seed=seed, cfa=cfa)).scene
    return {"grey": sim(2, None, 1), "colour": sim(2, "RGGB", 2), "events": sim(0, None, 3)}


@pytest.mark.parametrize("case", CASES)
def test_training_makes_no_tensor_on_an_implicit_device(case, scenes, tmp_path, monkeypatch):
    scene, extra = CASES[case]
    cfg = resolve_config(None, BASE + extra)
    tr, audit = audited_train(scenes[scene], cfg, tmp_path, monkeypatch)
    h = tr.history
    assert math.isfinite(h.event[-1]), "the event loss ran"
    assert h.n_gaussians[-1] != h.n_gaussians[0], "a refinement step ran"
    bad = sorted(set(audit.implicit))
    assert not bad, "tensors or generators on an implicit device:\n  " + "\n  ".join(bad)


def test_the_audit_catches_a_factory_without_a_device(monkeypatch):
    """The rule itself: a generator or factory without a device is reported with its call site."""
    audit = Audit(scope="tests")
    with _Mode(audit):
        torch.zeros(3)
        torch.zeros(3, device="cpu")
        torch.as_tensor(torch.ones(2, device="cpu"))  # a tensor keeps its device
    assert len(audit.implicit) == 1 and "test_device_clean.py" in audit.implicit[0]
    assert "torch.zeros without device=" in audit.implicit[0]


@pytest.mark.parametrize("scene", ["grey", "colour"])
def test_count_maps_on_the_device_equal_the_event_streams(scenes, scene):
    data = prepare_data(scenes[scene], torch.device("cpu"), True)
    t0, t1 = data.t_range
    for a, b in [(t0, t1), (t0 + 0.01, t0 + 0.013), (t0 + 0.02, t0 + 0.02), (t1 - 0.005, t1 + 1.0)]:
        want = data.events.count_maps(int(round(a * 1e6)), int(round(b * 1e6)))
        got = data.count_maps(a, b, torch.device("cpu"))
        assert got.dtype == torch.float32
        np.testing.assert_array_equal(got.numpy(), want)


def test_records_are_read_back_together_and_a_diverged_loss_stops_training():
    from fusiongs.train.history import History, PendingRow, flush_pending

    class Bar:
        def set_postfix(self, **kw):
            self.postfix = kw

    h, bar = History(), Bar()
    nan = math.nan
    # loss, blur, event, event_lowpass, edi, intensity, tv, psnr_input, θ+, θ−
    pending = [PendingRow(0, torch.tensor([1.0, 0.5, nan, nan, nan, nan, nan, 20.0, 0.2, 0.3]), 10, 0.0),
               PendingRow(1, torch.tensor([0.9, 0.4, 0.1, 0.07, nan, 0.05, 0.02, 21.0, 0.21, 0.31]), 12, 0.1)]
    flush_pending(h, pending, bar)
    assert not pending and h.iteration == [0, 1] and h.n_gaussians == [10, 12]
    assert h.loss == pytest.approx([1.0, 0.9]) and math.isnan(h.event[0]) and h.event[1] == pytest.approx(0.1)
    assert h.theta_pos == [[pytest.approx(0.2)], [pytest.approx(0.21)]] and bar.postfix["n"] == 12
    assert h.theta_neg == [[pytest.approx(0.3)], [pytest.approx(0.31)]] and h.psnr_input[1] == 21.0
    assert math.isnan(h.intensity[0]) and h.intensity[1] == pytest.approx(0.05)
    assert math.isnan(h.tv[0]) and h.tv[1] == pytest.approx(0.02)
    assert math.isnan(h.event_lowpass[0]) and h.event_lowpass[1] == pytest.approx(0.07)
    with pytest.raises(InputError, match="nan at iteration 2"):
        flush_pending(h, [PendingRow(2, torch.tensor([math.nan] * 10), 12, 0.1)], bar)


# ------------------------------------------------------------------------------------------- CUDA
CUDA_CASES = ["grey-mse-crop-edi", "colour-pvc-demosaic", "event-only", "event-only-chain"]
# every pixel of a window is sampled, so the device generator's draws do not change the loss; the
# host generator (frames, windows, crops) and the initialisation are the same on both devices
SAME_DRAWS = ["events.pixels=100000", "densify.enabled=false", "backend=auto"]
#: fusiongs functions allowed to synchronise with the GPU inside the loop, and why.
SYNC_ALLOWED = {
    "flush_pending": "history and progress bar, every FLUSH_EVERY iterations and at checkpoints",
    "save_checkpoint": "checkpoints",
    "_payload": "checkpoints (the payload's running PSNR copied to the host)",
    # the demosaic masks and kernels are copied to the device once per size (cached), which may
    # be in the first step (the per-call copies of cfa.py and the B-spline basis of
    # camera/trajectory.py are gone; not yet checked on a GPU)
    "_bilinear_tensors": "first call per image size and device only",
}
cuda = pytest.mark.skipif(not has_cuda(), reason="needs a CUDA GPU")


@pytest.mark.cuda
@cuda
@pytest.mark.parametrize("case", CUDA_CASES)
def test_cuda_training_matches_the_cpu_and_names_its_devices(case, scenes, tmp_path, monkeypatch):
    scene, extra = CASES[case]
    cpu = train(scenes[scene], resolve_config(None, BASE + extra + SAME_DRAWS), tmp_path / "cpu")
    cfg = resolve_config(None, BASE + extra + SAME_DRAWS + ["device=cuda"])
    gpu, audit = audited_train(scenes[scene], cfg, tmp_path / "cuda", monkeypatch)
    assert gpu.state.model.means.device.type == "cuda"
    assert gpu.state.trajectory.knots.device.type == "cpu", "poses are computed on the host by design"
    assert not audit.implicit, "\n".join(sorted(set(audit.implicit)))
    for name in ("loss", "blur", "event"):
        a, b = getattr(cpu.history, name), getattr(gpu.history, name)
        assert len(a) == len(b) == cfg.optim.iterations
        for i, (x, y) in enumerate(zip(a, b)):
            assert math.isnan(x) == math.isnan(y), f"{name}[{i}]: {x} on the CPU, {y} on CUDA"
            if not math.isnan(x):
                assert y == pytest.approx(x, rel=2e-2, abs=1e-4), f"{name}[{i}]"


@pytest.mark.cuda
@cuda
@pytest.mark.skipif(not gsplat_available(), reason="needs gsplat: the pure-torch rasteriser sizes its "
                    "tile lists from the data (nonzero, bincount, repeat_interleave), so it synchronises")
@pytest.mark.parametrize("case", CUDA_CASES)
def test_cuda_training_loop_synchronises_only_to_record(case, scenes, tmp_path, monkeypatch):
    scene, extra = CASES[case]
    cfg = resolve_config(None, BASE + extra + SAME_DRAWS + ["device=cuda"])
    _, audit = audited_train(scenes[scene], cfg, tmp_path, monkeypatch, watch_syncs=True)
    syncs = sorted({s for s in audit.syncs if s.split(" (")[1].split(")")[0] not in SYNC_ALLOWED})
    assert not syncs, "host synchronisations in the loop:\n  " + "\n  ".join(syncs)


@pytest.mark.cuda
@cuda
def test_cuda_training_with_densification_names_its_devices(scenes, tmp_path, monkeypatch):
    scene, extra = CASES["grey-mse-crop-edi"]
    cfg = resolve_config(None, BASE + extra + ["device=cuda", "backend=auto"])
    tr, audit = audited_train(scenes[scene], cfg, tmp_path, monkeypatch)
    assert not audit.implicit, "\n".join(sorted(set(audit.implicit)))
    assert all(math.isfinite(v) for v in tr.history.loss)
    assert tr.history.n_gaussians[-1] != tr.history.n_gaussians[0]  # refinement ran on the GPU


def test_the_training_device_names_its_card():
    from fusiongs.train.trainer import training_device

    assert training_device("cpu") == torch.device("cpu")
    assert training_device("cuda:1") == torch.device("cuda", 1)  # named: kept, CUDA not touched
    if has_cuda():
        assert training_device("cuda") == torch.device("cuda", torch.cuda.current_device())


def test_a_device_the_machine_lacks_is_one_line_before_any_work(tiny_scene, tmp_path, capfd):
    """``device=`` naming no device this machine has: one line naming the key, exit 2, and nothing
    run or written (the calibration and the pose stage come before training and take minutes)."""
    from fusiongs.cli import main
    from fusiongs.train.trainer import check_device

    check_device("cpu")
    bad = ["nonsense", "cuda:99"] + ([] if has_cuda() else ["cuda", "cuda:0"])
    for name in bad:
        with pytest.raises(ConfigError, match="device: expected"):
            check_device(name)
    out = tmp_path / "out"
    capfd.readouterr()
    assert main(["deblur", str(tiny_scene), "-o", str(out), "device=nonsense"]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "device: expected a torch device" in err[0], err
    assert not out.exists() or not any(out.iterdir())
