"""Photographic textures for the simulator: scikit-image sample photos in linear light, with mipmaps.

The photos ship inside scikit-image (no download). They are stored as sRGB; the simulator renders
linear radiance, so every texture is decoded with the sRGB transfer curve first.
"""

from __future__ import annotations

import numpy as np
import torch

from fusiongs.errors import InputError
from fusiongs.frames.response import srgb_to_linear

# Colour photos and grey textures bundled with scikit-image (``skimage.data.<name>()``).
COLOUR_PHOTOS = ("astronaut", "coffee", "chelsea", "rocket", "immunohistochemistry",
                 "hubble_deep_field", "colorwheel", "retina")
GREY_PHOTOS = ("brick", "grass", "gravel", "camera", "coins", "moon", "text", "page", "cell")


def load_photo(name: str, tint: tuple[float, float, float] = (1.0, 1.0, 1.0),
               max_side: int = 512) -> np.ndarray:
    """A bundled scikit-image photo as a linear-light RGB texture.

    Args:
        name: one of ``COLOUR_PHOTOS`` or ``GREY_PHOTOS``.
        tint: per-channel linear multipliers (gives grey textures a colour).
        max_side: the longer side is downsampled (area average) to at most this many texels.

    Returns:
        ``[h, w, 3]`` float32 linear reflectance in [0, 1].
    """
    import skimage.data
    from skimage.transform import resize

    if name not in COLOUR_PHOTOS + GREY_PHOTOS:
        raise InputError("simulator", "texture", f"one of {', '.join(COLOUR_PHOTOS + GREY_PHOTOS)}",
                         repr(name))
    img = np.asarray(getattr(skimage.data, name)())
    if img.dtype == bool:
        img = img.astype(np.uint8) * 255
    img = img.astype(np.float32) / np.float32(255.0)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    img = img[:, :, :3]
    scale = max_side / max(img.shape[:2])
    if scale < 1:
        shape = (max(1, round(img.shape[0] * scale)), max(1, round(img.shape[1] * scale)), 3)
        img = resize(img, shape, order=1, anti_aliasing=True).astype(np.float32)
    lin = srgb_to_linear(np.clip(img, 0.0, 1.0)).astype(np.float32)
    return np.clip(lin * np.asarray(tint, dtype=np.float32), 0.0, 1.0)


def solid_texture(rgb: tuple[float, float, float], size: int = 4) -> np.ndarray:
    """A constant ``[size, size, 3]`` float32 linear texture."""
    return np.broadcast_to(np.asarray(rgb, dtype=np.float32), (size, size, 3)).copy()


def build_mipmaps(texture: np.ndarray, device: torch.device | str = "cpu") -> list[torch.Tensor]:
    """Mipmap pyramid of a texture by repeated 2x2 area averaging.

    Args:
        texture: ``[h, w, 3]`` float32 linear texture.
        device: where the pyramid lives (the renderer's device).

    Returns:
        list of ``[1, 3, h_l, w_l]`` float32 tensors, level 0 = full resolution, down to 1 texel.
    """
    level = torch.as_tensor(np.ascontiguousarray(texture), dtype=torch.float32,
                            device=device).permute(2, 0, 1)[None]
    levels = [level]
    while max(level.shape[-2:]) > 1:
        h, w = level.shape[-2:]
        level = torch.nn.functional.interpolate(level, size=(max(1, h // 2), max(1, w // 2)),
                                                mode="area")
        levels.append(level)
    return levels
