"""Gaussian PLY files in the Inria 3DGS layout (read by common 3DGS viewers).

One ``vertex`` element, binary little-endian float32 properties in this order::

    x y z nx ny nz f_dc_0..2 f_rest_0..(3(K-1)-1) opacity scale_0..2 rot_0..3

Values are raw (pre-activation): opacity as logit, scales as log, rotation ``(w, x, y, z)``
unnormalised, normals zero. ``f_rest`` is channel-major: the ``K-1`` red coefficients, then green,
then blue (Inria transposes ``[N, K-1, 3]`` to ``[N, 3, K-1]`` before flattening), so
``f_rest_{c (K-1) + j}`` is band coefficient ``j + 1`` of channel ``c``; ``f_dc_c`` is channel c.
The active SH degree is not stored: a loaded model renders with all its bands.

Colours are stored for display. fusiongs renders linear light (sRGB primaries) and shows it
sRGB-encoded; 3DGS viewers (SuperSplat, the gsplat and nerfstudio viewers) show
``SH_C0 * f_dc + 0.5`` (plus the ``f_rest`` terms) directly as the display colour. So with ``c =
SH_C0 * sh0 + 0.5`` the linear base colour of a channel and ``S`` the sRGB encoding
(:func:`fusiongs.frames.response.linear_to_srgb`, IEC 61966-2-1, its linear segment continued
below 0 and its power law above 1, which keeps it invertible on every real)::

    f_dc   = (S(c) - 0.5) / SH_C0          so  clip(SH_C0 f_dc + 0.5, 0, 1) = S(clip(c, 0, 1))
    f_rest = S'(c) * shN                   (first order: the display change of view dependence)

which is exactly what ``fusiongs deblur`` shows for one Gaussian's base colour. :func:`load_ply`
inverts both (``sh0`` from ``S^-1``, ``shN`` divided by the same slope), so a write/read round trip
returns the model up to float32 rounding; a PLY of another tool (trained on sRGB images) loads
as the equivalent linear model.

Per Gaussian this is exact, but a viewer composites the display values, ``sum_i w_i S(c_i)``,
where fusiongs shows ``S(sum_i w_i c_i)``: wherever Gaussians of different colours overlap the
two differ. ``fusiongs deblur`` therefore writes ``model.ply`` from a copy whose colours and
opacities were fitted for display-space compositing (:mod:`fusiongs.outputs.display_ply`), with
``save_ply(..., colours="display")``; ``load_ply(..., colours="display")`` reads such coefficients
back as they are stored.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from fusiongs.atomic import atomic_path
from fusiongs.errors import InputError
from fusiongs.frames.response import linear_to_srgb, srgb_to_linear
from fusiongs.scene.gaussians import SH_C0, GaussianModel

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}


def _property_names(k: int) -> list[str]:
    return (["x", "y", "z", "nx", "ny", "nz"] + [f"f_dc_{i}" for i in range(3)]
            + [f"f_rest_{i}" for i in range(3 * (k - 1))] + ["opacity"]
            + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)])


def _srgb_and_slope(c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(S(c), S'(c))`` elementwise; the slope is kept >= 1e-6 (so dividing by it is safe)."""
    with torch.enable_grad():
        x = c.detach().clone().requires_grad_(True)
        d = linear_to_srgb(x)
        (slope,) = torch.autograd.grad(d.sum(), x)
    return d.detach(), slope.clamp_min(1e-6)


