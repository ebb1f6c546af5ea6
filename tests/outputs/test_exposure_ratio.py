"""The exposure-ratio correction of the deblurred frames (fusiongs/outputs/exposure_ratio.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.response import linear_to_response
from fusiongs.losses.blur import exposure_instants
from fusiongs.outputs.exposure_ratio import (
    SATURATED,
    containing_frame,
    corrected_renders,
    exposure_ratio,
    frame_log_gains,
)

H, W, N = 6, 8, 5
GREY = (0.299, 0.587, 0.114)


class MovingPattern:
    """A stand-in for FusionState: renders a bright stripe pattern sliding right at 40 px/s."""

    def __init__(self, n_frames: int, log_gain=None):
        self.model = SimpleNamespace(means=torch.zeros(1, 3))
        self.log_gain = torch.zeros(n_frames) if log_gain is None else torch.as_tensor(log_gain)
        self.calls = 0

    def image(self, t: float) -> torch.Tensor:
        x = torch.arange(W, dtype=torch.float64) - 40.0 * t
        base = 0.35 + 0.25 * torch.sin(x * 0.9)[None, :, None] + 0.02 * torch.arange(H)[:, None, None]
        return (base * torch.tensor([1.0, 0.8, 0.6], dtype=torch.float64)).float()

    def render(self, camera, t, backend="auto"):
        self.calls += 1
        return torch.stack([self.image(float(v)) for v in t]), None, None


def _scene(images, t_start, t_end, response="srgb"):
    names = tuple(f"{i:06d}" for i in range(len(t_start)))
    frames = FrameSet(images=np.asarray(images, np.float32), t_start=np.asarray(t_start, np.float64),
                      t_end=np.asarray(t_end, np.float64), names=names, response=response)
    return SimpleNamespace(frames=frames, camera=SimpleNamespace(height=H, width=W))


def _blurry(state, s, e, detail, gain=1.0):
    """The frame the model predicts for exposure [s, e], times a static per-pixel ``detail``."""
    lin = torch.stack([state.image(float(t)) for t in exposure_instants(s, e, N)]).mean(0)
    return linear_to_response((lin * detail * gain).numpy().astype(np.float64), "srgb")


def test_ratio_is_frame_over_prediction_and_one_where_saturated():
    obs = torch.tensor([[[0.2], [0.5], [1.0]]])
    pred = torch.tensor([[[0.1], [0.5], [0.4]]])
    sat = torch.tensor([[[False], [False], [True]]])
    r = exposure_ratio(obs, pred, sat, 0.01)
    assert torch.allclose(r, torch.tensor([[[0.21 / 0.11], [1.0], [1.0]]]))


def test_a_frame_the_model_explains_leaves_the_render_unchanged():
    state = MovingPattern(2)
    s, e = np.array([0.0, 0.1]), np.array([0.03, 0.13])
    imgs = [_blurry(state, a, b, 1.0) for a, b in zip(s, e)]
    mids = 0.5 * (s + e)
    plain, fixed, frame = corrected_renders(state, _scene(imgs, s, e), mids, state.log_gain, N, 1e-3, GREY)
    assert frame.tolist() == [True, True]
    np.testing.assert_allclose(plain, torch.stack([state.image(float(t)) for t in mids]).numpy(), atol=1e-6)
    np.testing.assert_allclose(fixed, plain, atol=1e-5)


@pytest.mark.parametrize("channels", [3, 1])
def test_static_detail_the_model_lacks_is_restored_at_every_instant_of_the_exposure(channels):
    """The true image is the render times a static per-pixel factor: the frame reveals it, and the
    correction recovers the true sharp image inside the exposure (exactly, up to eps)."""
    rng = np.random.default_rng(0)
    detail = torch.as_tensor(rng.uniform(0.6, 1.4, size=(H, W, channels)), dtype=torch.float32)
    state = MovingPattern(1, log_gain=[np.log(1.2)])
    s, e = 0.0, 0.05
    lin = torch.stack([state.image(float(t)) for t in exposure_instants(s, e, N)]).mean(0) * 1.2
    if channels == 1:
        lin = lin[..., 0:1] * GREY[0] + lin[..., 1:2] * GREY[1] + lin[..., 2:3] * GREY[2]
    frame = linear_to_response((lin * detail).numpy().astype(np.float64), "srgb")
    times = np.array([0.0, 0.02, 0.05, 0.2])  # the last one is outside the exposure
    plain, fixed, which = corrected_renders(state, _scene([frame], [s], [e]), times, state.log_gain,
                                            N, 1e-7, GREY)
    assert which.tolist() == [True, True, True, False]
    truth = plain[:3] * detail.numpy()  # the gain g is the frame's, not the scene's
    np.testing.assert_allclose(fixed[:3], truth, rtol=1e-4, atol=1e-6)
    np.testing.assert_array_equal(fixed[3], plain[3])


def test_saturated_pixels_keep_the_render():
    state = MovingPattern(1)
    frame = _blurry(state, 0.0, 0.04, 0.7)
    frame[2, 3] = 1.0  # clipped in the captured frame
    plain, fixed, _ = corrected_renders(state, _scene([frame], [0.0], [0.04]), [0.02], state.log_gain, N,
                                        1e-6, GREY)
    np.testing.assert_array_equal(fixed[0, 2, 3], plain[0, 2, 3])
    np.testing.assert_allclose(fixed[0, 0, 0], 0.7 * plain[0, 0, 0], rtol=1e-4)
    assert SATURATED < 1.0 and SATURATED > 254 / 255


def test_containing_frame_prefers_the_nearer_mid_exposure_and_says_none():
    s, e = np.array([0.0, 0.08, 0.5]), np.array([0.1, 0.2, 0.6])
    got = containing_frame(s, e, np.array([0.05, 0.09, 0.15, 0.3, 0.5, 0.6, -1.0]))
    assert got.tolist() == [0, 0, 1, -1, 2, 2, -1]
    assert containing_frame(np.zeros(0), np.zeros(0), np.array([0.1])).tolist() == [-1]


def test_frame_log_gains_fill_held_out_frames_with_the_mean_gain():
    state = SimpleNamespace(log_gain=torch.log(torch.tensor([1.0, 4.0])))
    g = frame_log_gains(state, 3, kept=np.array([0, 2]))
    np.testing.assert_allclose(g.exp().numpy(), [1.0, 2.5, 4.0], rtol=1e-6)
    assert frame_log_gains(state, 2) is not None and torch.equal(frame_log_gains(state, 2), state.log_gain)


def test_the_colour_anchor_is_applied_before_the_ratio():
    """With a colour transform (the one-frame anchor) a frame that matches the anchored renders
    leaves them as anchored; the returned plain renders stay raw."""
    state = MovingPattern(1)
    gain, offset = np.array([1.5, 0.9, 0.7]), np.array([0.01, 0.0, 0.02])
    s, e = 0.0, 0.04
    anchored = [state.image(float(t)).clamp(0, 1) * torch.tensor(gain, dtype=torch.float32)
                + torch.tensor(offset, dtype=torch.float32) for t in exposure_instants(s, e, N)]
    frame = linear_to_response(torch.stack(anchored).mean(0).numpy().astype(np.float64), "srgb")
    plain, fixed, _ = corrected_renders(state, _scene([frame], [s], [e]), [0.02], state.log_gain, N, 1e-3,
                                        GREY, colour=(gain, offset))
    raw = state.image(0.02).numpy()
    np.testing.assert_allclose(plain[0], raw, atol=1e-6)
    np.testing.assert_allclose(fixed[0], np.clip(raw, 0, 1) * gain + offset, rtol=1e-4, atol=1e-5)
