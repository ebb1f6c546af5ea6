"""A finished ``fusiongs deblur`` run as ``fusiongs view`` shows it: the folder checked, its frames
placed in time, and the images shown for a frame or an instant.

The frames come from ``OUT/frames.json`` (written by ``fusiongs deblur``). A run written before that
file existed is placed from the scene's own ``scene.json`` when ``--scene`` names it (the frames'
exposure windows, the same names as ``OUT/deblurred/``; the held-out ones from ``OUT/heldout.json``);
without it the viewer shows the Gaussians and the path, and says what is missing.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusiongs.errors import InputError, is_finite_number
from fusiongs.outputs.write import FRAMES_FILE, PLY_FILE

CHECKPOINT_FILE = "checkpoint.pt"
CHUNKS_FILE = "chunks.json"
HELDOUT_FILE = "heldout.json"  # written with --holdout: the held-out frames' scores
FINISHED = "a finished `fusiongs deblur` run folder (with checkpoint.pt and model.ply)"


@dataclass(frozen=True)
class ViewFrame:
    """One frame of a run.

    Attributes:
        name: its name (``OUT/deblurred/<name>.png``).
        index: its position in the scene's ``frames`` (``scene.json``).
        t_start, t_end, t_mid: its exposure window and mid-exposure (s, the run's clock).
        trained: whether the run was trained on it (False: held out with ``--holdout``).
    """

    name: str
    index: int
    t_start: float
    t_end: float
    t_mid: float
    trained: bool = True


@dataclass(frozen=True)
class RunFrames:
    """Where a run's frames and render instants lie in time, and where its scene is.

    Attributes:
        frames: the frames in order (empty for an event-only run, or when unknown).
        renders: ``(name, t)`` of the scene's render instants (``OUT/renders/<name>.png``).
        scene: the scene folder holding the blurry frames, or None when unknown or missing.
        notes: what could not be found, one sentence each (shown in the viewer).
    """

    frames: tuple[ViewFrame, ...] = ()
    renders: tuple[tuple[str, float], ...] = ()
    scene: Path | None = None
    notes: tuple[str, ...] = ()


def check_run_folder(run: Path) -> None:
    """Raise unless ``run`` is a finished run folder.

    Raises:
        InputError: naming the folder and the first missing file (a chunked run's top folder is
            named as such: each chunk has a run folder of its own).
    """
    if not run.is_dir():
        raise InputError(run, "run folder", FINISHED, "no such folder")
    if (run / CHUNKS_FILE).is_file() and not (run / CHECKPOINT_FILE).is_file():
        raise InputError(run, CHECKPOINT_FILE, "one run folder: a chunked run has one per chunk, "
                         "view OUT/chunks/NNN/run", "chunks.json without checkpoint.pt")
    for name in (CHECKPOINT_FILE, PLY_FILE):
        if not (run / name).is_file():
            raise InputError(run, name, FINISHED, f"no {name}")


def _number(doc: dict, key: str, path: Path, where: str) -> float:
    v = doc.get(key)
    if not is_finite_number(v):
        raise InputError(path, f"{where}.{key}", "a finite number of seconds", repr(v))
    return float(v)


def _name(doc: dict, path: Path, where: str) -> str:
    v = doc.get("name")
    if not isinstance(v, str) or not v:
        raise InputError(path, f"{where}.name", "a non-empty string", repr(v))
    return v


def read_frames_file(path: Path) -> tuple[tuple[ViewFrame, ...], tuple[tuple[str, float], ...], str | None]:
    """``(frames, renders, scene)`` of a ``frames.json``.

    Raises:
        InputError: naming the file and the key when it is not the JSON ``fusiongs deblur`` writes.
    """
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise InputError(path, "(file)", "the JSON object fusiongs deblur writes", str(e)) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("frames"), list) \
            or not isinstance(doc.get("renders", []), list):
        raise InputError(path, "frames", "a JSON object with a list 'frames' (and 'renders')",
                         type(doc).__name__)
    frames = []
    for i, f in enumerate(doc["frames"]):
        where = f"frames[{i}]"
        if not isinstance(f, dict):
            raise InputError(path, where, "a JSON object", type(f).__name__)
        frames.append(ViewFrame(_name(f, path, where), i, _number(f, "t_start", path, where),
                                _number(f, "t_end", path, where), _number(f, "t_mid", path, where),
                                bool(f.get("trained", True))))
    renders = []
    for i, r in enumerate(doc.get("renders", [])):
        if not isinstance(r, dict):
            raise InputError(path, f"renders[{i}]", "a JSON object", type(r).__name__)
        renders.append((_name(r, path, f"renders[{i}]"), _number(r, "t", path, f"renders[{i}]")))
    scene = doc.get("scene")
    return tuple(frames), tuple(renders), scene if isinstance(scene, str) and scene else None


def scene_frames(scene: Path) -> tuple[tuple[ViewFrame, ...], tuple[tuple[str, float], ...]]:
    """The frames and render instants of the scene folder ``scene`` (its ``scene.json`` only).

    Raises:
        InputError: a missing or bad ``scene.json``.
    """
    from fusiongs.io.scene_io import frame_names, read_scene_spec

    spec = read_scene_spec(scene)
    frames = tuple(ViewFrame(n, i, f.t_start, f.t_end, 0.5 * (f.t_start + f.t_end))
                   for i, (n, f) in enumerate(zip(frame_names(spec), spec.frames)))
    return frames, tuple((r.name, float(r.t)) for r in spec.renders)


def deblurred_names(run: Path) -> list[str]:
    """The stems of ``run/deblurred/*.png``, sorted."""
    return sorted(p.stem for p in (run / "deblurred").glob("*.png"))


def held_out_names(run: Path) -> set[str]:
    """The frames a run held out (``--holdout``): the keys of ``frames`` in ``run/heldout.json``;
    none without the file (or when it is not that JSON)."""
    try:
        doc = json.loads((run / HELDOUT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return set()
    frames = doc.get("frames") if isinstance(doc, dict) else None
    return set(frames) if isinstance(frames, dict) else set()


def run_frames(run: Path, scene: Path | None = None) -> RunFrames:
    """Where the frames of the finished run ``run`` lie (see the module docstring).

    Args:
        run: the run folder.
        scene: the scene folder (``--scene``): where the blurry frames are, and, for a run without
            ``frames.json``, where their exposure windows are read from.

    Raises:
        InputError: a bad ``frames.json``; ``scene`` not a scene folder, or (without
            ``frames.json``) one whose frames are not the run's (``OUT/deblurred/`` names).
    """
    notes: list[str] = []
    written = deblurred_names(run)
    if (run / FRAMES_FILE).is_file():
        frames, renders, recorded = read_frames_file(run / FRAMES_FILE)
        if scene is None and recorded is not None:
            scene = Path(recorded)
            if not scene.is_dir():
                notes.append(f"the scene folder {scene} (frames.json) is not there: no blurry frames "
                             "(pass --scene SCENE)")
                scene = None
        elif scene is not None:
            scene_frames(scene)  # a bad --scene is said now, not on the first click
    elif scene is not None:
        frames, renders = scene_frames(scene)
        held = held_out_names(run)
        frames = tuple(dataclasses.replace(f, trained=f.name not in held) for f in frames)
        names = [f.name for f in frames]
        if written and sorted(names) != written:
            raise InputError(scene, "frames", f"the frames of the run {run} (deblurred/: "
                             f"{len(written)} images, {written[0]}...)", f"{len(names)} frames")
        notes.append(f"{run} has no frames.json (written before it existed): frames placed from "
                     f"{scene}/scene.json")
    else:
        frames, renders = (), ()
        if written:
            notes.append(f"{run} has no frames.json (written before it existed): pass --scene SCENE "
                         f"to place its {len(written)} frames; the Gaussians and the path are shown")
    if frames and scene is None and not notes:
        notes.append("the scene folder is not known: no blurry frames (pass --scene SCENE)")
    return RunFrames(tuple(frames), tuple(renders), scene, tuple(notes))


def to_uint8(img: np.ndarray) -> np.ndarray:
    """``[H, W, 3]`` (or ``[H, W, 1]``, ``[H, W]``) values in [0, 1] as RGB uint8."""
    a = np.asarray(img, dtype=np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[-1] == 1:
        a = np.repeat(a, 3, axis=-1)
    return np.round(np.clip(a, 0.0, 1.0) * 255.0).astype(np.uint8)


def blurry_image(scene: Path, frame: ViewFrame) -> np.ndarray:
    """The captured frame as sRGB uint8 ``[H, W, 3]`` (decoded by the scene's ``frame_response``).

    Raises:
        InputError: a bad ``scene.json`` or a missing or unreadable frame file.
    """
    from fusiongs.frames.response import linear_to_srgb, response_to_linear
    from fusiongs.io.scene_io import read_frame, read_scene_spec

    response = read_scene_spec(scene).frame_response
    img = read_frame(scene, frame.index)
    return to_uint8(linear_to_srgb(np.clip(response_to_linear(img, response), 0.0, 1.0)))


def run_image(path: Path) -> np.ndarray | None:
    """An image the run wrote (``deblurred/<name>.png``, ``renders/<name>.png``) as uint8, or None
    when it is not there."""
    from fusiongs.frames.image_io import read_image

    return to_uint8(read_image(path)) if path.is_file() else None


def side_by_side(left: np.ndarray | None, right: np.ndarray | None, gap: int = 4) -> np.ndarray | None:
    """``left | right`` (uint8 ``[H, W, 3]`` each) with a white ``gap`` (px) between; a missing
    side is a grey field of the other's size; None when both are missing."""
    if left is None and right is None:
        return None
    ref = left if left is not None else right
    fill = np.full_like(ref, 96)
    a, b = (left if left is not None else fill), (right if right is not None else fill)
    h = max(a.shape[0], b.shape[0])
    pad = [np.pad(x, ((0, h - x.shape[0]), (0, 0), (0, 0))) for x in (a, b)]
    return np.concatenate([pad[0], np.full((h, gap, 3), 255, np.uint8), pad[1]], axis=1)


@dataclass(frozen=True)
class LoadedRun:
    """A finished run loaded for the viewer.

    Attributes:
        root: the run folder.
        state: its :class:`fusiongs.train.state.FusionState` (``checkpoint.pt``, on the CPU).
        camera: its pinhole camera.
        backend: the rasteriser backend of its config.
        gain: the linear gain of its renders (``exposure.json``; 1 when frames fixed the level).
        anchor: its colour anchor (``colour_anchor.json``; none applied without it).
        ply: ``model.ply`` read as stored (display colours, ``load_ply(..., colours="display")``).
        frames: :class:`RunFrames`.
        t_open: the instant the page opens at (s): the first frame's mid-exposure, else the path's
            start.
    """

    root: Path
    state: object
    camera: object
    backend: str
    gain: float
    anchor: object
    ply: object
    frames: RunFrames
    t_open: float

    @property
    def t_range(self) -> tuple[float, float]:
        """``(t_min, t_max)`` (s) of the fitted path."""
        return self.state.trajectory.t_min, self.state.trajectory.t_max

    def c2w(self, times) -> np.ndarray:
        """``[T, 4, 4]`` float64 camera-to-world poses on the fitted path at ``times`` (s; clamped
        to the path)."""
        t = np.clip(np.asarray(times, dtype=np.float64).reshape(-1), *self.t_range)
        return self.state.trajectory.as_pose_samples(t).c2w

    def sharp_view(self, t: float, max_width: int = 640) -> np.ndarray:
        """fusiongs' own render at instant ``t`` (s) of the fitted path, as ``fusiongs render``
        writes it (the exposure gain and colour anchor applied), at most ``max_width`` px wide:
        uint8 ``[H, W, 3]``."""
        from fusiongs.outputs.colour_anchor import apply_anchor
        from fusiongs.train.render_io import render_srgb

        cam = self.camera
        if cam.width > max_width:
            cam = cam.scaled(max_width / cam.width)
        img = render_srgb(self.state, cam, [float(t)], self.backend, gain=self.gain)[0]
        return to_uint8(apply_anchor(self.anchor, img) if self.anchor.applied else img)


def load_run(run: Path, scene: Path | None = None) -> LoadedRun:
    """Check and load the finished run ``run`` (``scene``: ``--scene``, see :func:`run_frames`).

    Raises:
        InputError: not a finished run folder, a bad file in it, or a bad ``scene``.
    """
    from fusiongs.outputs.colour_anchor import read_anchor
    from fusiongs.outputs.write import read_exposure
    from fusiongs.scene.ply import load_ply
    from fusiongs.train.restore import restore_state

    check_run_folder(run)
    frames = run_frames(run, scene)
    gain, anchor = read_exposure(run), read_anchor(run)
    ply = load_ply(run / PLY_FILE, colours="display")
    state, camera, cfg = restore_state(run / CHECKPOINT_FILE)
    t_min, t_max = state.trajectory.t_min, state.trajectory.t_max
    t_open = float(np.clip(frames.frames[0].t_mid, t_min, t_max)) if frames.frames else t_min
    return LoadedRun(run, state, camera, str(cfg.get("backend", "auto")), gain, anchor, ply, frames, t_open)