def display_sh(sh0: torch.Tensor, shN: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """PLY colour coefficients of a linear-light model (see the module docstring).

    Args:
        sh0: ``[N, 1, 3]`` DC coefficients (linear colour ``SH_C0 * sh0 + 0.5``).
        shN: ``[N, K-1, 3]`` higher bands.

    Returns:
        ``(f_dc [N, 3], f_rest [N, K-1, 3])`` in float64: ``SH_C0 * f_dc + 0.5`` is the sRGB-encoded
        colour, ``f_rest`` the bands scaled by the slope of the encoding at the base colour.
    """
    c = sh0[:, 0].detach().double() * SH_C0 + 0.5
    d, slope = _srgb_and_slope(c)
    return (d - 0.5) / SH_C0, shN.detach().double() * slope[:, None, :]


def linear_sh(f_dc: torch.Tensor, f_rest: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Inverse of :func:`display_sh`: ``(sh0 [N, 1, 3], shN [N, K-1, 3])`` in float64."""
    c = srgb_to_linear(f_dc.double() * SH_C0 + 0.5)
    _, slope = _srgb_and_slope(c)
    return ((c - 0.5) / SH_C0)[:, None, :], f_rest.double() / slope[:, None, :]


COLOURS = ("linear", "display")  # what the SH coefficients of a model given to save_ply hold


def save_ply(model: GaussianModel, path: str | Path, *, colours: str = "linear", comment: str = "") -> None:
    """Write ``model`` as an Inria-layout binary PLY, atomically (temporary file, then rename).

    Args:
        model: the Gaussians.
        path: the file to write.
        colours: ``"linear"``: ``model`` is a linear-light model (fusiongs' own) and its colours are
            written as display coefficients by :func:`display_sh` (see the module docstring);
            ``"display"``: its SH coefficients already are display values (e.g. fitted for
            display-space compositing, :mod:`fusiongs.outputs.display_ply`) and are written as
            they are.
        comment: an optional one-line header comment (ASCII) saying what the file holds.

    Raises:
        InputError: an unknown ``colours``, or a comment that is not one ASCII line.
    """
    if colours not in COLOURS:
        raise InputError("save_ply", "colours", " or ".join(repr(c) for c in COLOURS), repr(colours))
    if not comment.isascii() or "\n" in comment or "\r" in comment:
        raise InputError("save_ply", "comment", "one line of ASCII text", repr(comment))
    path = Path(path)
    k = model.max_sh_degree + 1
    k = k * k
    n = model.n
    with torch.no_grad():
        if colours == "linear":
            f_dc, f_rest = display_sh(model.sh0.cpu(), model.shN.cpu())
        else:
            f_dc, f_rest = model.sh0[:, 0].cpu(), model.shN.cpu()
        cols = [model.means, torch.zeros_like(model.means), f_dc,
                f_rest.transpose(1, 2).reshape(n, -1), model.opacity_logits[:, None],
                model.log_scales, model.quats]
        data = torch.cat([c.detach().float().cpu() for c in cols], 1).numpy()
    names = _property_names(k)
    rec = np.empty(n, dtype=[(name, "<f4") for name in names])
    for i, name in enumerate(names):
        rec[name] = data[:, i]
    header = ("ply\nformat binary_little_endian 1.0\ncomment written by fusiongs\n"
              + (f"comment {comment}\n" if comment else "")
              + f"element vertex {n}\n" + "".join(f"property float {nm}\n" for nm in names)
              + "end_header\n")
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(rec.tobytes())


def _parse_header(path: Path, raw: bytes) -> tuple[int, list[tuple[str, int, np.dtype]]]:
    """Header length and elements ``(name, count, dtype)``; raises InputError on bad headers."""
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise InputError(path, "header", "a PLY file ('ply' ... 'end_header')")
    nl = raw.find(b"\n", end)
    if nl < 0:
        raise InputError(path, "header", "a newline after 'end_header'")
    lines = raw[:end].decode("ascii", errors="replace").splitlines()
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    fmt = None
    for line in lines[1:]:
        parts = line.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format":
            fmt = " ".join(parts[1:])
        elif parts[0] == "element" and len(parts) == 3 and parts[2].isdigit():
            elements.append((parts[1], int(parts[2]), []))
        elif parts[0] == "property" and elements and len(parts) == 3 and parts[1] in _PLY_TYPES:
            elements[-1][2].append((parts[2], "<" + _PLY_TYPES[parts[1]]))
        elif parts[0] == "property" and elements:
            raise InputError(path, f"element {elements[-1][0]}", "scalar properties only", repr(line))
        else:
            raise InputError(path, "header", "valid PLY header lines", repr(line))
    if fmt != "binary_little_endian 1.0":
        raise InputError(path, "format", "binary_little_endian 1.0", fmt)
    return nl + 1, [(name, count, np.dtype(props)) for name, count, props in elements]


def load_ply(path: str | Path, *, colours: str = "linear") -> GaussianModel:
    """Read an Inria-layout Gaussian PLY (properties by name, any order and scalar type).

    Args:
        path: the file.
        colours: ``"linear"``: the file's display colours become a linear-light model
            (:func:`linear_sh`, the inverse of :func:`save_ply`'s conversion); ``"display"``: the
            SH coefficients are returned as stored (what a 3DGS viewer composites).

    Returns:
        A float32 CPU :class:`GaussianModel` with ``active_sh_degree = max_sh_degree``.

    Raises:
        InputError: naming the file and the missing property, bad format, truncated data, or an
            ``f_rest`` count that is not ``3((d+1)^2 - 1)`` for a degree ``d <= 3``; an unknown
            ``colours``.
    """
    if colours not in COLOURS:
        raise InputError("load_ply", "colours", " or ".join(repr(c) for c in COLOURS), repr(colours))
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(path, "file", "a readable PLY file", e.strerror) from None
    offset, elements = _parse_header(path, raw)
    vertex = None
    for name, count, dtype in elements:
        if name == "vertex":
            vertex = (count, dtype)
            break
        offset += count * dtype.itemsize
    if vertex is None:
        raise InputError(path, "element vertex", "present in the header")
    n, dtype = vertex
    if len(raw) < offset + n * dtype.itemsize:
        raise InputError(path, "element vertex", f"{n} records of {dtype.itemsize} bytes",
                         f"{len(raw) - offset} bytes")
    rec = np.frombuffer(raw, dtype=dtype, count=n, offset=offset)
    names = set(dtype.names)
    n_rest = sum(1 for nm in names if nm.startswith("f_rest_"))
    k = n_rest // 3 + 1
    degree = round(math.sqrt(k)) - 1
    if n_rest % 3 or (degree + 1) ** 2 != k or degree > 3:
        raise InputError(path, "f_rest_*", "3((d+1)^2 - 1) properties for an SH degree d <= 3",
                         f"{n_rest} properties")
    for nm in _property_names(k):
        if nm not in names and nm not in ("nx", "ny", "nz"):
            raise InputError(path, f"property {nm}", "present in the vertex element")

    def cols(*keys: str) -> torch.Tensor:
        out = np.empty((n, len(keys)), dtype=np.float32)
        for i, key in enumerate(keys):
            out[:, i] = rec[key]
        return torch.from_numpy(out)

    f_rest = cols(*[f"f_rest_{i}" for i in range(n_rest)]).reshape(n, 3, k - 1).transpose(1, 2)
    f_dc = cols("f_dc_0", "f_dc_1", "f_dc_2")
    sh0, shN = linear_sh(f_dc, f_rest) if colours == "linear" else (f_dc[:, None, :], f_rest)
    return GaussianModel(
        means=cols("x", "y", "z"), log_scales=cols("scale_0", "scale_1", "scale_2"),
        quats=cols("rot_0", "rot_1", "rot_2", "rot_3"), opacity_logits=cols("opacity")[:, 0],
        sh0=sh0.float().contiguous(), shN=shN.float().contiguous(), active_sh_degree=degree)
