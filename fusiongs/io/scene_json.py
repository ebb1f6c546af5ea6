"""``scene.json`` of the native scene folder (docs/scene-format.md, version 1): parse and validate, and dump.

Parsing checks every key it knows and ignores unknown ones; each error is an
:class:`~fusiongs.errors.InputError` naming the file and the key path (``frames[3].t_end``).
Files named by the document are not touched here (see :mod:`fusiongs.io.scene_io`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fusiongs.camera.pinhole import PinholeCamera, SceneCamera, UncalibratedCamera
from fusiongs.errors import InputError, is_finite_number
from fusiongs.events.stream import CFA_PATTERNS
from fusiongs.frames.response import parse_response
from fusiongs.io.scene import RenderRequest

SCENE_FORMAT = "fusiongs-scene"
SCENE_VERSION = 1


@dataclass(frozen=True)
class FrameEntry:
    """One ``frames[i]`` entry: image path (relative to the scene folder) and exposure in seconds."""

    path: str
    t_start: float
    t_end: float


@dataclass(frozen=True)
class SceneSpec:
    """The validated content of a ``scene.json`` (paths as written, relative to the scene folder)."""

    camera: SceneCamera
    events_path: str | None = None
    cfa: str | None = None
    frames: tuple[FrameEntry, ...] = ()
    frame_response: str = "srgb"
    trajectory: str | None = None
    renders: tuple[RenderRequest, ...] = field(default_factory=tuple)


def _number(d: dict, key: str, where: str, path: str) -> float:
    if key not in d:
        raise InputError(where, f"{path}{key}", "a finite number (required key missing)")
    v = d[key]
    if not is_finite_number(v):
        raise InputError(where, f"{path}{key}", "a finite number", repr(v))
    return float(v)


def _obj(v: object, where: str, key: str) -> dict:
    if not isinstance(v, dict):
        raise InputError(where, key, "a JSON object", type(v).__name__)
    return v


def _str(v: object, where: str, key: str) -> str:
    if not isinstance(v, str) or not v:
        raise InputError(where, key, "a non-empty string", repr(v))
    return v


def _intrinsics(c: dict, where: str) -> dict[str, float] | None:
    """``fx, fy, cx, cy`` of ``camera``, or ``None`` when all four are absent ("estimate them")."""
    keys = ("fx", "fy", "cx", "cy")
    missing = [k for k in keys if k not in c]
    if len(missing) == len(keys):
        return None
    if missing:
        raise InputError(where, ", ".join(f"camera.{k}" for k in missing),
                         "all four of camera.fx, fy, cx, cy, or none of them (then the intrinsics "
                         "are estimated from the frames)",
                         f"only {', '.join(k for k in keys if k not in missing)}")
    vals = {k: _number(c, k, where, "camera.") for k in keys}
    for k in ("fx", "fy"):
        if vals[k] <= 0:
            raise InputError(where, f"camera.{k}", "a positive focal length in pixels", vals[k])
    return vals


def _camera(d: dict, where: str) -> SceneCamera:
    if "camera" not in d:
        raise InputError(where, "camera", "a camera object (required key missing)")
    c = _obj(d["camera"], where, "camera")
    size = {}
    for k in ("width", "height"):
        v = c.get(k)
        if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
            raise InputError(where, f"camera.{k}", "a positive integer", repr(v))
        size[k] = v
    vals = _intrinsics(c, where)
    dist = c.get("distortion")
    if dist is not None:
        if not isinstance(dist, list) or len(dist) != 5 or not all(is_finite_number(v) for v in dist):
            raise InputError(where, "camera.distortion", "5 finite numbers [k1, k2, p1, p2, k3]",
                             repr(dist))
        dist = tuple(float(v) for v in dist)
        if any(v != 0.0 for v in dist):
            raise InputError(where, "camera.distortion", "no lens distortion (absent or all zero): "
                             "distortion coefficients are not supported yet, undistort the frames and "
                             "events first (OpenCV undistort / undistortPoints) and remove the key",
                             repr(list(dist)))
    if vals is None:
        return UncalibratedCamera(size["width"], size["height"], dist)
    return PinholeCamera(size["width"], size["height"], vals["fx"], vals["fy"], vals["cx"],
                         vals["cy"], dist)


def _check_frame_order(frames: list[FrameEntry], where: str) -> None:
    """Frames in time order with exposures that do not overlap (one camera exposes one frame at a
    time); compared in whole µs, the events' clock, so windows that touch are fine."""
    def us(t: float) -> int:
        return round(t * 1e6)

    for i in range(1, len(frames)):
        a, b = frames[i - 1], frames[i]
        if us(b.t_start) < us(a.t_start):
            raise InputError(where, f"frames[{i}].t_start", "frames listed in time order (sorted by t_start)",
                             f"frames[{i}] ({b.path}) starts at {b.t_start} s, before frames[{i - 1}] "
                             f"({a.path}) at {a.t_start} s")
        if us(b.t_start) < us(a.t_end):
            raise InputError(where, f"frames[{i}].t_start", "exposures that do not overlap (each frame "
                             "starts at or after the previous one ends)",
                             f"frames[{i}] ({b.path}) starts at {b.t_start} s, before frames[{i - 1}] "
                             f"({a.path}) ends at {a.t_end} s")


