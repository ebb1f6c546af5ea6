"""The frame colour anchor: per-channel gain and offset in linear light, fitted to a captured frame."""

from types import SimpleNamespace

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.response import linear_to_response, linear_to_srgb
from fusiongs.outputs.colour_anchor import (
    FRAME_ANCHOR,
    ColourAnchor,
    anchor_run,
    apply_anchor,
    fit_frame_anchor,
    fit_gain_offset,
)

GAIN, OFFSET = np.array([1.6, 0.7, 0.9]), np.array([0.02, -0.05, 0.1])


def _render(rng, shape=(1, 12, 16, 3)):
    return 0.1 + 0.5 * rng.random(shape)


@pytest.mark.parametrize("response", ["srgb", "linear", "gamma:2.2"])
def test_fit_recovers_gain_and_offset_through_the_response(rng, response):
    render = _render(rng)
    frame = linear_to_response(render * GAIN + OFFSET, response)
    a = fit_frame_anchor(render, frame, response, (0.299, 0.587, 0.114), ["000000"])
    assert a.kind == FRAME_ANCHOR and a.frames == ("000000",) and a.pixels == 12 * 16
    np.testing.assert_allclose(a.gain, GAIN, atol=1e-6)
    np.testing.assert_allclose(a.offset, OFFSET, atol=1e-6)


def test_clipped_frame_pixels_are_left_out(rng):
    render = _render(rng)
    lin = render * GAIN + OFFSET
    lin[0, :3] = 1.0  # three saturated rows: what the render predicts there is unknown
    lin[0, -1, :4, 1] = 0.0  # and four pixels clipped at black in one channel
    a = fit_frame_anchor(render, linear_to_srgb(lin), "srgb", (0.299, 0.587, 0.114))
    assert a.pixels == 12 * 16 - 3 * 16 - 4
    np.testing.assert_allclose(a.gain, GAIN, atol=1e-6)


def test_a_monochrome_frame_fixes_one_gain_for_all_channels(rng):
    w = (0.299, 0.587, 0.114)
    render = _render(rng)
    grey = (render * np.asarray(w)).sum(-1, keepdims=True)
    a = fit_frame_anchor(render, linear_to_srgb(1.3 * grey + 0.05), "srgb", w)
    np.testing.assert_allclose(a.gain, [1.3] * 3, atol=1e-6)
    np.testing.assert_allclose(a.offset, [0.05] * 3, atol=1e-6)


def test_applying_the_anchor_gives_the_frame_colours(rng):
    render = _render(rng)
    frame = linear_to_srgb(render * GAIN + OFFSET)
    a = fit_frame_anchor(render, frame, "srgb", (0.299, 0.587, 0.114))
    np.testing.assert_allclose(apply_anchor(a, linear_to_srgb(render[0])), frame[0], atol=1e-5)
    unchanged = linear_to_srgb(render[0]).astype(np.float32)
    np.testing.assert_array_equal(apply_anchor(ColourAnchor(), unchanged), unchanged)


def test_bad_shapes_and_too_few_pixels_are_named(rng):
    render = _render(rng)
    with pytest.raises(InputError, match="frames"):
        fit_frame_anchor(render, render[:, :6], "srgb", (0.299, 0.587, 0.114))
    with pytest.raises(InputError, match="unclipped frame pixels"):
        fit_frame_anchor(render, np.ones_like(render), "srgb", (0.299, 0.587, 0.114))
    with pytest.raises(InputError, match="shapes"):
        fit_gain_offset(render, render[..., :1], np.ones(render.shape[:-1], bool))


def test_anchor_is_recorded_for_metrics_json():
    none = ColourAnchor().as_dict()
    assert none["anchor"] == "none" and "affine fit only" in none["label"] and "gain" not in none
    frame = ColourAnchor(FRAME_ANCHOR, (1.0, 2.0, 3.0), (0.0, 0.1, 0.2), ("000000",), 10).as_dict()
    assert frame["anchor"] == "frame" and frame["gain"] == [1.0, 2.0, 3.0] and frame["space"] == "linear"


class _StubState:
    """Renders one fixed linear image at every instant (what :func:`anchor_run` needs of a state)."""

    def __init__(self, img):
        import torch

        self.img = torch.as_tensor(img, dtype=torch.float32)
        self.model = SimpleNamespace(means=torch.zeros(1, 3))

    def render(self, camera, t, backend):
        return self.img.expand(len(t), *self.img.shape), None, None


def _frames(images):
    n = len(images)
    return FrameSet(np.asarray(images, np.float32), np.arange(n) * 0.1, np.arange(n) * 0.1 + 0.05,
                    tuple(f"{i:06d}" for i in range(n)), "srgb")


def _cfg():
    return SimpleNamespace(blur=SimpleNamespace(n_samples=3), backend="torch",
                           events=SimpleNamespace(grey_weights=(0.299, 0.587, 0.114)))


def test_anchor_run_uses_a_single_frame_only(rng):
    render = _render(rng)[0]
    frame = linear_to_srgb(render * GAIN + OFFSET)
    one = SimpleNamespace(frames=_frames([frame]), camera=None)
    a = anchor_run(_StubState(render), one, _cfg())
    assert a.kind == FRAME_ANCHOR
    np.testing.assert_allclose(a.gain, GAIN, atol=1e-5)
    two = SimpleNamespace(frames=_frames([frame, frame]), camera=None)  # the blur loss anchors these
    assert not anchor_run(_StubState(render), two, _cfg()).applied
    none = SimpleNamespace(frames=FrameSet.empty(12, 16, 3, "srgb"), camera=None)
    assert not anchor_run(_StubState(render), none, _cfg()).applied


def test_a_saturated_frame_gives_no_anchor_and_says_so(rng, capsys):
    render = _render(rng)[0]
    scene = SimpleNamespace(frames=_frames([np.ones_like(render)]), camera=None)
    assert not anchor_run(_StubState(render), scene, _cfg()).applied
    assert "no colour anchor" in capsys.readouterr().err
