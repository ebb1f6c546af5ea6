"""Read and write the native scene folder (docs/scene-format.md, version 1).

``load_scene`` validates ``scene.json`` (:mod:`fusiongs.io.scene_json`), then every file it names:
the event stream (``fusiongs.events.h5``), each frame (8/16-bit PNG/JPEG, or a raw file through
rawpy), and the trajectory (TUM). Every error is an :class:`~fusiongs.errors.InputError` naming the
file and the key path.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fusiongs.errors import InputError
from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.image_io import image_info, is_raw_path, read_image, read_raw, write_png
from fusiongs.frames.response import linear_to_response
from fusiongs.io.scene import Scene
from fusiongs.io.scene_json import FrameEntry, SceneSpec, parse_scene_dict, scene_spec_to_dict

SCENE_FILE = "scene.json"


def scene_json_path(path: str | Path) -> Path:
    """``path/scene.json`` for a folder, or ``path`` itself when it names a file."""
    path = Path(path)
    return path / SCENE_FILE if path.is_dir() else path


def read_scene_spec(path: str | Path) -> SceneSpec:
    """Read and validate ``scene.json`` only (no other file is opened)."""
    jp = scene_json_path(path)
    try:
        text = jp.read_text(encoding="utf-8")
    except OSError as e:
        raise InputError(jp, SCENE_FILE, "a readable scene.json (or a folder holding one)",
                         e.strerror) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(jp, f"line {e.lineno} column {e.colno}", "valid JSON", e.msg) from None
    return parse_scene_dict(doc, str(jp))


def _resolve(root: Path, rel: str) -> Path:
    p = Path(rel)
    return p if p.is_absolute() else root / p


def frame_names(spec: SceneSpec) -> tuple[str, ...]:
    """The names a scene's frames go by (``FrameSet.names``, the stems of the deblurred images):
    their files' stems, or ``<index>_<stem>`` for all when two stems are equal."""
    return _frame_names(spec.frames)


def _frame_names(entries: tuple[FrameEntry, ...]) -> tuple[str, ...]:
    stems = [Path(f.path).stem for f in entries]
    if len(set(stems)) == len(stems):
        return tuple(stems)
    return tuple(f"{i:06d}_{s}" for i, s in enumerate(stems))


def _frame_path(spec: SceneSpec, root: Path, where: str, i: int) -> Path:
    p = _resolve(root, spec.frames[i].path)
    if not p.is_file():
        raise InputError(where, f"frames[{i}].path", "an existing image file", str(p))
    return p


def _check_frame_shape(spec: SceneSpec, where: str, i: int, p: Path, width: int, height: int,
                       channels: int, first_channels: int | None) -> None:
    """One frame against the camera, ``frames[0]`` and the event sensor's CFA."""
    cam, key = spec.camera, f"frames[{i}].path"
    if (width, height) != (cam.width, cam.height):
        raise InputError(p, key, f"an image of the camera size {cam.width}x{cam.height} (scene.json "
                         "camera.width x camera.height)", f"{width}x{height}")
    if channels not in (1, 3):
        raise InputError(p, key, "1 (grey) or 3 (RGB) channels", f"{channels} channels (alpha?)")
    if first_channels is not None and channels != first_channels:
        raise InputError(p, key, f"{first_channels} channel(s) like frames[0]", f"{channels} channel(s)")
    if spec.cfa is not None and channels != 3:
        raise InputError(where, "events.cfa", f"RGB frames for the colour event sensor {spec.cfa!r} "
                         "(or null for a monochrome event sensor)",
                         f"single-channel {key} {spec.frames[i].path}")


def check_frame_files(spec: SceneSpec, root: str | Path, where: str) -> None:
    """The frame checks of :func:`load_scene` without decoding PNG pixels (``fusiongs inspect``):
    every frame exists, is a complete and undamaged PNG (chunk CRCs), has the camera size and
    ``frames[0]``'s channels, and is RGB when the events have a CFA.

    Raises:
        InputError: naming the frame file, its size and the expected one (or the channels).
    """
    first = None
    for i in range(len(spec.frames)):
        p = _frame_path(spec, Path(root), where, i)
        info = image_info(p)
        _check_frame_shape(spec, where, i, p, info.width, info.height, info.channels, first)
        first = info.channels if first is None else first


