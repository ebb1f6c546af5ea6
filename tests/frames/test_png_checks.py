"""PNG size and integrity from the file's chunks (no decoding): ``png_info`` and ``image_info``."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.frames.image_io import image_info, png_info, read_image, write_png


@pytest.fixture
def png(tmp_path):
    p = tmp_path / "f.png"
    write_png(p, np.random.default_rng(0).random((6, 10, 3)), bits=16)
    return p


@pytest.mark.parametrize("channels", [1, 3])
def test_png_info_reads_size_and_channels_from_the_header(tmp_path, channels):
    p = tmp_path / "g.png"
    write_png(p, np.zeros((7, 5, channels)))
    for info in (png_info(p), png_info(p, p.read_bytes()), image_info(p), image_info(p, verify=False)):
        assert (info.width, info.height, info.channels) == (5, 7, channels)


def test_truncation_is_found_by_the_cheap_check_too(png):
    data = png.read_bytes()
    png.write_bytes(data[:-20])
    for check in (lambda: png_info(png), lambda: image_info(png, verify=False), lambda: read_image(png)):
        with pytest.raises(InputError, match=r"f\.png: image: expected a complete PNG file \(truncated\?\)"):
            check()


def test_a_damaged_chunk_fails_its_crc_when_the_whole_file_is_read(png):
    b = bytearray(png.read_bytes())
    b[len(b) // 2] ^= 0x01
    png.write_bytes(bytes(b))
    assert png_info(png).width == 10  # header and trailer are intact: the cheap check passes
    for check in (lambda: png_info(png, png.read_bytes()), lambda: image_info(png), lambda: read_image(png)):
        with pytest.raises(InputError, match=r"f\.png: .*chunk IDAT at byte \d+ fails its CRC check"):
            check()


def test_bytes_after_iend_are_accepted_like_libpng_does(png):
    png.write_bytes(png.read_bytes() + b"trailing junk")
    assert png_info(png).height == 6
    assert read_image(png).shape == (6, 10, 3)


@pytest.mark.parametrize("data,words", [(b"", "empty file"), (b"\x89PN", "truncated"),
                                        (b"GIF89a" + b"\x00" * 40, "PNG or JPEG file OpenCV can decode")])
def test_short_empty_or_foreign_files_name_the_file(tmp_path, data, words):
    p = tmp_path / "x.png"
    p.write_bytes(data)
    with pytest.raises(InputError, match="x.png") as e:
        image_info(p)
    assert words in str(e.value)


def test_image_info_of_a_jpeg_decodes_it(tmp_path):
    import cv2

    cv2.imwrite(str(tmp_path / "g.jpg"), np.full((4, 9, 3), 128, np.uint8))
    info = image_info(tmp_path / "g.jpg")
    assert (info.width, info.height, info.channels) == (9, 4, 3)
