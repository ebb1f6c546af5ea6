"""A random pixel rectangle rendered in one training step (full resolution, shifted principal point).

A pinhole camera of size ``(w, h)`` whose principal point is moved by ``(-x0, -y0)`` sees pixels
``x0..x0+w-1`` × ``y0..y0+h-1`` of the full image, so the losses of a step can be taken on a window
of the frame at a fraction of the rendering cost (the rays-in-a-batch idea of NeRF training, with
patches so that SSIM still has neighbourhoods). The crop equals the full render except for
Gaussians centred far outside it (beyond 1.3x its half field of view), whose projection Jacobian is
clamped (3DGS / gsplat), the approximation the full image makes at its own borders.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from fusiongs.camera.pinhole import PinholeCamera


@dataclass(frozen=True)
class Crop:
    """Columns ``x0 .. x0 + w - 1`` and rows ``y0 .. y0 + h - 1`` of a ``full_w`` × ``full_h`` image."""

    x0: int
    y0: int
    w: int
    h: int
    full_w: int
    full_h: int

    @staticmethod
    def whole(camera: PinholeCamera) -> Crop:
        return Crop(0, 0, camera.width, camera.height, camera.width, camera.height)

    @staticmethod
    def random(camera: PinholeCamera, size: tuple[int, int] | None, gen: torch.Generator) -> Crop:
        """A uniformly placed ``size = (w, h)`` crop (clipped to the image); the whole image if None."""
        if size is None:
            return Crop.whole(camera)
        w, h = min(int(size[0]), camera.width), min(int(size[1]), camera.height)
        x0 = int(torch.randint(0, camera.width - w + 1, (1,), generator=gen))
        y0 = int(torch.randint(0, camera.height - h + 1, (1,), generator=gen))
        return Crop(x0, y0, w, h, camera.width, camera.height)

    @property
    def is_whole(self) -> bool:
        return self.w == self.full_w and self.h == self.full_h

    def camera(self, camera: PinholeCamera) -> PinholeCamera:
        """The camera that renders exactly this crop."""
        if self.is_whole:
            return camera
        return PinholeCamera(self.w, self.h, camera.fx, camera.fy, camera.cx - self.x0,
                             camera.cy - self.y0, camera.distortion)

    def maps(self, x: torch.Tensor) -> torch.Tensor:
        """``[..., H, W]`` -> ``[..., h, w]``."""
        return x[..., self.y0:self.y0 + self.h, self.x0:self.x0 + self.w]

    def images(self, x: torch.Tensor) -> torch.Tensor:
        """``[..., H, W, C]`` -> ``[..., h, w, C]``."""
        return x[..., self.y0:self.y0 + self.h, self.x0:self.x0 + self.w, :]

    def full_index(self, pix: torch.Tensor) -> torch.Tensor:
        """Flat indices ``[P]`` into the crop -> flat indices ``y * full_w + x`` of the full image."""
        return (self.y0 + pix // self.w) * self.full_w + self.x0 + pix % self.w
