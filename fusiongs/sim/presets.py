"""Simulator scene presets: textured geometry (photographs on planes and boxes) and camera motion.

World axes are OpenCV's (x right, y down, z forward); the camera starts near the origin looking
along +z. Each preset differs in geometry, textures and motion:

- ``boxes``: a photo wall, a gravel floor, three textured boxes and a tilted panel at different
  depths; the camera orbits the middle of the scene (strong parallax).
- ``wall``: a brick wall with photo posters and one panel standing in front; a sideways pan with
  little rotation (nearly planar scene).
- ``corridor``: a corridor (textured walls, floor, ceiling, an end wall) with a box; the camera
  dollies forward while turning slightly (looming motion, depth from 1 to 12 m).
- ``gallery``: five photo panels at depths 2.5 to 7 m in front of a grass wall at 10 m, over a
  gravel floor; every texture is cropped so that it has about 1.5 texels per pixel at the default
  173-pixel width (fine, high-frequency detail everywhere); a sideways arc.
- ``dark``: a dimly lit room (walls and floor at a few percent of the bright radiance, most pixels
  below 0.03) with a few bright things: a lit poster, a bright box, a lamp, a star field; an arc.
- ``depth``: thin posts and a box 1.2 to 2 m away, boxes at 8 and 14 m, a far wall at 40 m and a
  floor between them; a sideways slide looking at the far wall (image speed falls with depth:
  strong parallax).

Two walks, whose view keeps changing (record them long: ``--duration 20 --frames 240``):

- ``hallway``: a 20 m corridor of five 4 m segments, each with its own wall, floor and ceiling
  textures, posters and boxes along it and an end wall; the camera walks 10 m down it in 20 s
  (0.5 m/s) with a walker's sway, so walls, floor and the end wall keep coming into view.
- ``walkway``: a 24 m wall of photo panels 3 m to the camera's side of a pavement, with posts in
  front of it; the camera walks 10 m along it in 20 s looking at it, so every few seconds the whole
  view is new.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fusiongs.errors import InputError
from fusiongs.sim.motion import Motion
from fusiongs.sim.raycast import Quad, World, box_quads, lambert_gain
from fusiongs.sim.textures import load_photo, solid_texture

LIGHT = (0.35, -0.8, -0.5)  # direction towards the light (from above, left, behind the camera)


@dataclass(frozen=True, eq=False)
class Preset:
    """A scene to simulate: ``world`` seen along ``motion`` with a ``hfov_deg`` lens."""

    world: World
    motion: Motion
    hfov_deg: float = 62.0


def _plane(origin, edge_u, edge_v, texture: int, intensity: float = 1.0, crop=(0.0, 0.0, 1.0, 1.0)) -> Quad:
    n = np.cross(edge_u, edge_v)
    return Quad(tuple(map(float, origin)), tuple(map(float, edge_u)), tuple(map(float, edge_v)),
                texture, crop, lambert_gain(n, LIGHT, intensity=intensity))


def _box(center, size, texture: int, intensity: float = 1.0) -> list[Quad]:
    normals = [(-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0), (0, 0, -1), (0, 0, 1)]
    gains = tuple(lambert_gain(n, LIGHT, intensity=intensity) for n in normals)
    return box_quads(center, size, texture, gains)


def boxes() -> Preset:
    """Sideways arc past three boxes and a tilted panel in front of a photo wall."""
    tex = (load_photo("astronaut"), load_photo("gravel", (0.85, 0.7, 0.5)), load_photo("coffee"),
           load_photo("chelsea"), load_photo("rocket"), load_photo("immunohistochemistry"))
    quads = [
        _plane((-13, -8.5, 9), (26, 0, 0), (0, 17, 0), 0),  # back wall (z = 9)
        _plane((-13, 1.5, -1), (26, 0, 0), (0, 0, 10), 1),  # floor (y = 1.5)
        *_box((-1.4, 0.85, 4.2), (1.1, 1.3, 1.1), 2),
        *_box((1.5, 0.6, 5.6), (1.2, 1.8, 1.2), 3),
        *_box((0.2, 1.15, 3.0), (0.7, 0.7, 0.7), 4),
        _plane((-1.0, -2.0, 7.0), (2.0, 0, 0.7), (0.2, 1.5, 0), 5),  # tilted panel
    ]
    motion = Motion(target=(0.0, 1.2, 20.0), radius=(20.0, 20.0), azimuth_deg=(-11.0, 11.0),
                    height=(-1.3, -1.1), bob=0.1, look_shift=(0.0, 1.0, 0.0),
                    shake_pos=0.004, shake_rot_deg=0.25)
    return Preset(World(tuple(quads), tex), motion, 62.0)


def wall() -> Preset:
    """Sideways pan in front of a brick wall with posters."""
    tex = (load_photo("brick", (0.9, 0.55, 0.4)), load_photo("astronaut"), load_photo("rocket"),
           load_photo("colorwheel"), load_photo("hubble_deep_field"), load_photo("chelsea"))
    quads = [
        _plane((-2.3, -1.7, 4.97), (2.0, 0, 0), (0, 2.0, 0), 1),  # posters just in front of the wall
        _plane((0.6, -1.5, 4.97), (2.4, 0, 0), (0, 1.6, 0), 2),
        _plane((-0.5, 0.6, 4.97), (1.2, 0, 0), (0, 1.2, 0), 3),
        _plane((1.0, 0.4, 4.97), (1.5, 0, 0), (0, 1.4, 0), 4),
        _plane((-8, -5, 5.0), (16, 0, 0), (0, 10, 0), 0),  # wall
        _plane((-1.6, -0.2, 3.2), (1.0, 0, -0.3), (0, 1.3, 0), 5),  # a panel standing in front
    ]
    motion = Motion(target=(0.0, 0.0, 60.0), radius=(60.0, 60.0), azimuth_deg=(-2.6, 2.6),
                    height=(0.05, -0.05), shake_pos=0.004, shake_rot_deg=0.3)
    return Preset(World(tuple(quads), tex), motion, 62.0)


def corridor() -> Preset:
    """Dolly forward down a corridor while turning a little."""
    names = ("brick", "coffee", "gravel", "grass", "hubble_deep_field", "chelsea", "immunohistochemistry",
             "rocket", "astronaut")
    tints = {"brick": (0.8, 0.75, 0.7), "gravel": (0.6, 0.6, 0.65), "grass": (0.9, 0.95, 0.8)}
    tex = tuple(load_photo(n, tints.get(n, (1.0, 1.0, 1.0))) for n in names)
    seg, n_seg = 4.5, 3  # corridor of three 4.5 m segments, 3 m wide, 2.7 m high
    quads = []
    for i in range(n_seg):
        z0, z1 = i * seg, (i + 1) * seg
        quads += [
            _plane((-1.5, -1.5, z0), (0, 0, seg), (0, 2.7, 0), 0),  # left wall (x = -1.5)
            _plane((1.5, -1.5, z1), (0, 0, -seg), (0, 2.7, 0), (1, 7, 5)[i]),  # right wall
            _plane((-1.5, 1.2, z0), (3.0, 0, 0), (0, 0, seg), 2),  # floor (y = 1.2)
            _plane((-1.5, -1.5, z1), (3.0, 0, 0), (0, 0, -seg), 3),  # ceiling (y = -1.5)
        ]
    quads += [
        _plane((-1.5, -1.5, seg * n_seg), (3.0, 0, 0), (0, 2.7, 0), 4),  # end wall
        _plane((-1.49, -0.9, 6.0), (0, 0, 1.8), (0, 1.2, 0), 8, 1.1),  # poster on the left wall
        *_box((0.6, 0.75, 7.5), (0.8, 0.9, 0.8), 6),
    ]
    motion = Motion(target=(0.0, 0.0, 40.0), radius=(39.8, 36.3), azimuth_deg=(0.0, 0.0),
                    height=(-0.1, 0.0), bob=0.05, look_shift=(18.0, -3.0, 0.0),
                    shake_pos=0.005, shake_rot_deg=0.35)
    return Preset(World(tuple(quads), tex), motion, 66.0)


def gallery() -> Preset:
    """Sideways arc past photo panels at several depths, every texture fine at the pixel scale."""
    tex = (load_photo("grass", (0.75, 0.9, 0.6)), load_photo("gravel", (0.8, 0.75, 0.7)),
           load_photo("hubble_deep_field"), load_photo("immunohistochemistry"),
           load_photo("page", (0.95, 0.9, 0.8)), load_photo("coins", (0.9, 0.85, 0.7)),
           load_photo("text", (0.8, 0.85, 0.95)))
    quads = [  # crops: about 1.5 texels per pixel at 173 pixels across (coins: 3)
        _plane((-12, -8, 10.0), (24, 0, 0), (0, 16, 0), 0, crop=(0.0, 0.0, 1.0, 0.68)),  # back wall
        _plane((-6, 1.5, 0.5), (12, 0, 0), (0, 0, 9.5), 1),  # floor (y = 1.5)
        _plane((-1.3, -0.9, 2.5), (1.4, 0, 0), (0, 1.0, 0), 2, crop=(0.30, 0.30, 0.54, 0.49)),
        _plane((0.4, -0.2, 3.5), (1.6, 0, 0), (0, 1.2, 0), 3, crop=(0.05, 0.05, 0.24, 0.195)),
        _plane((-2.8, 0.2, 5.0), (2.2, 0, 0), (0, 1.6, 0), 4, crop=(0.0, 0.30, 0.25, 0.66)),
        _plane((0.5, -2.6, 7.0), (3.0, 0, 0), (0, 2.2, 0), 5, crop=(0.0, 0.0, 0.5, 0.5)),
        _plane((-2.5, -1.7, 4.3), (1.4, 0, -0.5), (0, 1.1, 0), 6, crop=(0.30, 0.0, 0.47, 0.33)),
    ]
    motion = Motion(target=(0.0, 0.0, 12.0), radius=(12.0, 12.0), azimuth_deg=(-10.0, 10.0),
                    height=(-0.2, 0.0), bob=0.05, shake_pos=0.004, shake_rot_deg=0.3)
    return Preset(World(tuple(quads), tex), motion, 62.0)


def dark() -> Preset:
    """Arc through a dim room: large dark walls and floor, a few bright objects."""
    tex = (load_photo("brick", (0.9, 0.7, 0.55)), load_photo("gravel"), load_photo("camera"),
           load_photo("astronaut"), load_photo("coffee"), load_photo("hubble_deep_field"),
           solid_texture((1.0, 0.9, 0.7)), load_photo("page", (0.9, 0.9, 0.8)))
    dim = 0.05
    quads = [
        _plane((-10, -6, 8.0), (20, 0, 0), (0, 12, 0), 0, dim),  # back wall
        _plane((-10, 1.4, 0.5), (20, 0, 0), (0, 0, 7.5), 1, 0.6 * dim),  # floor (y = 1.4)
        _plane((-2.6, -1.6, 7.95), (1.8, 0, 0), (0, 1.4, 0), 2, dim),  # dim posters on the wall
        _plane((1.6, 0.1, 7.95), (1.4, 0, 0), (0, 1.8, 0), 7, dim),
        _plane((0.3, -1.4, 6.5), (1.2, 0, -0.3), (0, 1.2, 0), 3, 1.3),  # a lit poster
        *_box((-1.0, 0.9, 4.5), (0.9, 1.0, 0.9), 4, 1.6),  # a bright box
        _plane((1.6, -1.2, 5.0), (0.35, 0, 0), (0, 0.5, 0), 6, 2.5),  # a lamp
        _plane((-3.6, -0.4, 6.0), (1.2, 0, 0.2), (0, 0.9, 0), 5, 1.0),  # a star field
    ]
    motion = Motion(target=(0.0, 0.3, 15.0), radius=(15.0, 15.0), azimuth_deg=(-10.0, 10.0),
                    height=(-0.3, -0.2), bob=0.05, shake_pos=0.004, shake_rot_deg=0.3)
    return Preset(World(tuple(quads), tex, background=(0.004, 0.004, 0.005)), motion, 62.0)


def depth() -> Preset:
    """Sideways slide past near posts toward a far wall: depths from 1.2 to 40 m."""
    tex = (load_photo("rocket"), load_photo("grass", (0.7, 0.85, 0.55)), load_photo("brick", (0.8, 0.6, 0.5)),
           load_photo("coffee"), load_photo("chelsea"), load_photo("astronaut"))
    quads = [
        _plane((-35, -30, 40.0), (70, 0, 0), (0, 31.2, 0), 0),  # far wall (z = 40)
        _plane((-15, 1.2, 0.5), (30, 0, 0), (0, 0, 39.5), 1),  # floor (y = 1.2)
        *_box((-0.75, 0.2, 1.3), (0.18, 2.0, 0.18), 2),  # a post 1.3 m away
        *_box((0.85, 0.1, 2.0), (0.2, 2.2, 0.2), 2),  # another at 2 m
        *_box((0.25, 0.95, 1.6), (0.4, 0.5, 0.4), 3),  # a small box on the floor
        _plane((-3.5, -1.2, 8.0), (2.4, 0, 0), (0, 2.4, 0), 4),  # a panel at 8 m
        _plane((2.0, -3.5, 14.0), (4.0, 0, 0), (0, 4.7, 0), 5),  # a panel at 14 m
    ]
    motion = Motion(target=(0.0, -0.3, 40.0), radius=(40.0, 40.0), azimuth_deg=(-1.6, 1.6),
                    height=(-0.2, -0.2), bob=0.03, shake_pos=0.004, shake_rot_deg=0.3)
    return Preset(World(tuple(quads), tex), motion, 62.0)


WALK_SHAKE = {"shake_pos": 0.03, "shake_rot_deg": 3.0, "shake_hz": (1.0, 6.0)}  # a hand-held walker's sway


def hallway() -> Preset:
    """Walk 10 m down a 20 m corridor of five differently textured segments in 20 s."""
    names = ("brick", "coffee", "gravel", "grass", "hubble_deep_field", "chelsea", "immunohistochemistry",
             "rocket", "astronaut", "page", "coins", "text", "colorwheel", "camera")
    tints = {"brick": (0.8, 0.75, 0.7), "gravel": (0.6, 0.6, 0.65), "grass": (0.9, 0.95, 0.8),
             "page": (0.95, 0.9, 0.8), "coins": (0.9, 0.85, 0.7)}
    tex = tuple(load_photo(n, tints.get(n, (1.0, 1.0, 1.0))) for n in names)
    seg, n_seg = 4.0, 5
    walls = ((0, 1), (9, 5), (11, 0), (1, 10), (5, 9))  # (left, right) texture of each segment
    floors, ceilings = (2, 3, 2, 10, 3), (3, 11, 4, 3, 11)
    quads = []
    for i in range(n_seg):
        z0, z1 = i * seg, (i + 1) * seg
        crop = (0.1 * i, 0.0, 0.1 * i + 0.5, 1.0)  # the same photo differs from segment to segment
        quads += [
            _plane((-1.5, -1.5, z0), (0, 0, seg), (0, 2.7, 0), walls[i][0], crop=crop),  # left wall
            _plane((1.5, -1.5, z1), (0, 0, -seg), (0, 2.7, 0), walls[i][1], crop=crop),  # right wall
            _plane((-1.5, 1.2, z0), (3.0, 0, 0), (0, 0, seg), floors[i], crop=crop),  # floor (y = 1.2)
            _plane((-1.5, -1.5, z1), (3.0, 0, 0), (0, 0, -seg), ceilings[i], 0.8, crop),  # ceiling
            _plane((-1.49, -0.9, z0 + 1.2), (0, 0, 1.4), (0, 1.1, 0), (6, 7, 8, 12, 13)[i], 1.1),  # posters
            _plane((1.49, -0.7, z0 + 2.9), (0, 0, -1.2), (0, 1.0, 0), (8, 12, 6, 13, 7)[i], 1.1),
        ]
    quads += [
        _plane((-1.5, -1.5, seg * n_seg), (3.0, 0, 0), (0, 2.7, 0), 4),  # end wall (z = 20)
        *_box((0.7, 0.8, 6.5), (0.6, 0.8, 0.6), 8),
        *_box((-0.8, 0.85, 13.0), (0.7, 0.7, 0.5), 12),
        *_box((0.6, 0.9, 17.5), (0.5, 0.6, 0.5), 1),
    ]
    motion = Motion(target=(0.0, 0.0, 40.0), radius=(39.5, 39.5), azimuth_deg=(0.0, 0.0),
                    height=(-0.3, -0.3), target_shift=(0.0, 0.0, 10.0), look_shift=(1.5, 0.0, 0.0),
                    period=20.0, **WALK_SHAKE)
    return Preset(World(tuple(quads), tex), motion, 66.0)


def walkway() -> Preset:
    """Walk 10 m along a 24 m wall of photo panels in 20 s, looking at it."""
    names = ("astronaut", "coffee", "chelsea", "rocket", "hubble_deep_field", "immunohistochemistry",
             "page", "coins", "text", "colorwheel", "camera", "brick", "gravel", "grass")
    tints = {"brick": (0.85, 0.6, 0.45), "gravel": (0.7, 0.7, 0.72), "grass": (0.75, 0.9, 0.6),
             "page": (0.95, 0.9, 0.8), "coins": (0.9, 0.85, 0.7)}
    tex = tuple(load_photo(n, tints.get(n, (1.0, 1.0, 1.0))) for n in names)
    quads = []
    for i in range(6):  # pavement (y = 1.4) and the wall behind the panels (z = 3), 4 m tiles
        crop = (0.08 * i, 0.0, 0.08 * i + 0.5, 1.0)
        quads += [_plane((-12 + 4.0 * i, 1.4, -1.0), (4.0, 0, 0), (0, 0, 4.0), 12 + i % 2, crop=crop),
                  _plane((-12 + 4.0 * i, -3.0, 3.02), (4.0, 0, 0), (0, 4.4, 0), 11, crop=crop)]
    for i in range(12):  # a panel every 2 m, at alternating heights and sizes
        x0 = -12.0 + 2.0 * i + 0.2
        w, h = (1.6, 1.4) if i % 2 == 0 else (1.3, 1.8)
        quads.append(_plane((x0, -1.9 + 0.3 * (i % 3), 3.0), (w, 0, 0), (0, h, 0), i % 11))
    for i in range(6):  # posts 1.5 m in front of the wall
        quads += _box((-10.0 + 4.0 * i, 0.4, 1.5), (0.12, 2.0, 0.12), 13)
    motion = Motion(target=(-5.0, 0.0, 10.0), radius=(10.0, 10.0), azimuth_deg=(0.0, 0.0),
                    height=(-0.2, -0.2), target_shift=(10.0, 0.0, 0.0), period=20.0, **WALK_SHAKE)
    return Preset(World(tuple(quads), tex), motion, 62.0)


PRESETS: dict[str, Callable[[], Preset]] = {"boxes": boxes, "wall": wall, "corridor": corridor,
                                            "gallery": gallery, "dark": dark, "depth": depth,
                                            "hallway": hallway, "walkway": walkway}


def get_preset(name: str) -> Preset:
    """Build a preset by name (``PRESETS`` keys); unknown names raise :class:`InputError`."""
    if name not in PRESETS:
        raise InputError("simulate", "preset", f"one of {', '.join(PRESETS)}", repr(name))
    return PRESETS[name]()
