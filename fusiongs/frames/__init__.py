"""Frames: the frame set container, image and raw file IO, response curves."""

from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.image_io import read_image, read_raw, read_raw_mosaic, write_png
from fusiongs.frames.response import (
    linear_to_response,
    linear_to_srgb,
    parse_response,
    response_to_linear,
    srgb_to_linear,
)

__all__ = [
    "FrameSet", "linear_to_response", "linear_to_srgb", "parse_response", "read_image", "read_raw",
    "read_raw_mosaic", "response_to_linear", "srgb_to_linear", "write_png",
]
