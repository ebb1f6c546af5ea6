"""CFA layouts and the bilinear demosaic of float event maps."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.losses.colour import (
    bilinear_demosaic,
    cfa_index,
    channel_weights_for,
    demosaic_event_maps,
)
from fusiongs.losses.event import select_channel

PATTERNS = ["RGGB", "BGGR", "GRBG", "GBRG"]


def test_rggb_layout_red_even_even_blue_odd_odd():
    idx = cfa_index("RGGB", 4, 4)
    assert idx[0, 0] == 0 and idx[0, 1] == 1 and idx[1, 0] == 1 and idx[1, 1] == 2
    assert idx[2, 2] == 0 and idx[3, 3] == 2


@pytest.mark.parametrize("pattern", PATTERNS)
def test_layout_spells_top_left_cell(pattern):
    idx = cfa_index(pattern, 2, 2).reshape(-1).tolist()
    assert "".join("RGB"[i] for i in idx) == pattern


def test_unknown_pattern_is_named_error():
    with pytest.raises(InputError, match="RGGB, BGGR"):
        cfa_index("RGBW", 4, 4)


@pytest.mark.parametrize("pattern", PATTERNS)
def test_constant_per_channel_mosaic_demosaics_to_constant(pattern):
    values = torch.tensor([0.7, -1.5, 2.0], dtype=torch.float64)
    mosaic = values[cfa_index(pattern, 7, 9)]
    out = bilinear_demosaic(mosaic, pattern)
    torch.testing.assert_close(out, values[:, None, None].expand(3, 7, 9))


@pytest.mark.parametrize("pattern", PATTERNS)
def test_linear_ramp_reproduced_in_interior(pattern):
    h, w = 8, 10
    yy, xx = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64),
                            indexing="ij")
    truth = torch.stack([0.3 * xx + 0.1 * yy, -0.2 * xx + 0.5 * yy + 1, xx - yy])  # [3, H, W]
    mosaic = truth.gather(0, cfa_index(pattern, h, w)[None]).squeeze(0)
    out = bilinear_demosaic(mosaic, pattern)
    torch.testing.assert_close(out[:, 1:-1, 1:-1], truth[:, 1:-1, 1:-1])
    # measured samples are kept everywhere
    torch.testing.assert_close(out.gather(0, cfa_index(pattern, h, w)[None])[0], mosaic)


def test_matches_opencv_bilinear_in_interior_for_rggb():
    rng = np.random.default_rng(0)
    raw = rng.integers(0, 255, (12, 14), dtype=np.uint8)
    ref = cv2.cvtColor(raw, cv2.COLOR_BayerRGGB2RGB).astype(np.float64)  # bilinear in OpenCV
    out = bilinear_demosaic(torch.from_numpy(raw.astype(np.float64)), "RGGB").permute(1, 2, 0).numpy()
    np.testing.assert_allclose(out[2:-2, 2:-2], ref[2:-2, 2:-2], atol=0.51)


def test_event_maps_batched_channels_last_and_differentiable():
    maps = torch.randn(4, 6, 8, dtype=torch.float64, requires_grad=True)
    out = demosaic_event_maps(maps, "GRBG")
    assert out.shape == (4, 6, 8, 3)
    torch.autograd.gradcheck(lambda m: demosaic_event_maps(m, "GRBG"), (maps[:1].detach().requires_grad_(),))
    out.sum().backward()
    assert torch.isfinite(maps.grad).all()


def test_mask_mode_pipeline_selects_own_channel_and_weights():
    h, w = 4, 6
    idx_map = cfa_index("RGGB", h, w)
    flat = torch.tensor([0, 1, w + 1])  # R, G, B pixels
    ch = idx_map.reshape(-1)[flat]
    vals = torch.tensor([[1.0, 2.0, 3.0]]).expand(3, 3)
    torch.testing.assert_close(select_channel(vals, ch), torch.tensor([[1.0], [2.0], [3.0]]))
    torch.testing.assert_close(channel_weights_for(ch), torch.tensor([[0.4], [0.2], [0.4]]))


@pytest.mark.parametrize("pattern", PATTERNS)
def test_parity_with_events_cfa_bilinear_demosaic(pattern):
    from fusiongs.events.cfa import demosaic

    maps = torch.randn(2, 7, 9, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(demosaic_event_maps(maps, pattern), demosaic(maps, pattern, "bilinear"))
