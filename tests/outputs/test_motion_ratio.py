"""The exposure ratio carried by the fitted motion (fusiongs/outputs/motion_ratio.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.reproject import identity_grid
from fusiongs.camera.trajectory import Trajectory
from fusiongs.camera.tum import PoseSamples
from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.response import linear_to_response
from fusiongs.losses.blur import exposure_instants
from fusiongs.losses.threshold import ContrastThreshold
from fusiongs.outputs.exposure_ratio import (
    between_frames,
    corrected_renders,
    exposure_ratio,
    factor_carried,
    frame_factor,
)
from fusiongs.outputs.motion_ratio import adjoint, blur_operator, carry, motion_ratio
from fusiongs.scene.gaussians import GaussianModel
from fusiongs.train.state import FusionState

GREY = (0.299, 0.587, 0.114)
H, W, N = 10, 24, 7
CAM = PinholeCamera(width=W, height=H, fx=20.0, fy=20.0, cx=W / 2, cy=H / 2)


def _shifted(shifts_px) -> torch.Tensor:
    """``[n, H, W, 2]`` grids that read the reference image ``s`` pixels to the left of each pixel."""
    ident = identity_grid(CAM)
    out = ident.expand(len(shifts_px), H, W, 2).clone()
    out[..., 0] -= 2.0 * torch.as_tensor(shifts_px, dtype=torch.float64)[:, None, None] / W
    return out


def _smooth_detail(rng, channels) -> torch.Tensor:
    x = torch.arange(W, dtype=torch.float64)
    phase = torch.as_tensor(rng.uniform(0, 6, size=channels))
    return (1.0 + 0.35 * torch.sin(0.4 * x[None, :, None] + phase)).expand(H, W, channels).clone()


@pytest.mark.parametrize("channels", [1, 3])
def test_the_adjoint_is_the_transpose(channels):
    rng = np.random.default_rng(1)
    renders = torch.as_tensor(rng.uniform(0.1, 0.9, size=(N, H, W, 3)))
    grid = identity_grid(CAM) + torch.as_tensor(rng.normal(0, 0.05, size=(N, H, W, 2)))
    op = blur_operator(renders, grid, 1.3, channels, GREY)
    rho = torch.as_tensor(rng.uniform(0.5, 1.5, size=(H, W, channels)))
    y = torch.as_tensor(rng.normal(size=(H, W, channels)))
    lhs = (op(rho) * y).sum()
    rhs = (rho * adjoint(op, y)).sum()
    torch.testing.assert_close(lhs, rhs, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("channels", [1, 3])
def test_without_motion_one_iteration_is_the_per_pixel_ratio(channels):
    rng = np.random.default_rng(2)
    renders = torch.as_tensor(rng.uniform(0.1, 0.9, size=(N, H, W, 3)))
    observed = torch.as_tensor(rng.uniform(0.05, 0.95, size=(H, W, channels)))
    sat = torch.zeros(H, W, channels, dtype=torch.bool)
    sat[2, 3] = True
    grid = identity_grid(CAM).expand(N, H, W, 2)
    rho = motion_ratio(observed, renders, grid, 1.2, sat, 0.01, 1, GREY)
    pred = renders.mean(0) * 1.2
    if channels == 1:
        pred = pred @ torch.tensor(GREY, dtype=torch.float64)[:, None]
    torch.testing.assert_close(rho, exposure_ratio(observed, pred, sat, 0.01), rtol=1e-10, atol=1e-12)


def test_a_frame_the_motion_explains_leaves_the_factor_at_one():
    rng = np.random.default_rng(3)
    renders = torch.as_tensor(rng.uniform(0.1, 0.9, size=(N, H, W, 3)))
    grid = _shifted(np.linspace(-3, 3, N))
    op = blur_operator(renders, grid, 0.8, 3, GREY)
    observed = op(torch.ones(H, W, 3, dtype=torch.float64))
    none = torch.zeros_like(observed, dtype=torch.bool)
    rho = motion_ratio(observed, renders, grid, 0.8, none, 0.01, 5, GREY)
    torch.testing.assert_close(rho, torch.ones_like(rho), rtol=1e-9, atol=1e-9)


def test_detail_that_moves_is_deblurred_where_the_per_pixel_ratio_blurs_it():
    """The frame is the renders times a detail that moves 6 px during the exposure. The per-pixel
    ratio brings the detail back blurred; the motion-carried one, with the motion known, recovers
    it better, and better with more iterations (noise-free)."""
    rng = np.random.default_rng(4)
    detail = _smooth_detail(rng, 3)
    renders = 0.4 + 0.1 * torch.as_tensor(rng.uniform(size=(N, H, W, 3)))
    grid = _shifted(np.linspace(-3, 3, N))
    observed = blur_operator(renders, grid, 1.0, 3, GREY)(detail)
    sat = torch.zeros_like(observed, dtype=torch.bool)
    inner = (slice(None), slice(5, W - 5))  # away from the border, where the paths leave the image
    per_pixel = exposure_ratio(observed, renders.mean(0), sat, 1e-6)

    def err(rho):
        return float((rho - detail)[inner].abs().mean())

    e0 = err(per_pixel)
    e3 = err(motion_ratio(observed, renders, grid, 1.0, sat, 1e-6, 3, GREY))
    e30 = err(motion_ratio(observed, renders, grid, 1.0, sat, 1e-6, 30, GREY))
    assert e3 < 0.7 * e0 and e30 < 0.5 * e3, (e0, e3, e30)  # measured: 0.55 and 0.33


def test_carry_reads_the_factor_along_the_grid():
    rho = torch.arange(H * W, dtype=torch.float64).reshape(H, W, 1)
    out = carry(rho, _shifted([0.0, 2.0]))
    torch.testing.assert_close(out[0], rho)
    torch.testing.assert_close(out[1][:, 2:], rho[:, :-2])


class SlidingPlane:
    """A stand-in for FusionState: a textured plane at depth 1 seen by a camera moving left, so the
    pattern slides right at ``SPEED`` px/s; ``detail`` (on the plane) is what the model lacks."""

    SPEED = 60.0

    def __init__(self):
        self.model = SimpleNamespace(means=torch.zeros(1, 3))
        self.log_gain = torch.zeros(1)
        c2w = np.tile(np.eye(4), (2, 1, 1))
        c2w[1, 0, 3] = -self.SPEED / CAM.fx  # at t = 1 s
        self.trajectory = Trajectory(PoseSamples(t=np.array([0.0, 1.0]), c2w=c2w), mode="linear")

    @staticmethod
    def plane(x: torch.Tensor, detail: bool) -> torch.Tensor:
        base = 0.35 + 0.15 * torch.sin(0.35 * x)
        rgb = base[..., None] * torch.tensor([1.0, 0.8, 0.6], dtype=torch.float64)
        if detail:
            rgb = rgb * (1.0 + 0.3 * torch.sin(0.5 * x + 0.5))[..., None]
        return rgb

    def image(self, t: float, detail: bool = False) -> torch.Tensor:
        x = (torch.arange(W, dtype=torch.float64) + 0.5 - self.SPEED * t)[None, :].expand(H, W)
        return self.plane(x, detail).float()

    def render(self, camera, t, backend="auto"):
        return torch.stack([self.image(float(v)) for v in t]), None, None

    def render_depth(self, camera, t, backend="auto"):
        return torch.ones(len(t), H, W), torch.ones(len(t), H, W)


def test_corrected_renders_deblur_moving_detail_with_the_fitted_motion():
    state = SlidingPlane()
    s, e = 0.0, 0.1  # 6 px of motion
    truth = torch.stack([state.image(float(t), detail=True) for t in exposure_instants(s, e, 25)]).mean(0)
    frame = linear_to_response(truth.numpy().astype(np.float64), "srgb")
    scene = SimpleNamespace(frames=FrameSet(images=np.asarray([frame], np.float32), t_start=np.array([s]),
                                            t_end=np.array([e]), names=("000000",), response="srgb"),
                            camera=CAM)
    mid = 0.5 * (s + e)
    sharp = state.image(mid, detail=True).numpy()
    inner = (slice(None), slice(6, W - 6))
    errs = {}
    for it in (0, 3):
        plain, fixed, which = corrected_renders(state, scene, [mid, 0.5], state.log_gain, N, 1e-4, GREY,
                                                iterations=it)
        assert which.tolist() == [True, False]
        np.testing.assert_array_equal(fixed[1], plain[1])  # outside the exposure: the render
        errs[it] = float(np.abs(fixed[0] - sharp)[inner].mean())
    render_err = float(np.abs(plain[0] - sharp)[inner].mean())
    assert errs[3] < 0.6 * errs[0] < render_err, (errs, render_err)


@pytest.mark.parametrize("iterations", [0, 3])
def test_a_kept_frames_factor_carried_along_the_motion_predicts_a_held_out_frame(iterations):
    """--holdout's ``fusiongs_ratio``: the detail of the kept frames 0 and 2, carried to frame 1's
    exposure, predicts frame 1 (which the factors never saw) better than the render alone."""
    state = SlidingPlane()
    spans = [(0.0, 0.05), (0.1, 0.15), (0.2, 0.25)]  # 3 px of motion in each exposure, 6 px between

    def blurry(s, e, detail):
        return torch.stack([state.image(float(t), detail) for t in exposure_instants(s, e, 25)]).mean(0)

    frames = np.stack([linear_to_response(blurry(s, e, True).numpy().astype(np.float64), "srgb")
                       for s, e in spans]).astype(np.float32)
    starts, ends = (np.array(v) for v in zip(*spans))
    scene = SimpleNamespace(frames=FrameSet(images=frames, t_start=starts, t_end=ends, names=("0", "1", "2"),
                                            response="srgb"), camera=CAM)
    gains = torch.zeros(3)
    times = exposure_instants(*spans[1], N)
    renders = state.render(CAM, times)[0]
    carried = [renders * factor_carried(state, scene, frame_factor(state, scene, j, gains, N, 1e-4, GREY,
                                                                   iterations=iterations), j, times)
               for j in (0, 2)]
    assert carried[0].shape == renders.shape == (N, H, W, 3)
    truth = blurry(*spans[1], True)
    inner = (slice(None), slice(8, W - 8))

    def err(pred):
        return float((pred.mean(0) - truth).abs()[inner].mean())

    with_detail, render_only = err(torch.stack(carried).mean(0)), err(renders)
    assert with_detail < 0.5 * render_only, (with_detail, render_only)
    # a factor of 1 carries nothing: the prediction is the render's
    ones = factor_carried(state, scene, torch.ones(H, W, 1), 0, times)
    torch.testing.assert_close(ones, torch.ones_like(renders))


def test_between_frames_weighs_the_two_exposures_linearly_in_time():
    times = np.array([0.02, 0.05, 0.07, 0.2, -0.1])
    rows = between_frames(np.array([0.0, 0.1]), np.array([0.04, 0.14]), times)
    np.testing.assert_allclose(rows, [[-1, -1, 0], [0, 1, 5 / 6], [0, 1, 0.5], [1, -1, 0], [-1, 0, 0]])


def test_instants_between_exposures_get_both_frames_detail_when_asked():
    """``output.ratio_between``: an instant in the gap between two exposures is corrected with both
    frames' factors carried to it, which brings the plane's detail that the renders lack."""
    state = SlidingPlane()
    spans = [(0.0, 0.04), (0.1, 0.14)]
    frames = np.stack([linear_to_response(torch.stack([state.image(float(t), True) for t in
                                                       exposure_instants(s, e, 25)]).mean(0).numpy()
                                          .astype(np.float64), "srgb") for s, e in spans]).astype(np.float32)
    starts, ends = (np.array(v) for v in zip(*spans))
    scene = SimpleNamespace(frames=FrameSet(images=frames, t_start=starts, t_end=ends, names=("0", "1"),
                                            response="srgb"), camera=CAM)
    times = [0.07, 0.2]  # in the gap; after the last exposure
    truth = state.image(0.07, detail=True).numpy()
    inner = (slice(None), slice(8, W - 8))
    gains = torch.zeros(2)
    plain, off, applied_off = corrected_renders(state, scene, times, gains, N, 1e-4, GREY, iterations=3)
    _, on, applied_on = corrected_renders(state, scene, times, gains, N, 1e-4, GREY, iterations=3,
                                          between=True)
    assert applied_off.tolist() == [False, False] and applied_on.tolist() == [True, False]
    np.testing.assert_array_equal(off, plain)
    np.testing.assert_array_equal(on[1], plain[1])  # no frame after it: as rendered
    err_on, err_render = (float(np.abs(v - truth)[inner].mean()) for v in (on[0], plain[0]))
    assert err_on < 0.5 * err_render, (err_on, err_render)


def test_render_depth_of_a_plane_of_gaussians():
    xy = torch.stack(torch.meshgrid(torch.linspace(-2, 2, 21), torch.linspace(-2, 2, 21), indexing="ij"), -1)
    xyz = torch.cat([xy.reshape(-1, 2), torch.full((441, 1), 3.0)], 1)
    model = GaussianModel.from_points(xyz, sh_degree=0, init_opacity=0.95)
    traj = Trajectory(PoseSamples(t=np.array([0.0, 1.0]), c2w=np.tile(np.eye(4), (2, 1, 1))), mode="linear")
    state = FusionState(model, traj, ContrastThreshold(), 1, False)
    depth, alpha = state.render_depth(CAM, torch.tensor([0.0, 0.5], dtype=torch.float64))
    assert depth.shape == alpha.shape == (2, H, W)
    covered = alpha > 0.5
    assert covered.float().mean() > 0.9
    np.testing.assert_allclose(depth[covered].numpy(), 3.0, rtol=1e-3)


def test_a_negative_iteration_count_is_refused_by_name():
    from fusiongs.errors import ConfigError
    from fusiongs.pipeline.deblur import resolve_config

    assert resolve_config(None, []).output.ratio_iterations == 3
    assert resolve_config(None, ["output.ratio_iterations=0"]).output.ratio_iterations == 0
    with pytest.raises(ConfigError, match="output.ratio_iterations"):
        resolve_config(None, ["output.ratio_iterations=-1"])
