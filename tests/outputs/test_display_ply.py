"""``model.ply`` shows 3DGS viewers the run's own renders: its colours and opacities are fitted for
display-space compositing (fusiongs/outputs/display_ply.py), checked with an independent dense
renderer that reads the file as viewers do (tests/reference/viewer_composite.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.tum import read_tum
from fusiongs.cli import main
from fusiongs.frames.image_io import read_image
from fusiongs.outputs.display_ply import DisplayFitOptions, composite_display, display_model, fit_display
from fusiongs.scene.gaussians import GaussianModel
from fusiongs.scene.ply import load_ply, save_ply
from fusiongs.train.restore import restore_state
from tests.conftest import small_run
from tests.reference.viewer_composite import read_vertices, render_viewer


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return -10.0 * math.log10(float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def _overlapping_model(seed: int = 0) -> GaussianModel:
    """Gaussians of clashing linear colours overlapping half-transparently in front of a camera at
    the origin looking down +z (where per-Gaussian sRGB encoding and display compositing differ)."""
    g = torch.Generator().manual_seed(seed)
    n = 40
    means = torch.cat([torch.rand(n, 2, generator=g) * 1.2 - 0.6, 2.0 + torch.rand(n, 1, generator=g)], 1)
    log_scales = torch.log(torch.full((n, 3), 0.15) * (0.5 + torch.rand(n, 3, generator=g)))
    quats = torch.nn.functional.normalize(torch.randn(n, 4, generator=g), dim=1)
    opacity = torch.logit(0.3 + 0.6 * torch.rand(n, generator=g))
    colour = torch.rand(n, 3, generator=g) ** 3  # dark-heavy linear colours: the encoding bends them most
    sh0 = ((colour - 0.5) / 0.28209479177387814)[:, None, :]
    return GaussianModel(means, log_scales, quats, opacity, sh0, torch.zeros(n, 0, 3), active_sh_degree=0)


def test_the_fit_shows_viewers_the_linear_composite_and_leaves_the_model_alone():
    from fusiongs.frames.response import linear_to_srgb
    from fusiongs.render import rasterize

    model = _overlapping_model()
    before = {k: v.detach().clone() for k, v in model.state_dict().items() if torch.is_tensor(v)}
    cam = PinholeCamera(width=24, height=18, fx=20.0, fy=20.0, cx=12.0, cy=9.0)
    w2c = torch.eye(4)[None].repeat(2, 1, 1)
    w2c[1, 0, 3] = 0.1
    with torch.no_grad():
        lin, _, _ = rasterize(model.means, model.rotations, model.scales, model.opacities, model.sh_coeffs(),
                              w2c, cam.K().expand(2, 3, 3), cam.width, cam.height, sh_degree=0)
    target = np.asarray(linear_to_srgb(lin.clamp(0, 1).numpy()), np.float32)
    fit = fit_display(model, cam, w2c, target, cam, w2c, target, DisplayFitOptions(steps=150))
    assert fit.psnr_after > fit.psnr_before + 3.0, (fit.psnr_before, fit.psnr_after)
    shown = composite_display(fit.model, cam, w2c).detach().numpy()
    assert psnr(shown, target) == pytest.approx(fit.psnr_after, abs=1e-6)
    for k, v in model.state_dict().items():
        if k in before:
            assert torch.equal(v, before[k]), k
    none = fit_display(model, cam, w2c, target, cam, w2c, target, DisplayFitOptions(steps=0))
    assert none.steps == 0 and none.psnr_after == none.psnr_before


def test_display_colours_are_written_and_read_as_stored(tmp_path):
    model = display_model(_overlapping_model(1))
    save_ply(model, tmp_path / "d.ply", colours="display", comment="a test")
    back = load_ply(tmp_path / "d.ply", colours="display")
    assert torch.equal(back.sh0, model.sh0) and torch.equal(back.opacity_logits, model.opacity_logits)
    assert b"comment a test\n" in (tmp_path / "d.ply").read_bytes()[:400]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return small_run(tmp_path_factory)


@pytest.mark.slow
def test_model_ply_composited_as_viewers_do_is_the_runs_own_render(run, tmp_path, record_property):
    """At every frame's fitted pose, model.ply drawn by the independent viewer-style renderer is
    within 30 dB of what ``fusiongs render`` gives there; the per-Gaussian conversion is not."""
    frames = json.loads((run / "frames.json").read_text())["frames"]
    mids = [f["t_mid"] for f in frames]
    assert main(["render", str(run), "--t", *map(str, mids), "-o", str(tmp_path / "r")]) == 0
    renders = [read_image(tmp_path / "r" / f"t_{t:.6f}.png") for t in mids]
    path = read_tum(run / "trajectory.txt")  # the written path holds every mid-exposure exactly
    c2w = [path.c2w[int(np.argmin(np.abs(path.t - t)))] for t in mids]
    assert all(np.min(np.abs(path.t - t)) < 1e-9 for t in mids)
    state, cam, _ = restore_state(run / "checkpoint.pt")
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]])
    save_ply(display_model(state.model), tmp_path / "unfitted.ply", colours="display")

    def shown(ply):
        v = read_vertices(ply)
        return [render_viewer(v, np.linalg.inv(p), K, cam.width, cam.height) for p in c2w]

    fitted = psnr(np.stack(shown(run / "model.ply")), np.stack(renders))
    unfitted = psnr(np.stack(shown(tmp_path / "unfitted.ply")), np.stack(renders))
    record_property("psnr_fitted_db", fitted)
    record_property("psnr_unfitted_db", unfitted)
    print(f"model.ply as viewers draw it, against fusiongs render at {len(mids)} fitted poses: "
          f"{fitted:.2f} dB fitted, {unfitted:.2f} dB per-Gaussian conversion")
    assert fitted >= 30.0
    assert unfitted < fitted - 3.0
    reported = json.loads((run / "metrics.json").read_text())["model_ply"]
    assert reported["psnr_after"] == pytest.approx(fitted, abs=1.5)  # fusiongs' own figure agrees
