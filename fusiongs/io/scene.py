"""The native scene folder (docs/scene-format.md, version 1): the ``Scene`` container."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from fusiongs.camera.pinhole import SceneCamera
from fusiongs.camera.tum import PoseSamples
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet


@dataclass(frozen=True)
class RenderRequest:
    """A named instant to render after optimisation (``renders`` in scene.json); ``t`` in seconds."""

    name: str
    t: float


@dataclass(frozen=True, eq=False)
class Scene:
    """Everything read from one scene folder.

    Attributes:
        camera: shared pinhole camera of frames and events: a
            :class:`~fusiongs.camera.pinhole.PinholeCamera`, or an
            :class:`~fusiongs.camera.pinhole.UncalibratedCamera` (size only; ``intrinsics_known``
            is ``False``) when ``scene.json`` has no ``fx, fy, cx, cy`` ("estimate them").
        events: the event stream, or ``None`` when the scene has none.
        frames: the (possibly blurry) frames with exposure windows; may be empty.
        poses: camera-to-world poses from ``trajectory.txt``, or ``None`` ("estimate poses").
        renders: named instants to render.
        root: the scene folder it was read from, if any.
    """

    camera: SceneCamera
    events: EventStream | None
    frames: FrameSet
    poses: PoseSamples | None = None
    renders: tuple[RenderRequest, ...] = field(default_factory=tuple)
    root: Path | None = None
