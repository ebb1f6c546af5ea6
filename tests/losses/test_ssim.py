"""The training loss's SSIM against kornia's (the reference): maps and gradients."""

from __future__ import annotations

import pytest
import torch
from kornia.metrics import ssim as kornia_ssim

from fusiongs.losses.ssim import ssim_map


@pytest.mark.parametrize("shape, window, dtype", [((2, 3, 40, 52), 11, torch.float32),
                                                   ((1, 1, 17, 23), 11, torch.float64),
                                                   ((3, 3, 30, 30), 7, torch.float64)])
def test_ssim_map_matches_kornia_with_its_gradients(shape, window, dtype):
    g = torch.Generator().manual_seed(sum(shape) + window)
    x = torch.rand(shape, generator=g, dtype=dtype)
    y = (x + 0.2 * torch.randn(shape, generator=g, dtype=dtype)).clamp(0, 1)  # correlated, not equal
    ours_x, ref_x = x.clone().requires_grad_(True), x.clone().requires_grad_(True)
    ours = ssim_map(ours_x, y, window_size=window)
    ref = kornia_ssim(ref_x, y, window_size=window, max_val=1.0, padding="same")
    tol = dict(rtol=1e-4, atol=1e-5) if dtype == torch.float32 else dict(rtol=1e-9, atol=1e-11)
    torch.testing.assert_close(ours, ref, **tol)
    w = torch.rand(shape, generator=g, dtype=dtype)  # a weighted sum: every pixel's gradient
    (ours * w).sum().backward()
    (ref * w).sum().backward()
    torch.testing.assert_close(ours_x.grad, ref_x.grad, **tol)


def test_identical_images_score_one_and_opposites_score_low():
    x = torch.rand(1, 3, 24, 24, generator=torch.Generator().manual_seed(0))
    assert torch.allclose(ssim_map(x, x), torch.ones_like(x), atol=1e-5)
    assert ssim_map(x, 1 - x).mean() < 0