def check_events_meet_frames(t_first_us: int, t_last_us: int, spec: SceneSpec,
                             events_file: str | Path) -> None:
    """The event stream must overlap the frames' time range (events between frames are normal;
    a stream entirely before the first exposure or after the last one is a clock or unit mix-up).

    Raises:
        InputError: naming the event file and both time ranges in seconds.
    """
    if not spec.frames:
        return
    f0 = min(f.t_start for f in spec.frames)
    f1 = max(f.t_end for f in spec.frames)
    if t_last_us < round(f0 * 1e6) or t_first_us > round(f1 * 1e6):
        raise InputError(events_file, "events/t", "events overlapping the frames' exposures (events.h5 "
                         "times in µs and scene.json times in seconds, on one clock)",
                         f"events in [{t_first_us * 1e-6:.6f}, {t_last_us * 1e-6:.6f}] s, frames in "
                         f"[{f0:.6f}, {f1:.6f}] s")


def _read_frame(spec: SceneSpec, root: Path, where: str, i: int) -> tuple[Path, np.ndarray]:
    p = _frame_path(spec, root, where, i)
    if is_raw_path(p):
        # Raw frames are linear; they are stored encoded like the other frames.
        lin = np.clip(read_raw(p, demosaic="opencv-ea"), 0.0, 1.0)
        return p, np.asarray(linear_to_response(lin, spec.frame_response), dtype=np.float32)
    return p, read_image(p)


def read_frame(path: str | Path, i: int) -> np.ndarray:
    """Frame ``i`` of the scene folder ``path`` (or its ``scene.json``) alone, without the others or
    the events: ``[H, W, C]`` float32 in [0, 1] as stored (encoded by the scene's
    ``frame_response``).

    Raises:
        InputError: a bad ``scene.json``, an index out of range, or a missing or unreadable file.
    """
    jp = scene_json_path(path)
    spec = read_scene_spec(jp)
    if not 0 <= i < len(spec.frames):
        raise InputError(jp, "frames", f"a frame index in [0, {len(spec.frames)})", i)
    return _read_frame(spec, jp.parent, str(jp), i)[1]


def _load_frames(spec: SceneSpec, root: Path, where: str) -> FrameSet:
    cam = spec.camera
    if not spec.frames:
        return FrameSet.empty(cam.height, cam.width, 3, spec.frame_response)
    images = []
    for i in range(len(spec.frames)):
        p, img = _read_frame(spec, root, where, i)
        _check_frame_shape(spec, where, i, p, img.shape[1], img.shape[0], img.shape[2],
                           images[0].shape[2] if images else None)
        images.append(img)
    return FrameSet(np.stack(images), np.array([f.t_start for f in spec.frames]),
                    np.array([f.t_end for f in spec.frames]), _frame_names(spec.frames),
                    spec.frame_response)


def recording_span(path: str | Path) -> tuple[float, float]:
    """First and last instant (s) of a scene folder's recording, its events and its exposures, from
    ``scene.json`` and the event file's first and last timestamps alone (no image and no event
    array is loaded): what decides whether ``fusiongs deblur`` cuts it into time chunks.

    Raises:
        InputError: a bad ``scene.json``, a missing events file, or one with no events.
    """
    from fusiongs.events.h5 import time_range_h5

    jp = scene_json_path(path)
    spec = read_scene_spec(jp)
    ends = [v for f in spec.frames for v in (f.t_start, f.t_end)]
    if spec.events_path is not None:
        ep = _resolve(jp.parent, spec.events_path)
        if not ep.is_file():
            raise InputError(jp, "events.path", "an existing HDF5 event file", str(ep))
        ends += [v * 1e-6 for v in time_range_h5(ep)]
    if not ends:
        raise InputError(jp, "frames", "frames or events", "neither")
    return min(ends), max(ends)


