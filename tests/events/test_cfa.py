"""Bayer CFA layout, mosaicing and demosaicing: the pattern-name mapping is checked empirically."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.errors import InputError
from fusiongs.events.cfa import cfa_channel_index, cfa_masks, demosaic, mosaic

PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
SWAPPED = {"RGGB": "BGGR", "BGGR": "RGGB", "GRBG": "GBRG", "GBRG": "GRBG"}  # R and B exchanged


@pytest.fixture(scope="module")
def astronaut() -> np.ndarray:
    import cv2
    from skimage import data

    img = cv2.resize(data.astronaut(), (96, 96), interpolation=cv2.INTER_AREA).astype(np.float32) / 255
    return cv2.GaussianBlur(img, (0, 0), 1.0)


def _psnr(a, b, border=2):
    d = (np.asarray(a, np.float64) - b)[border:-border, border:-border]
    return 10 * np.log10(1.0 / np.mean(d ** 2))


def test_rggb_layout_follows_the_format_convention():
    idx = cfa_channel_index("RGGB", 3, 5)
    np.testing.assert_array_equal(idx, [[0, 1, 0, 1, 0], [1, 2, 1, 2, 1], [0, 1, 0, 1, 0]])
    assert idx.dtype == np.int8
    np.testing.assert_array_equal(cfa_channel_index("GRBG", 2, 2), [[1, 0], [2, 1]])
    np.testing.assert_array_equal(cfa_channel_index("GBRG", 2, 2), [[1, 2], [0, 1]])
    np.testing.assert_array_equal(cfa_channel_index("BGGR", 2, 2), [[2, 1], [1, 0]])


def test_masks_partition_the_sensor():
    m = cfa_masks("GBRG", 4, 6)
    assert m.shape == (3, 4, 6) and m.dtype == bool
    np.testing.assert_array_equal(m.sum(0), 1)
    assert m[1].sum() == 12 and m[0].sum() == 6


def test_mosaic_takes_each_pixels_channel_numpy_and_torch():
    rgb = np.random.default_rng(0).random((4, 6, 3))
    for p in PATTERNS:
        idx = cfa_channel_index(p, 4, 6)
        m = mosaic(rgb, p)
        np.testing.assert_array_equal(m, np.take_along_axis(rgb, idx[..., None].astype(int), 2)[..., 0])
        np.testing.assert_array_equal(mosaic(torch.from_numpy(rgb), p).numpy(), m)


@pytest.mark.parametrize("method,min_db", [("bilinear", 30), ("opencv-bilinear", 30), ("opencv-ea", 30),
                                           ("opencv-vng", 30), ("kornia", 30)])
@pytest.mark.parametrize("pattern", PATTERNS)
def test_demosaic_name_mapping_is_right_and_a_wrong_one_fails(astronaut, pattern, method, min_db):
    raw = mosaic(astronaut, pattern)
    good = _psnr(demosaic(raw, pattern, method), astronaut)
    bad = _psnr(demosaic(raw, SWAPPED[pattern], method), astronaut)
    assert good > min_db  # measured about 34-37 dB at this size
    assert bad < good - 10  # R/B swapped: about 13 dB


def test_demosaic_uint16_passes_straight_to_opencv():
    raw16 = (np.random.default_rng(2).random((10, 12)) * 65535).astype(np.uint16)
    out = demosaic(raw16, "RGGB", "opencv-ea")
    assert out.dtype == np.float32 and out.shape == (10, 12, 3) and out.max() > 255


def test_float_bilinear_matches_opencv_bilinear_on_uint16_inside_the_border():
    import cv2

    raw16 = (np.random.default_rng(3).random((20, 30)) * 65535).astype(np.uint16)
    for p, name in (("RGGB", "BG"), ("GRBG", "GB"), ("BGGR", "RG"), ("GBRG", "GR")):
        ref = cv2.cvtColor(raw16, getattr(cv2, f"COLOR_Bayer{name}2RGB")).astype(np.float64)
        ours = demosaic(raw16.astype(np.float64), p, "bilinear")
        np.testing.assert_allclose(ours[1:-1, 1:-1], ref[1:-1, 1:-1], atol=0.5 + 1e-9)


def test_bilinear_handles_signed_float_maps_and_keeps_samples():
    counts = np.random.default_rng(4).integers(-5, 6, (2, 8, 10)).astype(np.float32)
    out = demosaic(counts, "RGGB", "bilinear")
    assert out.shape == (2, 8, 10, 3) and out.dtype == np.float32 and out.min() < 0
    idx = cfa_channel_index("RGGB", 8, 10)
    np.testing.assert_allclose(np.take_along_axis(out, np.broadcast_to(idx[..., None], (2, 8, 10, 1))
                                                  .astype(int), -1)[..., 0], counts)
    const = demosaic(np.full((5, 7), -2.0), "GBRG", "bilinear")
    np.testing.assert_allclose(const, -2.0)  # normalised convolution is exact at the border


def test_bilinear_torch_matches_numpy_and_is_differentiable():
    x = torch.randn(2, 6, 8, dtype=torch.float64, requires_grad=True)
    out = demosaic(x, "GRBG", "bilinear")
    np.testing.assert_allclose(out.detach().numpy(), demosaic(x.detach().numpy(), "GRBG"), atol=1e-12)
    assert torch.autograd.gradcheck(lambda t: demosaic(t, "GRBG", "bilinear"), (x[:1, :4, :4].detach()
                                                                                .requires_grad_(),))


def test_kornia_path_is_differentiable_and_handles_odd_sizes(astronaut):
    x = torch.from_numpy(mosaic(astronaut[:-1, :-1], "RGGB")).requires_grad_()
    out = demosaic(x, "RGGB", "kornia")
    assert out.shape == (95, 95, 3)
    out.sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all()
    assert _psnr(out.detach().numpy(), astronaut[:-1, :-1]) > 30


def test_opencv_float_path_rejects_negative_values_and_unknown_names():
    with pytest.raises(InputError, match="bilinear"):
        demosaic(np.full((4, 4), -1.0), "RGGB", "opencv-ea")
    with pytest.raises(InputError, match="cfa"):
        cfa_channel_index("RGBG", 4, 4)
    with pytest.raises(InputError, match="method"):
        demosaic(np.zeros((4, 4)), "RGGB", "nearest")
