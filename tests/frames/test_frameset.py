"""FrameSet validation and helpers."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.response import srgb_to_linear


def _fs(t0=(0.0, 0.1), t1=(0.05, 0.2), response="srgb", c=3):
    img = np.random.default_rng(0).random((2, 4, 5, c)).astype(np.float32)
    return FrameSet(img, np.array(t0), np.array(t1), ("f0", "f1"), response)


def test_mid_times_and_exposures():
    fs = _fs()
    np.testing.assert_allclose(fs.mid_times(), [0.025, 0.15])
    np.testing.assert_allclose(fs.exposures(), [0.05, 0.1])


@pytest.mark.parametrize("response", ["srgb", "linear", "gamma:2.2"])
def test_to_linear_decodes_with_the_response(response):
    fs = _fs(response=response)
    lin = fs.to_linear()
    ref = {"srgb": srgb_to_linear(fs.images), "linear": fs.images,
           "gamma:2.2": fs.images.astype(np.float64) ** 2.2}[response]
    np.testing.assert_allclose(lin, ref, rtol=1e-5)
    assert lin.dtype == np.float32


def test_exposure_window_must_be_positive_and_names_the_frame():
    with pytest.raises(InputError, match=r"frames\[1\].t_end.*'f1'"):
        _fs(t1=(0.05, 0.1))


def test_inconsistent_containers_raise():
    with pytest.raises(InputError, match="t_start"):
        FrameSet(np.zeros((2, 4, 5, 3), np.float32), np.zeros(3), np.ones(2), ("a", "b"))
    with pytest.raises(InputError, match="names"):
        FrameSet(np.zeros((2, 4, 5, 3), np.float32), np.zeros(2), np.ones(2), ("a",))
    with pytest.raises(InputError, match="images"):
        FrameSet(np.zeros((2, 4, 5, 2), np.float32), np.zeros(2), np.ones(2), ("a", "b"))
    with pytest.raises(InputError, match="response"):
        _fs(response="rec709")


def test_empty_frameset_is_valid():
    fs = FrameSet.empty(4, 5)
    assert len(fs) == 0 and fs.to_linear().shape == (0, 4, 5, 3)