def parse_scene_dict(doc: object, where: str = "scene.json") -> SceneSpec:
    """Validate a decoded ``scene.json`` document.

    Args:
        doc: the decoded JSON value.
        where: the file name used in error messages.

    Raises:
        InputError: on a wrong ``format``/``version``, a missing required key (``format``,
            ``version``, ``camera``, some but not all of the camera's ``fx, fy, cx, cy`` (all four
            absent give an :class:`~fusiongs.camera.pinhole.UncalibratedCamera`), ``events.path``,
            ``frames[i].path``, ``t_start``, ``t_end``, ``renders[i].name``/``t``), a wrong type,
            ``t_end <= t_start``, frames out of time order or with overlapping exposures, an unknown
            CFA or response, duplicate render names, or a
            non-zero lens distortion (not supported yet: frames and events must be undistorted
            first).
    """
    d = _obj(doc, where, "(top level)")
    if d.get("format") != SCENE_FORMAT:
        raise InputError(where, "format", f'"{SCENE_FORMAT}"', repr(d.get("format")))
    v = d.get("version")
    if isinstance(v, bool) or not isinstance(v, int) or v != SCENE_VERSION:
        raise InputError(where, "version", f"{SCENE_VERSION} (the only version this reader knows)",
                         repr(v))
    camera = _camera(d, where)
    events_path, cfa = None, None
    if d.get("events") is not None:
        e = _obj(d["events"], where, "events")
        events_path = _str(e.get("path"), where, "events.path")
        cfa = e.get("cfa")
        if cfa is not None and cfa not in CFA_PATTERNS:
            raise InputError(where, "events.cfa", f"null or one of {', '.join(CFA_PATTERNS)}", repr(cfa))
    frames_raw = d.get("frames", [])
    if frames_raw is None:
        frames_raw = []
    if not isinstance(frames_raw, list):
        raise InputError(where, "frames", "a list of frame objects", type(frames_raw).__name__)
    frames = []
    for i, fr in enumerate(frames_raw):
        key = f"frames[{i}]"
        fr = _obj(fr, where, key)
        p = _str(fr.get("path"), where, f"{key}.path")
        t0 = _number(fr, "t_start", where, f"{key}.")
        t1 = _number(fr, "t_end", where, f"{key}.")
        if not t1 > t0:
            raise InputError(where, f"{key}.t_end", "t_end > t_start (seconds)",
                             f"t_end {t1} <= t_start {t0} for {p}")
        frames.append(FrameEntry(p, t0, t1))
    _check_frame_order(frames, where)
    response = d.get("frame_response", "srgb")
    if response is None:
        response = "srgb"
    parse_response(response, where, "frame_response")
    traj = d.get("trajectory")
    if traj is not None:
        traj = _str(traj, where, "trajectory")
    renders_raw = d.get("renders")
    if renders_raw is None:
        renders_raw = []
    if not isinstance(renders_raw, list):
        raise InputError(where, "renders", "a list of {name, t} objects", type(renders_raw).__name__)
    renders, seen = [], set()
    for i, r in enumerate(renders_raw):
        key = f"renders[{i}]"
        r = _obj(r, where, key)
        name = _str(r.get("name"), where, f"{key}.name")
        if "/" in name or "\\" in name or name in (".", ".."):
            raise InputError(where, f"{key}.name", "a file stem without path separators", repr(name))
        if name in seen:
            raise InputError(where, f"{key}.name", "a name not used by another render", repr(name))
        seen.add(name)
        renders.append(RenderRequest(name, _number(r, "t", where, f"{key}.")))
    if events_path is None and not frames:
        raise InputError(where, "events/frames", "an event stream or at least one frame", "neither")
    return SceneSpec(camera, events_path, cfa, tuple(frames), response, traj, tuple(renders))


def scene_spec_to_dict(spec: SceneSpec) -> dict:
    """The ``scene.json`` document of ``spec`` (inverse of :func:`parse_scene_dict`)."""
    c = spec.camera
    cam: dict = {"width": c.width, "height": c.height}
    if isinstance(c, PinholeCamera):
        cam.update(fx=c.fx, fy=c.fy, cx=c.cx, cy=c.cy)
    if c.distortion is not None:
        cam["distortion"] = list(c.distortion)
    doc: dict = {"format": SCENE_FORMAT, "version": SCENE_VERSION, "camera": cam}
    if spec.events_path is not None:
        doc["events"] = {"path": spec.events_path, "cfa": spec.cfa}
    doc["frames"] = [{"path": f.path, "t_start": f.t_start, "t_end": f.t_end} for f in spec.frames]
    doc["frame_response"] = spec.frame_response
    if spec.trajectory is not None:
        doc["trajectory"] = spec.trajectory
    doc["renders"] = [{"name": r.name, "t": r.t} for r in spec.renders]
    return doc
