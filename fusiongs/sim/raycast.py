"""A vectorised ray caster for textured rectangles (planes and boxes), rendering linear radiance.

The simulator's ground truth is deliberately *not* a Gaussian model: the world is a set of
textured rectangles (``Quad``), every pixel's rays are intersected with every rectangle at once
(ray-plane intersection, nearest hit), and textures are read with trilinear mipmap filtering on
top of fixed jittered supersampling (anti-aliasing that does not flicker from one instant to the
next, so it creates no spurious events).

Conventions: world and camera use OpenCV axes (x right, y down, z forward); pixel centres are at
integer + 0.5; ``c2w`` is camera-to-world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch
import torch.nn.functional as F

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.sim.textures import build_mipmaps

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Quad:
    """A textured rectangle (a parallelogram in general).

    Attributes:
        origin: world position (m) of the texture's top-left corner.
        edge_u: world vector (m) from ``origin`` to the corner at texture (1, 0) (along columns).
        edge_v: world vector (m) from ``origin`` to the corner at texture (0, 1) (along rows).
        texture: index into ``World.textures``.
        crop: ``(u0, v0, u1, v1)`` part of the texture shown, in normalised texture coordinates.
        gain: radiance multiplier (shading times light intensity).
        one_sided: seen only from the side ``edge_v x edge_u`` points to (box faces, outward);
            lets the renderer skip faces turned away from the camera.
    """

    origin: Vec3
    edge_u: Vec3
    edge_v: Vec3
    texture: int
    crop: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)
    gain: float = 1.0
    one_sided: bool = False


@dataclass(frozen=True, eq=False)
class World:
    """Geometry and linear textures of a simulated scene.

    Attributes:
        quads: the rectangles.
        textures: ``[h, w, 3]`` float32 linear reflectance textures.
        background: linear RGB radiance of rays that hit nothing.
    """

    quads: tuple[Quad, ...]
    textures: tuple[np.ndarray, ...]
    background: Vec3 = (0.02, 0.02, 0.02)


def box_quads(center: Vec3, size: Vec3, texture: int, gains: tuple[float, ...] = (1.0,) * 6,
              tiles: int = 2) -> list[Quad]:
    """The six faces of an axis-aligned box, each showing a different crop of one texture.

    Args:
        center: box centre (m). size: extents along x, y, z (m).
        texture: texture index. gains: radiance multiplier of the faces -x, +x, -y, +y, -z, +z.
        tiles: the texture is split into ``tiles x tiles`` crops, assigned to faces in turn.

    Returns:
        six quads.
    """
    c, h = np.asarray(center, float), np.asarray(size, float) / 2
    ex, ey, ez = np.diag(2 * h)
    faces = [  # (origin, edge_u, edge_v) with the texture upright (v along +y where possible)
        (c + [-h[0], -h[1], h[2]], -ez, ey), (c + [h[0], -h[1], -h[2]], ez, ey),
        (c + [-h[0], -h[1], h[2]], ex, -ez), (c + [-h[0], h[1], -h[2]], ex, ez),
        (c + [-h[0], -h[1], -h[2]], ex, ey), (c + [h[0], -h[1], h[2]], -ex, ey),
    ]
    quads = []
    for i, ((o, u, v), g) in enumerate(zip(faces, gains)):
        k = i % (tiles * tiles)
        u0, v0 = (k % tiles) / tiles, (k // tiles) / tiles
        quads.append(Quad(tuple(o), tuple(u), tuple(v), texture,
                          (u0, v0, u0 + 1 / tiles, v0 + 1 / tiles), float(g), True))
    return quads


def lambert_gain(normal: Vec3, light_dir: Vec3, ambient: float = 0.35, intensity: float = 1.0) -> float:
    """Two-sided Lambertian shading ``intensity * (ambient + (1 - ambient) |n . l|)`` (unit vectors)."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    ld = np.asarray(light_dir, float) / np.linalg.norm(light_dir)
    return float(intensity * (ambient + (1 - ambient) * abs(n @ ld)))


