"""3D Gaussian parameters and their activations (Kerbl et al., 3D Gaussian Splatting, 2023).

The model holds raw ``nn.Parameter`` tensors (the names are the optimiser group names):

================  ============  ===========================================================
name              shape         activation / meaning
================  ============  ===========================================================
``means``         ``[N, 3]``    world positions
``log_scales``    ``[N, 3]``    ``scales = exp(log_scales)`` (standard deviations, world units)
``quats``         ``[N, 4]``    rotation ``(w, x, y, z)``, normalised on use
``opacity_logits`` ``[N]``      ``opacities = sigmoid(opacity_logits)``
``sh0``           ``[N, 1, 3]`` SH DC coefficient per RGB channel
``shN``           ``[N, K-1, 3]`` higher SH bands, ``K = (max_sh_degree + 1)^2``
================  ============  ===========================================================

Colour convention (gsplat / Inria): ``colour = SH(dir) + 0.5``, so ``sh0 = (rgb - 0.5) / C0`` with
``C0 = 0.28209479177387814``. In fusiongs the rendered colour is **linear** radiance.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from fusiongs.camera.frusta import sample_in_frusta
from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError
from fusiongs.scene.knn import knn_distances

SH_C0 = 0.28209479177387814
PARAM_NAMES = ("means", "log_scales", "quats", "opacity_logits", "sh0", "shN")


def num_sh_coeffs(degree: int) -> int:
    """Number of SH coefficients per channel ``(degree + 1)^2``."""
    return (degree + 1) ** 2


class GaussianModel(nn.Module):
    """A set of 3D Gaussians (see the module docstring for the parameters).

    Args:
        means, log_scales, quats, opacity_logits, sh0, shN: raw tensors (shapes above).
        active_sh_degree: SH degree the renderer should use now (``<= max_sh_degree``).

    Raises:
        InputError: when shapes disagree or ``shN`` does not hold ``(d+1)^2 - 1`` bands, d <= 3.
    """

    def __init__(self, means: torch.Tensor, log_scales: torch.Tensor, quats: torch.Tensor,
                 opacity_logits: torch.Tensor, sh0: torch.Tensor, shN: torch.Tensor,
                 active_sh_degree: int = 0):
        super().__init__()
        n = means.shape[0]
        expected = {"means": (n, 3), "log_scales": (n, 3), "quats": (n, 4), "opacity_logits": (n,),
                    "sh0": (n, 1, 3)}
        given = dict(means=means, log_scales=log_scales, quats=quats, opacity_logits=opacity_logits,
                     sh0=sh0, shN=shN)
        for name, shape in expected.items():
            if tuple(given[name].shape) != shape:
                raise InputError("GaussianModel", name, f"shape {list(shape)}", list(given[name].shape))
        k = shN.shape[1] + 1 if shN.ndim == 3 else -1
        degree = round(math.sqrt(k)) - 1 if k > 0 else -1
        if shN.ndim != 3 or shN.shape[0] != n or shN.shape[2] != 3 or num_sh_coeffs(degree) != k \
                or not 0 <= degree <= 3:
            raise InputError("GaussianModel", "shN", "shape [N, (d+1)^2 - 1, 3] with SH degree d <= 3",
                             list(shN.shape))
        if not 0 <= active_sh_degree <= degree:
            raise InputError("GaussianModel", "active_sh_degree", f"0 .. {degree}", active_sh_degree)
        self.max_sh_degree = degree
        self.active_sh_degree = int(active_sh_degree)
        for name, value in given.items():
            setattr(self, name, nn.Parameter(value.detach().clone()))

    # --- activated values -------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of Gaussians ``N``."""
        return int(self.means.shape[0])

    @property
    def scales(self) -> torch.Tensor:
        """``[N, 3]`` standard deviations ``exp(log_scales)``."""
        return torch.exp(self.log_scales)

    @property
    def opacities(self) -> torch.Tensor:
        """``[N]`` opacities in (0, 1), ``sigmoid(opacity_logits)``."""
        return torch.sigmoid(self.opacity_logits)

    @property
    def rotations(self) -> torch.Tensor:
        """``[N, 4]`` unit quaternions ``(w, x, y, z)``."""
        return nn.functional.normalize(self.quats, dim=-1)

    def sh_coeffs(self) -> torch.Tensor:
        """``[N, K, 3]`` all SH coefficients (``K = (max_sh_degree + 1)^2``); render with
        ``sh_degree=self.active_sh_degree`` (the renderer uses the first ``(d+1)^2``)."""
        return torch.cat([self.sh0, self.shN], dim=1)

    def base_colors(self) -> torch.Tensor:
        """``[N, 3]`` view-independent colour ``sh0 * C0 + 0.5`` (not clamped)."""
        return self.sh0[:, 0] * SH_C0 + 0.5

    def grow_sh_degree(self) -> int:
        """Raise the active SH degree by one (up to ``max_sh_degree``); returns the new degree."""
        self.active_sh_degree = min(self.active_sh_degree + 1, self.max_sh_degree)
        return self.active_sh_degree

    def parameter_groups(self) -> dict[str, nn.Parameter]:
        """Raw parameters by name (``PARAM_NAMES`` order), e.g. for per-group Adam learning rates."""
        return {name: getattr(self, name) for name in PARAM_NAMES}

    def get_extra_state(self) -> dict:
        return {"active_sh_degree": self.active_sh_degree, "max_sh_degree": self.max_sh_degree}

    def set_extra_state(self, state: dict) -> None:
        self.active_sh_degree = int(state["active_sh_degree"])

    # --- construction -----------------------------------------------------------------------
    @classmethod
    def empty(cls, n: int, sh_degree: int = 3, dtype: torch.dtype = torch.float32,
              device: torch.device | str | None = None) -> GaussianModel:
        """``n`` zero-initialised Gaussians (identity rotations), e.g. to ``load_state_dict`` into."""
        z = dict(dtype=dtype, device=device)
        quats = torch.zeros(n, 4, **z)
        quats[:, 0] = 1
        return cls(torch.zeros(n, 3, **z), torch.zeros(n, 3, **z), quats, torch.zeros(n, **z),
                   torch.zeros(n, 1, 3, **z), torch.zeros(n, num_sh_coeffs(sh_degree) - 1, 3, **z))

    @classmethod
    def from_points(cls, xyz: torch.Tensor, rgb: torch.Tensor | None = None, sh_degree: int = 3,
                    init_opacity: float = 0.1, init_scale: float = 1.0, k: int = 3,
                    where: str = "points") -> GaussianModel:
        """Isotropic Gaussians at points (3DGS initialisation).

        Scale = ``init_scale`` x RMS distance to the ``k`` nearest neighbours (floored at
        ``sqrt(1e-7)``, as Inria's ``distCUDA2``; a lone point gets scale 1), identity rotation,
        opacity ``init_opacity``, DC colour from ``rgb`` (higher bands zero).

        Args:
            xyz: ``[N, 3]`` points (their dtype/device are the model's).
            rgb: ``[N, 3]`` colours in [0, 1] (linear radiance), or ``None`` for grey 0.5.
            sh_degree: maximum SH degree 0..3 (active degree starts at 0).
            where: source name used in error messages.

        Raises:
            InputError: bad shapes, non-finite points, colours outside [0, 1], bad opacity.
        """
        xyz = torch.as_tensor(xyz)
        if not xyz.is_floating_point():
            xyz = xyz.float()
        if xyz.ndim != 2 or xyz.shape[1] != 3 or xyz.shape[0] == 0:
            raise InputError(where, "xyz", "[N, 3] points with N >= 1", list(xyz.shape))
        if not bool(torch.isfinite(xyz).all()):
            raise InputError(where, "xyz", "finite coordinates", "NaN or inf")
        if not 0 < init_opacity < 1:
            raise InputError(where, "init_opacity", "a number in (0, 1)", init_opacity)
        if not 0 <= sh_degree <= 3:
            raise InputError(where, "sh_degree", "0 .. 3", sh_degree)
        n = xyz.shape[0]
        if rgb is None:
            rgb = torch.full_like(xyz, 0.5)
        rgb = torch.as_tensor(rgb).to(dtype=xyz.dtype, device=xyz.device)
        if rgb.shape != xyz.shape:
            raise InputError(where, "rgb", f"[N, 3] colours with N = {n}", list(rgb.shape))
        if not bool(((rgb >= 0) & (rgb <= 1)).all()):
            raise InputError(where, "rgb", "colours in [0, 1]", f"range [{rgb.min()}, {rgb.max()}]")
        d = knn_distances(xyz, k)
        if d.shape[1] == 0:
            dist = torch.ones(n, dtype=xyz.dtype, device=xyz.device)
        else:
            dist = d.square().mean(1).clamp_min(1e-7).sqrt()
        log_scales = torch.log(dist * init_scale)[:, None].expand(n, 3)
        quats = torch.zeros(n, 4, dtype=xyz.dtype, device=xyz.device)
        quats[:, 0] = 1
        logit = math.log(init_opacity / (1 - init_opacity))
        opacity_logits = torch.full((n,), logit, dtype=xyz.dtype, device=xyz.device)
        sh0 = ((rgb - 0.5) / SH_C0)[:, None, :]
        shN = torch.zeros(n, num_sh_coeffs(sh_degree) - 1, 3, dtype=xyz.dtype, device=xyz.device)
        return cls(xyz, log_scales, quats, opacity_logits, sh0, shN)

    @classmethod
    def random_in_frusta(cls, camera: PinholeCamera, c2w: torch.Tensor, n: int, near: float,
                         far: float, generator: torch.Generator, sh_degree: int = 3,
                         depth_sampling: str = "volume", **kwargs) -> GaussianModel:
        """Grey Gaussians at ``n`` points sampled uniformly in the camera frusta.

        See :func:`fusiongs.camera.frusta.sample_in_frusta` (``c2w`` ``[C, 4, 4]``, depths in
        ``[near, far]``, ``depth_sampling``) and :meth:`from_points` (``kwargs``: init_opacity,
        init_scale, k). The
        model is float32 on ``c2w``'s device.
        """
        xyz = sample_in_frusta(camera, c2w, n, near, far, generator, depth_sampling).float()
        return cls.from_points(xyz, None, sh_degree, where="random init", **kwargs)
