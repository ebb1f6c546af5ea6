"""scene.json parsing: round trip (hypothesis) and one error test per failure, each naming the key."""

from __future__ import annotations

import copy
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError
from fusiongs.io.scene import RenderRequest
from fusiongs.io.scene_json import FrameEntry, SceneSpec, parse_scene_dict, scene_spec_to_dict

finite = st.floats(-1e6, 1e6, allow_nan=False)
positive = st.floats(1e-3, 1e5, allow_nan=False)
names = st.text("abcdefghijklmnopqrstuvwxyz0123456789_-", min_size=1, max_size=8)


@st.composite
def specs(draw):
    frames = []
    t = draw(st.floats(0, 100, allow_nan=False))
    for _ in range(draw(st.integers(0, 4))):  # in time order, exposures touching or apart
        t0 = t + draw(st.sampled_from([0.0, 0.5]))
        t = t0 + draw(st.floats(1e-4, 1.0))
        frames.append(FrameEntry(f"frames/{draw(names)}.png", t0, t))
    has_events = draw(st.booleans()) or not frames
    cfa = draw(st.sampled_from([None, "RGGB", "BGGR", "GRBG", "GBRG"])) if has_events else None
    size = st.integers(1, 4096)
    cam = PinholeCamera(draw(size), draw(size), draw(positive), draw(positive), draw(finite), draw(finite),
                        draw(st.none() | st.just((0.0,) * 5)))
    render_names = draw(st.lists(names, unique=True, max_size=4))
    renders = tuple(RenderRequest(n, draw(finite)) for n in render_names)
    return SceneSpec(cam, "events.h5" if has_events else None, cfa,
                     tuple(frames), draw(st.sampled_from(["srgb", "linear", "gamma:2.2"])),
                     draw(st.none() | st.just("trajectory.txt")), renders)


@settings(max_examples=60, deadline=None)
@given(specs())
def test_scene_json_round_trip(spec):
    text = json.dumps(scene_spec_to_dict(spec))
    assert parse_scene_dict(json.loads(text)) == spec


GOOD = {
    "format": "fusiongs-scene", "version": 1,
    "camera": {"width": 346, "height": 260, "fx": 300.0, "fy": 300, "cx": 173.0, "cy": 130.0},
    "events": {"path": "events.h5", "cfa": "RGGB"},
    "frames": [{"path": "frames/000000.png", "t_start": 0.01, "t_end": 0.07},
               {"path": "frames/000001.png", "t_start": 0.08, "t_end": 0.12}],
    "trajectory": "trajectory.txt",
    "renders": [{"name": "deblur_000000", "t": 0.04}, {"name": "novel_000", "t": 0.512}],
    "an_unknown_key": {"is": "ignored"},
}


def test_format_example_parses_and_unknown_keys_are_ignored():
    spec = parse_scene_dict(GOOD)
    assert spec.camera.width == 346 and spec.cfa == "RGGB" and spec.frame_response == "srgb"
    assert spec.frames[1] == FrameEntry("frames/000001.png", 0.08, 0.12)
    assert spec.renders[1] == RenderRequest("novel_000", 0.512)


def _set(path, value):
    doc = copy.deepcopy(GOOD)
    *head, last = path
    d = doc
    for k in head:
        d = d[k]
    if value is _DEL:
        del d[last]
    else:
        d[last] = value
    return doc


_DEL = object()

CASES = [
    (("format",), "fusiongs", "format"),
    (("format",), _DEL, "format"),
    (("version",), 2, "version"),
    (("version",), True, "version"),
    (("version",), "1", "version"),
    (("camera",), _DEL, "camera"),
    (("camera",), [1, 2], "camera"),
    (("camera", "width"), 0, "camera.width"),
    (("camera", "height"), 2.5, "camera.height"),
    (("camera", "fx"), "300", "camera.fx"),
    (("camera", "fy"), -1.0, "camera.fy"),
    (("camera", "cx"), _DEL, "camera.cx"),
    (("camera", "cy"), None, "camera.cy"),
    (("camera", "distortion"), [0.1, 0.2], "camera.distortion"),
    (("events",), "events.h5", "events"),
    (("events", "path"), _DEL, "events.path"),
    (("events", "path"), 3, "events.path"),
    (("events", "cfa"), "RGBG", "events.cfa"),
    (("frames",), {"path": "a.png"}, "frames"),
    (("frames", 1), "a.png", r"frames\[1\]"),
    (("frames", 1, "path"), _DEL, r"frames\[1\].path"),
    (("frames", 1, "t_start"), "0.1", r"frames\[1\].t_start"),
    (("frames", 0, "t_end"), _DEL, r"frames\[0\].t_end"),
    (("frames", 1, "t_end"), 0.08, r"frames\[1\].t_end"),
    (("frames", 1, "t_end"), float("nan"), r"frames\[1\].t_end"),
    (("frames", 1, "t_start"), 0.05, r"frames\[1\].t_start: expected exposures that do not overlap"),
    (("frames", 1, "t_start"), 0.0, r"frames\[1\].t_start: expected frames listed in time order"),
    (("frame_response",), "log", "frame_response"),
    (("frame_response",), "gamma:0", "frame_response"),
    (("trajectory",), 5, "trajectory"),
    (("renders",), {"name": "a"}, "renders"),
    (("renders", 1, "name"), "deblur_000000", r"renders\[1\].name"),
    (("renders", 0, "name"), "../x", r"renders\[0\].name"),
    (("renders", 0, "name"), "", r"renders\[0\].name"),
    (("renders", 1, "t"), _DEL, r"renders\[1\].t"),
    (("renders", 1, "t"), [0.5], r"renders\[1\].t"),
]


@pytest.mark.parametrize("path,value,key", CASES)
def test_each_bad_key_raises_naming_file_and_key(path, value, key):
    with pytest.raises(InputError, match=rf"^my/scene.json: {key}"):
        parse_scene_dict(_set(path, value), "my/scene.json")


@pytest.mark.parametrize("dist", [[0.1, 0, 0, 0, 0], [0, 0, 0, 0, -1e-6], [0, 0, 1e-3, 0, 0]])
def test_nonzero_distortion_is_refused_with_a_hint_to_undistort(dist):
    with pytest.raises(InputError, match=r"^my/scene.json: camera.distortion: .*not supported yet, "
                       r"undistort the frames and events first") as e:
        parse_scene_dict(_set(("camera", "distortion"), dist), "my/scene.json")
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("dist", [[0, 0, 0, 0, 0], [0.0, -0.0, 0.0, 0.0, 0.0], None])
def test_zero_or_absent_distortion_is_accepted(dist):
    spec = parse_scene_dict(_set(("camera", "distortion"), dist))
    assert spec.camera.distortion in (None, (0.0,) * 5)


def test_scene_without_events_or_frames_is_rejected():
    doc = _set(("events",), _DEL)
    doc["frames"] = []
    with pytest.raises(InputError, match="events/frames"):
        parse_scene_dict(doc)


def test_top_level_must_be_an_object():
    with pytest.raises(InputError, match="top level"):
        parse_scene_dict([GOOD])
