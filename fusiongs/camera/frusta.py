"""Points sampled uniformly (in volume) inside the viewing frusta of posed pinhole cameras."""

from __future__ import annotations

import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError

DEPTH_SAMPLING = ("volume", "depth", "disparity")


def sample_in_frusta(camera: PinholeCamera, c2w: torch.Tensor, n: int, near: float, far: float,
                     generator: torch.Generator, depth_sampling: str = "volume") -> torch.Tensor:
    """Sample ``n`` points uniformly in the union of the frusta (each camera equally likely).

    A camera is drawn uniformly, then a point uniformly in the volume of its frustum between the
    depths ``near`` and ``far``: pixel coordinates uniform over ``[0, W) x [0, H)`` and depth with
    density proportional to ``z^2`` (``z = (near^3 + U (far^3 - near^3))^(1/3)``). Lens distortion
    is ignored (ideal pinhole).

    ``depth_sampling`` picks the depth density instead: ``"volume"`` (uniform in volume, density
    ``∝ z^2``), ``"depth"`` (uniform in z) or ``"disparity"`` (uniform in 1/z, density ``∝ 1/z^2``,
    as NeRF's ``lindisp`` for scenes whose content is mostly near).

    Args:
        camera: intrinsics.
        c2w: ``[C, 4, 4]`` camera-to-world poses (OpenCV axes: z forward).
        n: number of points.
        near, far: depth range along the optical axis (scene units), ``0 <= near < far``.
        generator: torch random generator (its device is used for sampling).
        depth_sampling: ``"volume"``, ``"depth"`` or ``"disparity"``.

    Returns:
        ``[n, 3]`` world points, on ``c2w``'s device and dtype.

    Raises:
        InputError: on a bad depth range, ``n < 0`` or ``c2w`` not ``[C, 4, 4]``.
    """
    if not (0 <= near < far):
        raise InputError("random init", "near/far", "0 <= near < far", f"{near}, {far}")
    if n < 0:
        raise InputError("random init", "n", "a non-negative number of points", n)
    if depth_sampling not in DEPTH_SAMPLING:
        raise InputError("random init", "depth_sampling", " or ".join(DEPTH_SAMPLING), depth_sampling)
    if depth_sampling == "disparity" and near <= 0:
        raise InputError("random init", "near", "near > 0 for disparity sampling", near)
    c2w = torch.as_tensor(c2w)
    if not c2w.is_floating_point():
        c2w = c2w.double()
    if c2w.ndim != 3 or c2w.shape[1:] != (4, 4) or c2w.shape[0] == 0:
        raise InputError("random init", "c2w", "[C, 4, 4] poses with C >= 1", tuple(c2w.shape))
    gen = dict(generator=generator, device=generator.device, dtype=torch.float64)
    cam = torch.randint(c2w.shape[0], (n,), generator=generator, device=generator.device)
    u = torch.rand(n, **gen) * camera.width
    v = torch.rand(n, **gen) * camera.height
    r = torch.rand(n, **gen)
    if depth_sampling == "volume":
        z = (near**3 + r * (far**3 - near**3)) ** (1 / 3)
    elif depth_sampling == "depth":
        z = near + r * (far - near)
    else:
        z = 1.0 / (1.0 / near + r * (1.0 / far - 1.0 / near))
    p = torch.stack([(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z], -1)
    pose = c2w.to(torch.float64).to(generator.device)[cam]
    world = (pose[:, :3, :3] @ p[:, :, None])[:, :, 0] + pose[:, :3, 3]
    return world.to(dtype=c2w.dtype, device=c2w.device)
