"""Blur model and blur loss."""

from __future__ import annotations

import pytest
import torch
from kornia.metrics import ssim

from fusiongs.errors import InputError
from fusiongs.losses.blur import (
    apply_response,
    blur_loss,
    blurry_from_renders,
    exposure_average,
    exposure_instants,
    render_blurry,
)


def test_exposure_instants_are_midpoints_and_middle_is_mid_exposure():
    t = exposure_instants(1.0, 1.9, 9)
    assert t.dtype == torch.float64
    torch.testing.assert_close(t, 1.0 + (torch.arange(9, dtype=torch.float64) + 0.5) * 0.1)
    assert t[4].item() == pytest.approx(1.45)


def test_exposure_instants_batched_shape():
    s = torch.tensor([0.0, 1.0], dtype=torch.float64)
    t = exposure_instants(s, s + 0.04, 4)
    assert t.shape == (2, 4)
    torch.testing.assert_close(t[1], torch.tensor([1.005, 1.015, 1.025, 1.035], dtype=torch.float64))


def test_exposure_instants_rejects_zero_n():
    with pytest.raises(InputError, match="n"):
        exposure_instants(0.0, 1.0, 0)


def test_exposure_average_is_mean_over_instants_for_both_layouts():
    r = torch.rand(2, 3, 4, 5, 3)
    torch.testing.assert_close(exposure_average(r), r.mean(1))
    torch.testing.assert_close(exposure_average(r[0]), r[0].mean(0))


def test_srgb_response_matches_reference_values():
    x = torch.tensor([0.0, 0.002, 0.0031308, 0.18, 1.0], dtype=torch.float64)
    y = apply_response(x, "srgb")
    expected = [0.0, 0.02584, 0.04045, 0.46135, 1.0]
    torch.testing.assert_close(y, torch.tensor(expected, dtype=torch.float64), atol=2e-5, rtol=0)


def test_response_gamma_and_linear_and_bad_name():
    x = torch.tensor([0.25, 1.0])
    torch.testing.assert_close(apply_response(x, "gamma:2"), torch.tensor([0.5, 1.0]))
    assert apply_response(x, "linear") is x
    with pytest.raises(InputError, match="response"):
        apply_response(x, "log")
    with pytest.raises(InputError, match="gamma"):
        apply_response(x, "gamma:-1")


def test_srgb_gradient_finite_at_zero_and_negative():
    x = torch.tensor([-0.1, 0.0, 0.5], requires_grad=True)
    apply_response(x, "srgb").sum().backward()
    assert torch.isfinite(x.grad).all()
    assert x.grad[0].item() == pytest.approx(12.92)


def test_blurry_prediction_averages_in_linear_light_then_encodes():
    # two instants: black and white -> linear mean 0.5 -> sRGB 0.7354, not 0.5
    r = torch.stack([torch.zeros(1, 1, 3), torch.ones(1, 1, 3)])
    b = blurry_from_renders(r, response="srgb")
    torch.testing.assert_close(b, torch.full((1, 1, 3), 0.735357), atol=1e-5, rtol=0)


def test_per_frame_gain_in_batch():
    r = torch.full((2, 3, 2, 2, 1), 0.25)
    b = blurry_from_renders(r, gain=torch.tensor([1.0, 2.0]), response="linear")
    torch.testing.assert_close(b[:, 0, 0, 0], torch.tensor([0.25, 0.5]))


def test_render_blurry_calls_renderer_with_instants():
    seen = {}

    def render_fn(t):
        seen["t"] = t
        return t.float()[:, None, None, None].expand(len(t), 2, 2, 3)

    b = render_blurry(render_fn, 0.0, 1.0, n=5, response="linear")
    assert seen["t"].shape == (5,)
    torch.testing.assert_close(b, torch.full((2, 2, 3), 0.5))


def test_blur_loss_hand_example_l1_only_and_with_ssim():
    pred = torch.zeros(1, 16, 16, 3)
    target = torch.full((1, 16, 16, 3), 0.1)
    assert blur_loss(pred, target, lam=0.0).item() == pytest.approx(0.1)
    s = ssim(pred.permute(0, 3, 1, 2), target.permute(0, 3, 1, 2), 11).mean().item()
    assert blur_loss(pred, target, lam=0.2).item() == pytest.approx(0.8 * 0.1 + 0.2 * (1 - s), rel=1e-5)


def test_blur_loss_zero_for_identical_images_and_unbatched_ok():
    img = torch.rand(12, 12, 3, generator=torch.Generator().manual_seed(0))
    assert blur_loss(img, img).item() == pytest.approx(0.0, abs=1e-5)


def test_blur_loss_gradients_finite():
    g = torch.Generator().manual_seed(1)
    pred = torch.rand(1, 12, 12, 3, generator=g, requires_grad=True)
    blur_loss(pred, torch.rand(1, 12, 12, 3, generator=g)).backward()
    assert torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0


def test_blur_loss_shape_mismatch_is_named_error():
    with pytest.raises(InputError, match="pred/target"):
        blur_loss(torch.zeros(1, 4, 4, 3), torch.zeros(1, 4, 4, 1))
