"""Input checks for :func:`fusiongs.render.rasterize` (raise ``InputError`` naming the argument)."""

from __future__ import annotations

import torch
from torch import Tensor

from fusiongs.errors import InputError
from fusiongs.render.sh import num_sh_bases

WHERE = "rasterize"
BACKENDS = ("auto", "torch", "cpu", "gsplat")


def _shape(t: Tensor) -> str:
    return f"shape {list(t.shape)}"


def _tensor(name: str, t: object, expected: str) -> Tensor:
    if not isinstance(t, Tensor):
        raise InputError(WHERE, name, f"a torch.Tensor of {expected}", type(t).__name__)
    return t


def check_inputs(means, quats, scales, opacities, colors, viewmats, Ks, width, height, sh_degree,
                 backgrounds, near_plane, far_plane, backend, check_values: bool = True
                 ) -> tuple[int, int, int]:
    """Validate the arguments of ``rasterize``; returns ``(C, N, D)``.

    ``check_values=False`` skips the checks that read tensor values (finite, opacity range,
    non-zero quaternions): each is a host synchronisation on a GPU.
    """
    means = _tensor("means", means, "shape [N, 3]")
    if means.dim() != 2 or means.shape[1] != 3:
        raise InputError(WHERE, "means", "shape [N, 3]", _shape(means))
    N = means.shape[0]
    fixed = {"quats": (quats, (N, 4), "[N, 4] (wxyz)"), "scales": (scales, (N, 3), "[N, 3]"),
             "opacities": (opacities, (N,), "[N]")}
    for name, (t, shape, text) in fixed.items():
        t = _tensor(name, t, f"shape {text}")
        if tuple(t.shape) != shape:
            raise InputError(WHERE, name, f"shape {text} with N={N} (from means)", _shape(t))
    viewmats = _tensor("viewmats", viewmats, "shape [C, 4, 4]")
    if viewmats.dim() != 3 or tuple(viewmats.shape[1:]) != (4, 4):
        raise InputError(WHERE, "viewmats", "shape [C, 4, 4] (world->camera)", _shape(viewmats))
    C = viewmats.shape[0]
    Ks = _tensor("Ks", Ks, "shape [C, 3, 3]")
    if tuple(Ks.shape) != (C, 3, 3):
        raise InputError(WHERE, "Ks", f"shape [C, 3, 3] with C={C} (from viewmats)", _shape(Ks))
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
            raise InputError(WHERE, name, "a positive integer", repr(v))
    colors = _tensor("colors", colors, "shape [N, D], [C, N, D] or SH [N, K, 3]")
    if sh_degree is None:
        if not (colors.dim() == 2 and colors.shape[0] == N) and not (
                colors.dim() == 3 and tuple(colors.shape[:2]) == (C, N)):
            raise InputError(WHERE, "colors", f"shape [N, D] or [C, N, D] with N={N}, C={C} "
                             "(or pass sh_degree for SH coefficients [N, K, 3])", _shape(colors))
        D = colors.shape[-1]
    else:
        if isinstance(sh_degree, bool) or not isinstance(sh_degree, int) or not 0 <= sh_degree <= 3:
            raise InputError(WHERE, "sh_degree", "None or an integer 0..3", repr(sh_degree))
        K = num_sh_bases(sh_degree)
        if colors.dim() != 3 or colors.shape[0] != N or colors.shape[2] != 3 or colors.shape[1] < K:
            raise InputError(WHERE, "colors", f"SH coefficients of shape [N, K, 3] with N={N}, "
                             f"K >= {K} for sh_degree={sh_degree}", _shape(colors))
        D = 3
    if D < 1:
        raise InputError(WHERE, "colors", "at least one channel", _shape(colors))
    named = {"means": means, "quats": quats, "scales": scales, "opacities": opacities,
             "colors": colors, "viewmats": viewmats, "Ks": Ks}
    if backgrounds is not None:
        backgrounds = _tensor("backgrounds", backgrounds, f"shape [C, D] = [{C}, {D}]")
        if tuple(backgrounds.shape) != (C, D):
            raise InputError(WHERE, "backgrounds", f"shape [C, D] = [{C}, {D}]", _shape(backgrounds))
        named["backgrounds"] = backgrounds
    for name, t in named.items():
        if not t.is_floating_point() or t.dtype != means.dtype:
            raise InputError(WHERE, name, f"floating dtype {means.dtype} (as means)", str(t.dtype))
        if t.device != means.device:
            raise InputError(WHERE, name, f"device {means.device} (as means)", str(t.device))
        if check_values and not bool(torch.isfinite(t).all()):
            raise InputError(WHERE, name, "finite values", "NaN or inf")
    if check_values and not bool(((opacities >= 0) & (opacities <= 1)).all()):
        raise InputError(WHERE, "opacities", "activated opacities in [0, 1]",
                         f"range [{float(opacities.min()):g}, {float(opacities.max()):g}]")
    if check_values and N and not bool((quats.norm(dim=-1) > 0).all()):
        raise InputError(WHERE, "quats", "non-zero quaternions", "a zero-norm row")
    if not 0 <= near_plane < far_plane:
        raise InputError(WHERE, "near_plane/far_plane", "0 <= near_plane < far_plane",
                         f"{near_plane}, {far_plane}")
    if backend not in BACKENDS:
        raise InputError(WHERE, "backend", f"one of {BACKENDS}", repr(backend))
    return C, N, D
