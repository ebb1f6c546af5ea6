"""fusiongs.viz: event frames, CFA pictures, figure helpers and the missing-matplotlib error."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from fusiongs import viz
from fusiongs.errors import InputError, MissingDependencyError
from fusiongs.events.cfa import cfa_channel_index
from fusiongs.events.stream import EventStream


def _stream(t, x, y, p, w=4, h=3, cfa=None) -> EventStream:
    return EventStream.create(np.asarray(t, np.int64), np.asarray(x), np.asarray(y), np.asarray(p), w, h, cfa)


@pytest.fixture
def plt():
    mpl = pytest.importorskip("matplotlib")
    mpl.use("Agg")
    import matplotlib.pyplot as plt

    yield plt
    plt.close("all")


def test_event_frame_colours_on_red_off_blue_and_empty_white():
    ev = _stream([0, 1, 2, 3, 4], [0, 0, 1, 2, 3], [0, 0, 1, 2, 0], [1, 1, -1, 1, -1])
    img = viz.event_frame(ev, clip=2)
    assert img.shape == (3, 4, 3) and img.dtype == np.uint8
    assert tuple(img[0, 0]) == viz.ON_RGB  # two ON events = clip: fully saturated red
    assert tuple(img[1, 1]) == tuple(np.rint(127.5 + np.array(viz.OFF_RGB) / 2).astype(int))  # half blue
    assert tuple(img[2, 1]) == (255, 255, 255)
    assert img[2, 2, 0] > img[2, 2, 2]  # one ON event: reddish


def test_event_frame_uses_only_the_half_open_window():
    ev = _stream([0, 10, 20], [0, 1, 2], [0, 0, 0], [1, 1, 1])
    img = viz.event_frame(ev, 10, 20, clip=1)
    assert tuple(img[0, 1]) == viz.ON_RGB
    assert tuple(img[0, 0]) == (255, 255, 255) and tuple(img[0, 2]) == (255, 255, 255)


def test_event_frame_mask_greys_other_pixels_and_checks_its_shape():
    ev = _stream([0, 1], [0, 1], [0, 0], [1, -1])
    mask = np.zeros((3, 4), bool)
    mask[0, 0] = True
    img = viz.event_frame(ev, mask=mask, clip=1)
    assert tuple(img[0, 0]) == viz.ON_RGB
    assert tuple(img[0, 1]) == (225, 225, 225)  # an OFF event, but outside the mask
    with pytest.raises(InputError, match="mask"):
        viz.event_frame(ev, mask=np.ones((4, 3), bool))


def test_cfa_mask_image_colours_follow_the_channel_index():
    img = viz.cfa_mask_image("GRBG", 5, 7)
    idx = cfa_channel_index("GRBG", 5, 7)
    assert img.shape == (5, 7, 3)
    dominant = img.argmax(axis=2)
    np.testing.assert_array_equal(dominant, idx)


def test_to_rgb8_converts_grey_float_and_uint16():
    assert viz.to_rgb8(np.full((2, 2), 0.5, np.float32))[0, 0].tolist() == [128, 128, 128]
    assert viz.to_rgb8(np.full((2, 2, 1), 65535, np.uint16))[0, 0].tolist() == [255, 255, 255]
    assert viz.to_rgb8(np.array([[[2.0, -1.0, np.nan]]]))[0, 0].tolist() == [255, 0, 0]
    with pytest.raises(InputError, match="img"):
        viz.to_rgb8(np.zeros((2, 2, 2)))


def test_strip_makes_one_axis_per_image_with_titles(plt):
    fig = viz.strip([np.zeros((4, 6)), np.ones((4, 4, 3), np.uint8)], ["a", "b"])
    assert [ax.get_title() for ax in fig.axes] == ["a", "b"]
    with pytest.raises(InputError, match="titles"):
        viz.strip([np.zeros((4, 6))], ["a", "b"])


def test_hpf_traces_follow_each_pixels_events(plt):
    # pixel (1, 0): two ON events; pixel (3, 2): one OFF event; another pixel's events are ignored.
    ev = _stream([100, 200, 300, 400], [1, 1, 3, 0], [0, 0, 2, 0], [1, 1, -1, 1])
    fig = viz.hpf_traces(ev, [(1, 0), (3, 2)], 0, 1000, tau=1e6, contrast=0.5, n_samples=11)
    lines = [ln for ln in fig.axes[0].get_lines() if ln.get_linestyle() == "-"]
    assert len(lines) == 2
    np.testing.assert_allclose(lines[0].get_ydata()[-1], 1.0, atol=1e-5)  # 2 x 0.5, no decay
    np.testing.assert_allclose(lines[1].get_ydata()[-1], -0.5, atol=1e-5)
    with pytest.raises(InputError, match="pixels"):
        viz.hpf_traces(ev, [(4, 0)], 0, 1000)
    with pytest.raises(InputError, match="pixels"):
        viz.hpf_traces(ev, [(1, 0), (1, 0)], 0, 1000)


def test_event_rate_and_line_plot_return_figures(plt):
    ev = _stream(np.arange(0, 100_000, 1000), np.zeros(100, int), np.zeros(100, int),
                 np.where(np.arange(100) % 3, 1, -1))
    fig = viz.event_rate(ev, bin_s=0.01, exposures=([0.01], [0.02]))
    assert fig.axes[0].get_xlabel() == "time (s)"
    fig = viz.line_plot({"a": ([0, 1], [1, 2])}, title="t")
    assert fig.axes[0].get_title() == "t"


def test_plots_name_the_notebooks_extra_when_matplotlib_is_missing(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    with pytest.raises(MissingDependencyError, match=r"fusiongs\[notebooks\]"):
        viz.strip([np.zeros((2, 2))])
    assert viz.event_frame(_stream([0], [0], [0], [1])).shape == (3, 4, 3)  # numpy-only helpers work
