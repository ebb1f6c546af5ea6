"""EDI and HPF intensity priors."""

from __future__ import annotations

import math

import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.losses.blur import apply_response
from fusiongs.losses.priors import (
    edi_prior_loss,
    intensity_prior_loss,
    smooth_log_gradient,
    total_variation_prior,
)


def test_edi_prior_is_l1_after_encoding():
    r = torch.full((2, 2, 3), 0.18)
    e = torch.full((2, 2, 3), 0.5)
    expected = (apply_response(torch.tensor(0.5)) - apply_response(torch.tensor(0.18))).item()
    assert edi_prior_loss(r, e).item() == pytest.approx(expected)
    assert edi_prior_loss(r, e, response="linear").item() == pytest.approx(0.32)


def test_edi_prior_valid_mask_ignores_pixels():
    r = torch.zeros(1, 2, 1)
    e = torch.tensor([[[0.5], [100.0]]])
    valid = torch.tensor([[[True], [False]]])
    assert edi_prior_loss(r, e, "linear", valid).item() == pytest.approx(0.5)


def test_intensity_prior_is_invariant_to_log_offset_per_channel():
    g = torch.Generator().manual_seed(0)
    render = torch.rand(5, 6, 3, generator=g) + 0.1
    hpf = torch.log(render + 1e-3) + torch.tensor([0.3, -2.0, 5.0])
    assert intensity_prior_loss(render, hpf).item() == pytest.approx(0.0, abs=1e-6)


def test_intensity_prior_hand_example_median_offset():
    render = torch.tensor([[[1.0], [1.0], [1.0]]]) - 1e-3  # log render = 0 everywhere
    hpf = torch.tensor([[[0.0], [1.0], [3.0]]])
    # median offset 1 -> |0+1-0| + |1-1| + |1-3| = 3 -> mean 1
    assert intensity_prior_loss(render, hpf).item() == pytest.approx(1.0, rel=1e-5)


def test_intensity_prior_gradient_finite_and_shape_check():
    render = torch.rand(2, 4, 4, 3, requires_grad=True)
    intensity_prior_loss(render, torch.randn(2, 4, 4, 3)).backward()
    assert torch.isfinite(render.grad).all()
    with pytest.raises(InputError, match="render/target"):
        intensity_prior_loss(render, torch.zeros(4, 4, 3))
    assert math.isfinite(edi_prior_loss(torch.zeros(2, 2, 3), torch.zeros(2, 2, 3)).item())


def _highpass_reference(resid: torch.Tensor, sigma: float) -> torch.Tensor:
    """``[H, W, C]`` residual minus its normalised Gaussian low-pass, pixel by pixel (float64):
    the weights of the image's pixels within ``ceil(3 sigma)`` (a square), divided by their sum."""
    h, w, _ = resid.shape
    r = math.ceil(3.0 * sigma)
    out = torch.empty_like(resid)
    for y in range(h):
        for x in range(w):
            ys, xs = range(max(0, y - r), min(h, y + r + 1)), range(max(0, x - r), min(w, x + r + 1))
            wts = torch.tensor([[math.exp(-((yy - y) ** 2 + (xx - x) ** 2) / (2 * sigma**2)) for xx in xs]
                                for yy in ys], dtype=resid.dtype)
            patch = resid[ys.start:ys.stop, xs.start:xs.stop]
            out[y, x] = resid[y, x] - (wts[..., None] * patch).sum((0, 1)) / wts.sum()
    return out


def test_intensity_prior_highpass_matches_pixel_by_pixel_reference():
    g = torch.Generator().manual_seed(3)
    render = (torch.rand(9, 11, 3, generator=g, dtype=torch.float64) + 0.1).requires_grad_(True)
    hpf = torch.randn(9, 11, 3, generator=g, dtype=torch.float64)
    loss = intensity_prior_loss(render, hpf, highpass=1.5)
    ref = _highpass_reference(hpf - torch.log(render + 1e-3), 1.5).abs().mean()
    assert loss.item() == pytest.approx(ref.item(), rel=1e-9)
    (grad,) = torch.autograd.grad(loss, render)
    (grad_ref,) = torch.autograd.grad(ref, render)
    assert torch.allclose(grad, grad_ref, rtol=1e-9, atol=1e-12)


def test_intensity_prior_highpass_ignores_offsets_and_large_scales_not_texture():
    g = torch.Generator().manual_seed(1)
    render = torch.rand(2, 40, 48, 3, generator=g) + 0.1
    log_r = torch.log(render + 1e-3)
    offset = torch.tensor([0.3, -2.0, 5.0])
    assert intensity_prior_loss(render, log_r + offset, highpass=4.0).item() == pytest.approx(0.0, abs=1e-5)
    yy, xx = torch.meshgrid(torch.arange(40.0), torch.arange(48.0), indexing="ij")
    smooth = (0.5 * torch.sin(xx / 15.0) * torch.cos(yy / 13.0))[..., None]  # scales >> 4 px
    whole = intensity_prior_loss(render, log_r + smooth)
    fine = intensity_prior_loss(render, log_r + smooth, highpass=4.0)
    assert fine < 0.2 * whole  # (what is left is mostly the border, where a slope is not kept)
    texture = 0.3 * torch.randn(2, 40, 48, 3, generator=g)  # pixel-scale differences are kept
    whole = intensity_prior_loss(render, log_r + texture)
    fine = intensity_prior_loss(render, log_r + texture, highpass=4.0)
    assert 0.8 * whole < fine < 1.2 * whole


