"""Points sampled uniformly (in volume) inside the viewing frusta of posed pinhole cameras."""

from __future__ import annotations

import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError


def sample_in_frusta(camera: PinholeCamera, c2w: torch.Tensor, n: int, near: float, far: float,
                     generator: torch.Generator) -> torch.Tensor:
    """Sample ``n`` points uniformly in the union of the frusta (each camera equally likely).

    A camera is drawn uniformly, then a point uniformly in the volume of its frustum between the
    depths ``near`` and ``far``: pixel coordinates uniform over ``[0, W) x [0, H)`` and depth with
    density proportional to ``z^2`` (``z = (near^3 + U (far^3 - near^3))^(1/3)``). Lens distortion
    is ignored (ideal pinhole).

    Args:
        camera: intrinsics.
        c2w: ``[C, 4, 4]`` camera-to-world poses (OpenCV axes: z forward).
        n: number of points.
        near, far: depth range along the optical axis (scene units), ``0 <= near < far``.
        generator: torch random generator (its device is used for sampling).

    Returns:
        ``[n, 3]`` world points, on ``c2w``'s device and dtype.

    Raises:
        InputError: on a bad depth range, ``n < 0`` or ``c2w`` not ``[C, 4, 4]``.
    """
    if not (0 <= near < far):
        raise InputError("random init", "near/far", "0 <= near < far", f"{near}, {far}")
    if n < 0:
        raise InputError("random init", "n", "a non-negative number of points", n)
    c2w = torch.as_tensor(c2w)
    if not c2w.is_floating_point():
        c2w = c2w.double()
    if c2w.ndim != 3 or c2w.shape[1:] != (4, 4) or c2w.shape[0] == 0:
        raise InputError("random init", "c2w", "[C, 4, 4] poses with C >= 1", tuple(c2w.shape))
    gen = dict(generator=generator, device=generator.device, dtype=torch.float64)
    cam = torch.randint(c2w.shape[0], (n,), generator=generator, device=generator.device)
    u = torch.rand(n, **gen) * camera.width
    v = torch.rand(n, **gen) * camera.height
    z = (near**3 + torch.rand(n, **gen) * (far**3 - near**3)) ** (1 / 3)
    p = torch.stack([(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z], -1)
    pose = c2w.to(torch.float64).to(generator.device)[cam]
    world = (pose[:, :3, :3] @ p[:, :, None])[:, :, 0] + pose[:, :3, 3]
    return world.to(dtype=c2w.dtype, device=c2w.device)
