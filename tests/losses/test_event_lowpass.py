"""The low-pass event term of long windows: what it sees, what it averages away, what it skips."""

import pytest
import torch

from fusiongs.losses.event_lowpass import event_loss_lowpass, full_support, lowpass_maps
from fusiongs.train.lowpass_term import cross_pairs

H, W = 40, 48


def _field(seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.randn(H, W, generator=g, dtype=torch.float64).cumsum(0).cumsum(1) * 0.01


def _bayer() -> torch.Tensor:
    return torch.tensor([[0, 1], [1, 2]]).repeat(H // 2, W // 2)


def test_lowpass_is_a_weighted_mean_of_the_valid_pixels_of_each_channel():
    vals = torch.arange(H * W, dtype=torch.float64).reshape(H, W)
    valid = torch.ones(H, W, dtype=torch.bool)
    valid[10, 10] = False
    low, den = lowpass_maps(vals, valid, _bayer(), 3, 1.5)
    # the slow reference at one place: the Gaussian-weighted mean over the valid pixels of channel 1
    y, x = 20, 21
    yy, xx = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    wts = torch.exp(-0.5 * ((yy - y) ** 2 + (xx - x) ** 2) / 1.5**2)
    wts = wts * ((_bayer() == 1) & valid) * ((yy - y).abs() <= 5) * ((xx - x).abs() <= 5)
    ref = float((wts * vals).sum() / wts.sum())
    assert abs(float(low[1, y, x]) - ref) < 1e-6 * ref
    assert float(den[1, y, x]) > 0
    assert float(den[0, 1, 1]) < float(den[0, 20, 20])  # less support at the border


def test_zero_mean_pixel_noise_is_averaged_away_an_offset_is_not():
    d = _field()
    valid = torch.ones(H, W, dtype=torch.bool)
    g = torch.Generator().manual_seed(1)
    noise = 0.3 * torch.randn(H, W, generator=g, dtype=torch.float64)  # per-pixel threshold mismatch
    assert float(event_loss_lowpass(d, d, valid, None, 1, 3.0, 0.2)) == 0.0
    per_pixel = float(noise.abs().mean() / 0.2)
    noisy = float(event_loss_lowpass(d, d + noise, valid, None, 1, 3.0, 0.2))
    assert noisy < 0.15 * per_pixel
    # half the image 0.2 log units (one threshold) off, far less per pixel than the noise: seen
    # in full away from the step (mean over the image ~ half of 1 count)
    shifted = d.clone()
    shifted[:, : W // 2] += 0.2
    seen = float(event_loss_lowpass(d, shifted, valid, None, 1, 3.0, 0.2))
    assert 0.4 < seen <= 0.5 and seen > 3 * noisy


def test_invalid_pixels_and_other_channels_do_not_leak():
    d = _field(2)
    ch = _bayer()
    valid = torch.ones(H, W, dtype=torch.bool)
    target = d.clone()
    target[10:14, 10:14] += 50.0  # hot or censored pixels: huge counts
    valid[10:14, 10:14] = False
    assert float(event_loss_lowpass(d, target, valid, ch, 3, 2.0, 0.2)) < 1e-9
    # an offset on the red pixels only is seen on the red channel and nowhere else
    target = d + 0.2 * (ch == 0)
    low_t, _ = lowpass_maps(target, valid, ch, 3, 2.0)
    low_d, _ = lowpass_maps(d, valid, ch, 3, 2.0)
    gap = (low_t - low_d).abs()
    assert torch.allclose(gap[0], torch.full_like(gap[0], 0.2), atol=1e-9)
    assert float(gap[1:].max()) < 1e-9


def test_gradient_reaches_the_render_of_valid_places_only():
    d = _field(3).requires_grad_(True)
    valid = torch.zeros(H, W, dtype=torch.bool)
    valid[:, : W // 2] = True
    loss = event_loss_lowpass(d, d.detach() + 0.05, valid, None, 1, 2.0, 0.2)
    loss.backward()
    assert float(d.grad[:, : W // 2].abs().sum()) > 0
    assert float(d.grad[:, W // 2 + 8:].abs().max()) == 0.0  # beyond the support's reach


def test_cross_pairs_join_ends_of_different_windows_in_time_order():
    ends = [(0, 0.10, 0), (1, 0.12, 0), (2, 0.60, 1), (3, 0.05, 1)]
    pairs = cross_pairs(ends, 0.2)
    assert sorted(pairs) == sorted([(0, 2, 0.10, 0.60), (1, 2, 0.12, 0.60)])
    assert cross_pairs(ends, 0.0) == [(0, 2, 0.10, 0.60), (3, 0, 0.05, 0.10), (1, 2, 0.12, 0.60),
                                      (3, 1, 0.05, 0.12)]


def _reference(d, t, valid, ch, channels, sigma, theta, min_support=0.2):
    """Window by window from :func:`lowpass_maps`, as the loss is defined."""
    out = []
    full = torch.ones(H, W, dtype=torch.bool)
    _, den_full = lowpass_maps(torch.zeros(H, W, dtype=d.dtype), full, ch, channels, sigma)
    for k in range(d.shape[0]):
        low_d, den = lowpass_maps(d[k], valid[k], ch, channels, sigma)
        low_t, _ = lowpass_maps(t[k], valid[k], ch, channels, sigma)
        w = den * (den >= min_support * den_full)
        out.append((w * (low_d - low_t).abs()).sum() / w.sum() / theta)
    return torch.stack(out).mean()


def test_batched_loss_matches_the_window_by_window_reference_with_gradients():
    g = torch.Generator().manual_seed(5)
    for ch, channels in ((None, 1), (_bayer(), 3)):
        d = torch.stack([_field(k) for k in range(3)]).requires_grad_(True)
        t = (d.detach() + 0.2 * torch.randn(3, H, W, generator=g, dtype=torch.float64)).requires_grad_(True)
        valid = torch.rand(3, H, W, generator=g) > 0.3
        fast = event_loss_lowpass(d, t, valid, ch, channels, 2.5, 0.2)
        slow = _reference(d, t, valid, ch, channels, 2.5, 0.2)
        assert torch.allclose(fast, slow, rtol=1e-9, atol=1e-12)
        gd_f, gt_f = torch.autograd.grad(fast, (d, t))
        gd_s, gt_s = torch.autograd.grad(slow, (d, t))
        assert torch.allclose(gd_f, gd_s, atol=1e-12) and torch.allclose(gt_f, gt_s, atol=1e-12)
        assert float(gd_f.abs().sum()) > 0


def test_a_kept_full_support_gives_the_same_loss_and_is_the_blur_of_a_fully_valid_sensor():
    g = torch.Generator().manual_seed(6)
    for ch, channels in ((None, 1), (_bayer(), 3)):
        d = torch.stack([_field(k) for k in range(2)])
        t = d + 0.2 * torch.randn(2, H, W, generator=g, dtype=torch.float64)
        valid = torch.rand(2, H, W, generator=g) > 0.3
        sup = full_support(ch, channels, 2.5, H, W, torch.device("cpu"), torch.float64)
        _, den = lowpass_maps(torch.zeros(H, W, dtype=torch.float64), torch.ones(H, W, dtype=torch.bool),
                              ch, channels, 2.5)
        assert torch.allclose(sup, den, atol=1e-12)
        assert torch.equal(event_loss_lowpass(d, t, valid, ch, channels, 2.5, 0.2, support=sup),
                           event_loss_lowpass(d, t, valid, ch, channels, 2.5, 0.2))


def test_bad_lowpass_settings_are_one_line_naming_the_key():
    from fusiongs.errors import ConfigError
    from fusiongs.pipeline.deblur import resolve_config

    with pytest.raises(ConfigError, match=r"events.lowpass_sigma: expected a finite number > 0"):
        resolve_config("event_only", ["events.lowpass_sigma=0"])
    with pytest.raises(ConfigError, match=r"events.lowpass_weight: expected a finite number >= 0"):
        resolve_config("event_only", ["events.lowpass_weight=-1"])
    assert resolve_config("event_only", []).events.lowpass_weight == 1.0
    assert resolve_config(None, []).events.lowpass_weight == 0.0


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("sigma", [1.0, 2.5, 4.0])
def test_blur_with_a_kept_kernel_is_kornias_gaussian_blur(dtype, sigma):
    import kornia

    from fusiongs.losses.event_lowpass import gaussian_blur

    maps = torch.rand(4, H, W, generator=torch.Generator().manual_seed(9), dtype=dtype).requires_grad_(True)
    k = 2 * max(1, int(torch.tensor(3.0 * sigma).ceil())) + 1
    ref = kornia.filters.gaussian_blur2d(maps[None], (k, k), (sigma, sigma), border_type="constant")[0]
    got = gaussian_blur(maps, sigma)
    assert torch.allclose(got, ref, rtol=0, atol=1e-12 if dtype == torch.float64 else 1e-6)
    w = torch.rand(4, H, W, generator=torch.Generator().manual_seed(10), dtype=dtype)
    (g_got,) = torch.autograd.grad((got * w).sum(), maps)
    (g_ref,) = torch.autograd.grad((ref * w).sum(), maps)
    assert torch.allclose(g_got, g_ref, rtol=0, atol=1e-12 if dtype == torch.float64 else 1e-6)