def test_anchor_highpass_setting_is_checked_and_off_by_default():
    from fusiongs.errors import ConfigError
    from fusiongs.pipeline.deblur import resolve_config

    with pytest.raises(ConfigError, match=r"event_only.anchor_highpass: expected a finite number >= 0"):
        resolve_config("event_only", ["event_only.anchor_highpass=-1"])
    assert resolve_config("event_only", []).event_only.anchor_highpass == 0.0


def _tv_reference(f: torch.Tensor) -> torch.Tensor:
    """Pixel by pixel: per image and channel, the mean |horizontal| plus the mean |vertical|
    neighbour difference; then the mean over images and channels."""
    *lead, h, w, c = f.shape
    flat = f.reshape(-1, h, w, c)
    per = []
    for n in range(flat.shape[0]):
        for k in range(c):
            dx = [abs(float(flat[n, y, x + 1, k] - flat[n, y, x, k])) for y in range(h) for x in range(w - 1)]
            dy = [abs(float(flat[n, y + 1, x, k] - flat[n, y, x, k])) for y in range(h - 1) for x in range(w)]
            per.append(sum(dx) / len(dx) + sum(dy) / len(dy))
    return torch.tensor(sum(per) / len(per), dtype=torch.float64)


@pytest.mark.parametrize("space", ["log", "srgb"])
def test_total_variation_prior_matches_pixel_by_pixel_reference(space):
    g = torch.Generator().manual_seed(3)
    render = torch.rand(2, 5, 7, 3, generator=g, dtype=torch.float64) * 1.2  # some values above 1
    got = total_variation_prior(render, space, eps=1e-3)
    f = torch.log(render + 1e-3) if space == "log" else apply_response(render.clamp(0, 1), "srgb")
    assert float(got) == pytest.approx(float(_tv_reference(f)), rel=1e-12)


def test_total_variation_prior_zero_on_flat_images_and_gradient_finite():
    flat = torch.full((4, 6, 3), 0.3, dtype=torch.float64)
    assert float(total_variation_prior(flat, "log")) == 0.0
    assert float(total_variation_prior(flat, "srgb")) == 0.0
    step = flat.clone()
    step[:, 3:] = 0.6  # one vertical edge: log(0.6 + ε) − log(0.3 + ε) on 4 of the 4x5 horizontal pairs
    edge = math.log(0.601 / 0.301) * 4 / 20
    assert float(total_variation_prior(step, "log")) == pytest.approx(edge, rel=1e-12)
    x = step.clone().requires_grad_(True)
    total_variation_prior(x, "srgb").backward()
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0


def test_total_variation_prior_bad_input_and_setting():
    from fusiongs.errors import ConfigError
    from fusiongs.pipeline.deblur import resolve_config

    with pytest.raises(InputError, match="space"):
        total_variation_prior(torch.rand(4, 4, 3), "linear")
    with pytest.raises(InputError, match="render"):
        total_variation_prior(torch.rand(4, 4), "log")
    with pytest.raises(ConfigError, match=r"event_only.tv_weight: expected a finite number >= 0"):
        resolve_config("event_only", ["event_only.tv_weight=-1"])
    with pytest.raises(ConfigError, match=r"event_only.tv_space"):
        resolve_config("event_only", ["event_only.tv_space=lin"])
    for key in ("gradient_blur", "gradient_blur_weight"):
        with pytest.raises(ConfigError, match=rf"event_only.{key}: expected a finite number >= 0"):
            resolve_config("event_only", [f"event_only.{key}=-2"])


def test_smooth_log_gradient_matches_pixel_by_pixel_reference():
    g = torch.Generator().manual_seed(5)
    grad = torch.randn(2, 6, 8, 3, generator=g, dtype=torch.float64)
    render = torch.rand(2, 6, 8, 3, generator=g, dtype=torch.float64)
    sigma, weight, eps = 1.3, 0.7, 1e-3
    got = smooth_log_gradient(grad, render, sigma, weight, eps)
    r = math.ceil(3 * sigma)
    taps = [math.exp(-0.5 * (k / sigma) ** 2) for k in range(-r, r + 1)]
    norm = sum(taps)
    want = grad.clone()
    g_log = grad * (render + eps)
    for n in range(2):
        for y in range(6):
            for x in range(8):
                for c in range(3):
                    s = sum(taps[dy + r] * taps[dx + r] * float(g_log[n, y + dy, x + dx, c])
                            for dy in range(-r, r + 1) for dx in range(-r, r + 1)
                            if 0 <= y + dy < 6 and 0 <= x + dx < 8) / norm ** 2
                    want[n, y, x, c] += weight * s / (float(render[n, y, x, c]) + eps)
    torch.testing.assert_close(got, want, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(smooth_log_gradient(grad, render, sigma, 0.0, eps), grad)
    with pytest.raises(InputError, match="smooth_log_gradient"):
        smooth_log_gradient(grad[..., :2], render, sigma, weight, eps)


def test_smooth_log_gradient_spreads_an_edge_step_into_the_plain_area():
    # a gradient only along an edge column reaches the plain pixels beside it, in log units
    grad = torch.zeros(1, 9, 9, 1, dtype=torch.float64)
    grad[0, :, 4, 0] = 1.0
    render = torch.full_like(grad, 0.5)
    out = smooth_log_gradient(grad, render, 2.0, 1.0)
    assert float(out[0, 4, 0, 0]) > 0 and float(out[0, 4, 2, 0]) > float(out[0, 4, 0, 0])
    assert float(out[0, 4, 4, 0]) > 1.0