def pixel_sample_offsets(height: int, width: int, ss: int, jitter: float,
                         rng: np.random.Generator) -> np.ndarray:
    """Fixed jittered-stratified sample positions inside every pixel.

    Args:
        height, width: image size. ss: samples per pixel along each axis (``ss * ss`` in all).
        jitter: maximal offset from each stratum's centre as a fraction of the stratum (0..0.5).
        rng: seeded generator (the pattern is drawn once and reused for every render).

    Returns:
        ``[H, W, ss * ss, 2]`` float64 sample (x, y) positions in pixels (pixel centres at +0.5).
    """
    i = (np.arange(ss * ss) % ss + 0.5) / ss
    j = (np.arange(ss * ss) // ss + 0.5) / ss
    jit = rng.uniform(-jitter, jitter, size=(height, width, ss * ss, 2)) / ss
    xs = np.arange(width)[None, :, None] + i[None, None, :] + jit[..., 0]
    ys = np.arange(height)[:, None, None] + j[None, None, :] + jit[..., 1]
    return np.stack([np.broadcast_to(xs, ys.shape), ys], axis=-1)


@dataclass(eq=False)
class RayCaster:
    """Renders a ``World`` through a ``PinholeCamera``; holds the packed geometry and mipmaps.

    Args:
        world: the scene. camera: intrinsics (distortion ignored). ss: supersampling per axis.
        seed: seed of the fixed jitter pattern. device: tensor device.
    """

    world: World
    camera: PinholeCamera
    ss: int = 2
    seed: int = 0
    device: str = "cpu"
    _packed: dict = field(init=False, repr=False)

    def __post_init__(self) -> None:
        cam, dev = self.camera, self.device
        off = pixel_sample_offsets(cam.height, cam.width, self.ss, 0.3, np.random.default_rng(self.seed))
        d = np.stack([(off[..., 0] - cam.cx) / cam.fx, (off[..., 1] - cam.cy) / cam.fy,
                      np.ones(off.shape[:-1])], axis=-1).reshape(-1, 3)
        q = self.world.quads
        f32 = dict(dtype=torch.float32, device=dev)
        O, U, V = (torch.tensor([getattr(x, k) for x in q], dtype=torch.float64, device=dev)
                   for k in ("origin", "edge_u", "edge_v"))
        crop = torch.tensor([x.crop for x in q], **f32)
        tex_hw = torch.tensor([self.world.textures[x.texture].shape[:2] for x in q], **f32)
        density = torch.maximum(tex_hw[:, 1] * (crop[:, 2] - crop[:, 0]) / U.norm(dim=1).float(),
                                tex_hw[:, 0] * (crop[:, 3] - crop[:, 1]) / V.norm(dim=1).float())
        self._packed = dict(
            dirs=torch.tensor(d, **f32), O=O, U=U, V=V, N=torch.linalg.cross(U, V),
            one_sided=torch.tensor([x.one_sided for x in q], dtype=torch.bool, device=dev),
            crop=crop, density=density, texture=torch.tensor([x.texture for x in q], device=dev),
            gain=torch.tensor([x.gain for x in q], **f32),
            mips=[build_mipmaps(t, dev) for t in self.world.textures],
            background=torch.tensor(self.world.background, **f32))

    def render(self, c2w: np.ndarray | torch.Tensor) -> torch.Tensor:
        """Linear radiance ``[H, W, 3]`` float32 for one camera-to-world pose ``[4, 4]``."""
        cam, pk = self.camera, self._packed
        origin, dirs = self._rays(c2w, pk["dirs"])
        qid, depth, a, b, cos_term = self._hit(origin, dirs)
        rgb = pk["background"].expand(dirs.shape[0], 3).clone()
        idx = torch.nonzero(qid >= 0).squeeze(1)
        if idx.numel():
            q = qid[idx]
            crop = pk["crop"][q]
            uv = torch.stack([crop[:, 0] + a[idx] * (crop[:, 2] - crop[:, 0]),
                              crop[:, 1] + b[idx] * (crop[:, 3] - crop[:, 1])], dim=1)
            # Footprint of one sub-sample on the surface, in texels: depth / f on a fronto-parallel
            # plane, stretched by 1 / cos(incidence) relative to the view axis (capped at 4).
            stretch = torch.clamp(1.0 / (dirs[idx].norm(dim=1) * cos_term[idx].clamp_min(1e-6)), max=4.0)
            footprint = depth[idx] / cam.fx * stretch * pk["density"][q] / self.ss
            col = sample_textures(pk["mips"], pk["texture"][q], uv, footprint)
            rgb[idx] = col * pk["gain"][q, None]
        return rgb.reshape(cam.height, cam.width, self.ss * self.ss, 3).mean(dim=2)

    def surface_points(self, c2w: np.ndarray | torch.Tensor) -> torch.Tensor:
        """World points ``[n, 3]`` hit by the first sub-sample ray of every pixel (misses left out)."""
        pk = self._packed
        origin, dirs = self._rays(c2w, pk["dirs"].reshape(-1, self.ss * self.ss, 3)[:, 0])
        qid, depth, *_ = self._hit(origin, dirs)
        ok = qid >= 0
        return origin.float() + depth[ok, None] * dirs[ok]

    def _rays(self, c2w, dirs_cam: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        m = torch.as_tensor(np.asarray(c2w), dtype=torch.float64, device=self.device)
        return m[:3, 3], dirs_cam @ m[:3, :3].float().T  # camera z-component 1: hit parameter = depth

    def _hit(self, origin: torch.Tensor, dirs: torch.Tensor):
        pk = self._packed
        # Back-face culling of one-sided quads (box faces): keep those facing the eye.
        facing = ((origin[None] - pk["O"]) * pk["N"]).sum(1) < 0
        sel = torch.nonzero(~pk["one_sided"] | facing).squeeze(1)
        qid, *rest = intersect_quads(origin, dirs, pk["O"][sel], pk["U"][sel], pk["V"][sel], pk["N"][sel])
        return (torch.where(qid >= 0, sel[qid.clamp_min(0)], -1), *rest)


def intersect_quads(origin: torch.Tensor, dirs: torch.Tensor, O: torch.Tensor, U: torch.Tensor,
                    V: torch.Tensor, N: torch.Tensor, near: float = 1e-3):
    """Nearest ray-rectangle intersection for all rays at once.

    Args:
        origin: ``[3]`` float64 ray origin (m). dirs: ``[S, 3]`` ray directions (not normalised).
        O, U, V: ``[Q, 3]`` float64 rectangle corners and edge vectors. N: ``[Q, 3]`` ``U x V``.
        near: smallest accepted ray parameter.

    Returns:
        ``qid [S]`` int64 index of the hit rectangle (-1 = miss), ``t [S]`` ray parameter of the hit
        (``origin + t * dirs``), ``a, b [S]`` coordinates in [0, 1] along ``U`` and ``V``, and
        ``cos [S]`` = |unit(dirs) . unit(N)| (all float32).
    """
    rel = origin[None] - O  # [Q, 3] float64: small per-quad terms in double precision
    num = (-(rel * N).sum(1)).float()
    ru, rv = ((rel * U).sum(1) / (U * U).sum(1)).float(), ((rel * V).sum(1) / (V * V).sum(1)).float()
    Uf, Vf = (U / (U * U).sum(1, keepdim=True)).float(), (V / (V * V).sum(1, keepdim=True)).float()
    denom = dirs @ N.float().T  # [S, Q]
    t = num[None] / denom  # +-inf or nan where parallel: rejected below
    a = ru[None] + t * (dirs @ Uf.T)
    b = rv[None] + t * (dirs @ Vf.T)
    valid = (t > near) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
    tbest, qid = torch.where(valid, t, torch.inf).min(dim=1)
    qid = torch.where(torch.isinf(tbest), -1, qid)
    g = qid.clamp_min(0)[:, None]
    cos = denom.gather(1, g)[:, 0].abs() / (dirs.norm(dim=1) * N.float().norm(dim=1)[g[:, 0]])
    return qid, tbest, a.gather(1, g)[:, 0], b.gather(1, g)[:, 0], cos


def sample_textures(mips: list[list[torch.Tensor]], tex: torch.Tensor, uv: torch.Tensor,
                    footprint: torch.Tensor) -> torch.Tensor:
    """Trilinear (mipmapped) lookup in several textures at once.

    Args:
        mips: per texture, its pyramid from ``build_mipmaps`` (``[1, 3, h_l, w_l]`` per level).
        tex: ``[n]`` int64 texture index of each sample.
        uv: ``[n, 2]`` normalised texture coordinates in [0, 1] (u along columns).
        footprint: ``[n]`` sample footprint in level-0 texels; the level is ``log2(footprint)``.

    Returns:
        ``[n, 3]`` linear colours.
    """
    top = torch.tensor([len(m) - 1 for m in mips], dtype=torch.float32, device=uv.device)
    lam = torch.minimum(torch.log2(footprint.clamp_min(1.0)), top[tex])
    l0 = lam.floor().long()
    w = (lam - l0)[:, None]
    grid = uv * 2 - 1
    out = torch.empty(uv.shape[0], 3, dtype=uv.dtype, device=uv.device)
    # Group samples by (texture, level) with one sort; each group is two bilinear lookups.
    stride = 64
    key = tex * stride + l0
    order = torch.argsort(key)
    counts = torch.bincount(key, minlength=len(mips) * stride)
    ends = torch.cumsum(counts, 0).tolist()
    for k in torch.nonzero(counts).squeeze(1).tolist():
        sl = order[ends[k] - int(counts[k]):ends[k]]
        pyr, lvl = mips[k // stride], k % stride
        g = grid[sl][None, None]
        c0 = _bilinear(pyr[lvl], g)
        c1 = _bilinear(pyr[min(lvl + 1, len(pyr) - 1)], g)
        out[sl] = c0 + w[sl] * (c1 - c0)
    return out


def _bilinear(tex: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    s = F.grid_sample(tex, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return s[0, :, 0].T  # [n, 3]


def look_at(eye: np.ndarray, target: np.ndarray, down: Vec3 = (0.0, 1.0, 0.0)) -> np.ndarray:
    """Camera-to-world rotations ``[..., 3, 3]`` looking from ``eye`` to ``target`` (OpenCV axes)."""
    z = np.asarray(target, float) - np.asarray(eye, float)
    z = z / np.linalg.norm(z, axis=-1, keepdims=True)
    x = np.cross(np.broadcast_to(np.asarray(down, float), z.shape), z)
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1)


def fov_focal(width: int, hfov_deg: float) -> float:
    """Focal length in pixels for a horizontal field of view in degrees."""
    return width / 2 / math.tan(math.radians(hfov_deg) / 2)
