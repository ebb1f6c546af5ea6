"""Image and raw file reading/writing."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.frames.image_io import read_image, read_raw, read_raw_mosaic, write_png
from tests.conftest import real_file


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("channels", [1, 3])
def test_png_round_trip_keeps_values_and_channel_order(tmp_path, bits, channels):
    top = 2 ** bits - 1
    img = np.random.default_rng(0).integers(0, top + 1, (5, 7, channels)) / top
    write_png(tmp_path / "a.png", img, bits=bits)
    got = read_image(tmp_path / "a.png")
    assert got.dtype == np.float32 and got.shape == (5, 7, channels)
    np.testing.assert_allclose(got, img, atol=1e-7)
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]  # no temporary file left


def test_read_image_is_rgb_ordered(tmp_path):
    import cv2

    bgr = np.zeros((2, 2, 3), np.uint8)
    bgr[..., 2] = 255  # red in OpenCV's BGR order
    cv2.imwrite(str(tmp_path / "r.png"), bgr)
    np.testing.assert_array_equal(read_image(tmp_path / "r.png")[0, 0], [1, 0, 0])


def test_jpeg_reads(tmp_path):
    import cv2

    cv2.imwrite(str(tmp_path / "g.jpg"), np.full((8, 8, 3), 128, np.uint8))
    assert abs(float(read_image(tmp_path / "g.jpg").mean()) - 128 / 255) < 0.01


def test_read_image_errors_name_the_file(tmp_path):
    import cv2

    with pytest.raises(InputError, match="missing.png"):
        read_image(tmp_path / "missing.png")
    (tmp_path / "junk.png").write_bytes(b"not an image")
    with pytest.raises(InputError, match="junk.png"):
        read_image(tmp_path / "junk.png")
    cv2.imwrite(str(tmp_path / "alpha.png"), np.zeros((2, 2, 4), np.uint8))
    with pytest.raises(InputError, match="channels"):
        read_image(tmp_path / "alpha.png")


def test_write_png_rejects_bad_bits(tmp_path):
    with pytest.raises(InputError, match="bits"):
        write_png(tmp_path / "a.png", np.zeros((2, 2, 3)), bits=12)


def test_kodak_raw_mosaic_pattern_is_grbg():
    path = real_file("kodak_dc50_bayer.kdc")
    mos, pattern = read_raw_mosaic(path)
    assert pattern == "GRBG"  # README: G R / B G
    assert mos.shape == (512, 768) and mos.dtype == np.float32
    assert 0.0 <= mos.min() and mos.max() <= 1.0
    m2, p2 = read_raw(path, demosaic=None)
    assert p2 == "GRBG" and np.array_equal(m2, mos)


def test_kodak_raw_demosaics_to_linear_rgb():
    import rawpy

    path = real_file("kodak_dc50_bayer.kdc")
    rgb = read_raw(path, demosaic="opencv-bilinear")
    assert rgb.shape == (512, 768, 3) and rgb.dtype == np.float32
    with rawpy.imread(str(path)) as r:
        raw = r.raw_image_visible.astype(np.float64) / r.white_level
    # the green channel at G sites keeps the raw samples (normalised)
    np.testing.assert_allclose(rgb[10, 10, 1], raw[10, 10], atol=2e-5)  # G site: even row, even col
    np.testing.assert_allclose(rgb[10, 11, 0], raw[10, 11], atol=2e-5)  # R site: even row, odd col
    k = read_raw(path, demosaic="kornia")
    assert np.abs(k - rgb)[2:-2, 2:-2].mean() < 1e-3


def test_raw_errors_name_the_file(tmp_path):
    (tmp_path / "x.dng").write_bytes(b"junk")
    with pytest.raises(InputError, match="x.dng"):
        read_raw(tmp_path / "x.dng")


def test_uint8_arrays_are_written_as_they_are(tmp_path):
    """A uint8 image is encoded without the float detour (the report of an HD run doubled the
    process's peak memory there) and reads back equal to the float form of the same values."""
    from fusiongs.frames.image_io import read_image, write_png

    rng = np.random.default_rng(0)
    u8 = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    write_png(tmp_path / "u8.png", u8)
    write_png(tmp_path / "f.png", u8.astype(np.float32) / 255.0)
    assert (tmp_path / "u8.png").read_bytes() == (tmp_path / "f.png").read_bytes()
    back = read_image(tmp_path / "u8.png")
    np.testing.assert_array_equal(np.rint(np.asarray(back) * 255).astype(np.uint8), u8)


def test_report_strips_shrink_wide_images_only():
    from fusiongs.eval.report import picture_strip

    small, wide = np.zeros((130, 173, 3)), np.zeros((720, 1280, 3))
    assert picture_strip({"a": small, "b": small}).shape == (146, 2 * 177, 3)
    assert picture_strip({"a": wide}).shape == (16 + 270, 484, 3)