def load_scene(path: str | Path, *, sort_events: bool = False, drop_invalid_events: bool = False,
               load_events: bool = True) -> Scene:
    """Load a scene folder.

    Args:
        path: the scene folder, or its ``scene.json``.
        sort_events: stably sort unsorted event timestamps instead of raising.
        drop_invalid_events: drop events outside the sensor instead of raising.
        load_events: ``False`` skips reading the event file (``Scene.events`` is then ``None``;
            the file must still exist).

    Returns:
        the :class:`Scene`, ``root`` set to the folder holding ``scene.json``.

    Raises:
        InputError: naming ``scene.json`` or the faulty frame / events / trajectory file and the
            key path (``frames[3].path``, ``events.path``, ``trajectory``, ...): besides the checks
            of :func:`~fusiongs.io.scene_json.parse_scene_dict`, a missing, truncated or corrupt
            file, a frame whose size is not the camera's, single-channel frames with a CFA, or an
            event stream that does not overlap the frames' time range (µs vs seconds mix-up).
    """
    jp = scene_json_path(path)
    spec = read_scene_spec(jp)
    root, where = jp.parent, str(jp)
    events = None
    if spec.events_path is not None:
        ep = _resolve(root, spec.events_path)
        if not ep.is_file():
            raise InputError(where, "events.path", "an existing HDF5 event file", str(ep))
        if load_events:
            from fusiongs.events.h5 import read_events_h5

            events = read_events_h5(ep, spec.camera.width, spec.camera.height, spec.cfa,
                                    sort=sort_events, drop_invalid=drop_invalid_events)
            check_events_meet_frames(int(events.t[0]), int(events.t[-1]), spec, ep)
    frames = _load_frames(spec, root, where)
    poses = None
    if spec.trajectory is not None:
        tp = _resolve(root, spec.trajectory)
        if not tp.is_file():
            raise InputError(where, "trajectory", "an existing TUM trajectory file", str(tp))
        from fusiongs.camera.tum import read_tum

        poses = read_tum(tp)
    return Scene(spec.camera, events, frames, poses, spec.renders, root)


def save_scene(scene: Scene, path: str | Path, *, images_bits: int = 8) -> Path:
    """Write ``scene`` as a scene folder: ``scene.json``, ``events.h5``, ``frames/<name>.png``,
    ``trajectory.txt`` (each written atomically).

    Frames are written as stored (``FrameSet.images`` already encoded by its response), rounded
    to ``images_bits`` (8 or 16). The event CFA is taken from ``scene.events.cfa``.

    Returns:
        the path of the written ``scene.json``.

    Raises:
        InputError: duplicate frame names, a frame or event size that differs from the camera.
    """
    from fusiongs.atomic import write_text

    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    cam, fs = scene.camera, scene.frames
    if scene.events is None and len(fs) == 0:
        raise InputError("save_scene", "events/frames", "an event stream or at least one frame", "neither")
    if len(set(fs.names)) != len(fs.names):
        raise InputError("save_scene", "frames.names", "unique frame names", list(fs.names))
    if len(fs) and fs.images.shape[1:3] != (cam.height, cam.width):
        raise InputError("save_scene", "frames.images", f"images of the camera size {cam.width}x"
                         f"{cam.height}", f"{fs.images.shape[2]}x{fs.images.shape[1]}")
    entries = []
    for i, name in enumerate(fs.names):
        rel = f"frames/{name}.png"
        write_png(root / rel, fs.images[i], bits=images_bits)
        entries.append(FrameEntry(rel, float(fs.t_start[i]), float(fs.t_end[i])))
    events_path, cfa = None, None
    if scene.events is not None:
        ev = scene.events
        if (ev.width, ev.height) != (cam.width, cam.height):
            raise InputError("save_scene", "events", f"a {cam.width}x{cam.height} sensor",
                             f"{ev.width}x{ev.height}")
        from fusiongs.events.h5 import write_events_h5

        events_path, cfa = "events.h5", ev.cfa
        write_events_h5(ev, root / events_path)
    traj = None
    if scene.poses is not None:
        from fusiongs.camera.tum import write_tum

        traj = "trajectory.txt"
        write_tum(root / traj, scene.poses)
    spec = SceneSpec(cam, events_path, cfa, tuple(entries), fs.response, traj, tuple(scene.renders))
    jp = root / SCENE_FILE
    write_text(jp, json.dumps(scene_spec_to_dict(spec), indent=2) + "\n")
    return jp
