"""Plane-sweep stereo on posed images: per-pixel depth of a reference view.

Used to place the initial Gaussians on the scene's surfaces (from EDI-deblurred frames) instead of
scattering them through the frusta. The method is classic fronto-parallel plane sweeping (Collins,
"A space-sweep approach to true multi-image matching", CVPR 1996): for each depth hypothesis ``d``
the reference pixel ``u`` is back-projected to ``X = d K⁻¹ [u, 1]`` and every source image is sampled
where ``X`` projects; the matching cost is the absolute difference on gamma-compressed intensities,
aggregated over the best half of the sources (robust to occlusion, as in Kang, Szeliski and Chai,
CVPR 2001) and box-filtered over a window; the depth is the arg-min, refined by a parabola through
the neighbouring hypotheses. Conventions: pixel centres at integer + 0.5 (as
:class:`~fusiongs.camera.pinhole.PinholeCamera`), OpenCV camera axes (z forward), no distortion.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.camera.reproject import pixel_rays
from fusiongs.errors import InputError

WHERE = "stereo init"


def inverse_depth_planes(near: float, far: float, n: int) -> torch.Tensor:
    """``[n]`` float64 depths uniform in inverse depth from ``near`` to ``far`` (both included)."""
    if not (0 < near < far):
        raise InputError(WHERE, "near/far", "0 < near < far", f"{near}, {far}")
    if n < 2:
        raise InputError(WHERE, "n_planes", "an integer >= 2", n)
    return 1.0 / torch.linspace(1.0 / near, 1.0 / far, n, dtype=torch.float64)


def _check(images: torch.Tensor, c2w: torch.Tensor, camera: PinholeCamera, name: str) -> None:
    if images.ndim != 4 or images.shape[1:3] != (camera.height, camera.width):
        raise InputError(WHERE, name, f"[N, {camera.height}, {camera.width}, C] images",
                         tuple(images.shape))
    if c2w.shape != (images.shape[0], 4, 4):
        raise InputError(WHERE, f"{name} poses", f"[{images.shape[0]}, 4, 4] camera-to-world",
                         tuple(c2w.shape))


SORTING_NETWORK_MAX = 8  # up to this many sources, an elementwise sorting network beats topk


def smallest_mean(x: torch.Tensor, keep: int) -> torch.Tensor:
    """Mean of the ``keep`` smallest of ``x [S, ...]`` along its first axis (``inf`` allowed).

    Up to :data:`SORTING_NETWORK_MAX` rows, an odd-even transposition sort of the rows (``S``
    rounds of elementwise minimum / maximum; Knuth, TAOCP vol. 3, §5.3.4), about 10x faster than
    ``topk`` over a short strided axis on a CPU; ``topk`` beyond.
    """
    n = x.shape[0]
    if keep == n:
        return x.mean(0)
    if n > SORTING_NETWORK_MAX:
        return x.topk(keep, dim=0, largest=False).values.mean(0)
    rows = list(x.unbind(0))
    for r in range(n):
        for i in range(r % 2, n - 1, 2):
            rows[i], rows[i + 1] = torch.minimum(rows[i], rows[i + 1]), torch.maximum(rows[i], rows[i + 1])
    return torch.stack(rows[:keep]).mean(0)


def plane_sweep_cost(ref: torch.Tensor, ref_c2w: torch.Tensor, src: torch.Tensor, src_c2w: torch.Tensor,
                     camera: PinholeCamera, depths: torch.Tensor, window: int = 5) -> torch.Tensor:
    """Matching cost of every depth hypothesis at every reference pixel.

    Args:
        ref: ``[H, W, C]`` reference image (linear, >= 0).
        ref_c2w: ``[4, 4]`` its camera-to-world pose.
        src: ``[S, H, W, C]`` source images, ``S >= 1``.
        src_c2w: ``[S, 4, 4]`` their poses.
        camera: shared intrinsics (ideal pinhole).
        depths: ``[D]`` depth hypotheses along the reference optical axis (scene units).
        window: side of the square box filter over the cost (odd, pixels).

    Returns:
        ``[D, H, W]`` float32 cost: mean absolute difference of ``x^(1/2.2)`` over channels, averaged
        over the ``ceil(S/2)`` best sources; ``inf`` where fewer valid sources see the point.
    """
    _check(ref[None], ref_c2w[None], camera, "reference")
    _check(src, src_c2w, camera, "sources")
    if window < 1 or window % 2 == 0:
        raise InputError(WHERE, "window", "an odd number of pixels >= 1", window)
    dev = ref.device
    gamma = 1 / 2.2
    r = ref.clamp_min(0).pow(gamma).float().permute(2, 0, 1)[None]      # [1, C, H, W]
    s = src.to(dev).clamp_min(0).pow(gamma).float().permute(0, 3, 1, 2)  # [S, C, H, W]
    if r.shape[1] > 1 and bool((r == r[:, :1]).all()) and bool((s == s[:, :1]).all()):
        r, s = r[:, :1], s[:, :1]  # grey frames stored as RGB: one channel has the same mean
    h, w = camera.height, camera.width
    # the source pixel of reference ray a at depth d, as grid_sample's normalised coordinates:
    # g = (A d + t)_xy / (A d + t)_z + o, with A = diag(2fx/w, 2fy/h, 1) R K^-1 [u, 1] per source
    # (float64 here, float32 per plane: 1e-6 of a pixel at these sizes)
    w2s = torch.linalg.inv(src_c2w.double().to(dev)) @ ref_c2w.double().to(dev)  # ref cam -> source cam
    scale = torch.tensor([2 * camera.fx / w, 2 * camera.fy / h, 1.0], dtype=torch.float64, device=dev)
    a = (torch.einsum("sij,pj->spi", w2s[:, :3, :3], pixel_rays(camera, dev).reshape(-1, 3))
         * scale).float()                                               # [S, P, 3]
    t = (w2s[:, None, :3, 3] * scale).float()                           # [S, 1, 3]
    o = torch.tensor([2 * camera.cx / w - 1, 2 * camera.cy / h - 1], dtype=torch.float32, device=dev)
    n_s, keep = src.shape[0], (src.shape[0] + 1) // 2
    out = torch.empty(len(depths), h, w, dtype=torch.float32, device=dev)
    for k, d in enumerate(depths.tolist()):                             # loop over planes only
        x = torch.add(t, a, alpha=d)                                    # [S, P, 3]: A d + t
        z = x[..., 2:]
        grid = x[..., :2] / z.clamp_min(1e-6) + o
        inside = (z[..., 0] > 1e-6) & (grid.abs() <= 1).all(-1)        # [S, P]
        warped = F.grid_sample(s, grid.reshape(n_s, h, w, 2), mode="bilinear", padding_mode="border",
                               align_corners=False)
        diff = (warped - r).abs_().mean(1)                              # [S, H, W]
        diff.masked_fill_(~inside.reshape(n_s, h, w), float("inf"))
        out[k] = smallest_mean(diff, keep)
    finite = torch.isfinite(out)
    filled = torch.where(finite, out, torch.zeros_like(out))[:, None]
    num = F.avg_pool2d(filled, window, 1, window // 2, count_include_pad=False)[:, 0]
    den = F.avg_pool2d(finite.float()[:, None], window, 1, window // 2, count_include_pad=False)[:, 0]
    return torch.where(finite, num / den.clamp_min(1e-6), torch.full_like(out, float("inf")))


def depth_from_cost(cost: torch.Tensor, depths: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Arg-min depth with parabolic sub-plane refinement in inverse depth, and a confidence.

    Args:
        cost: ``[D, H, W]`` from :func:`plane_sweep_cost`.
        depths: ``[D]`` the hypotheses (uniform in inverse depth).

    Returns:
        ``(depth [H, W], confidence [H, W])`` float32; confidence is
        ``(median cost - min cost) / median cost`` in [0, 1] (0: flat, untextured or unseen).
    """
    d_n = cost.shape[0]
    k = cost.argmin(0)                                                  # [H, W]
    c0 = cost.gather(0, k[None])[0]
    km, kp = (k - 1).clamp_min(0), (k + 1).clamp_max(d_n - 1)
    cm, cp = cost.gather(0, km[None])[0], cost.gather(0, kp[None])[0]
    curv = cm - 2 * c0 + cp
    interior = (k > 0) & (k < d_n - 1) & torch.isfinite(curv) & (curv > 0)
    offset = torch.where(interior, 0.5 * (cm - cp) / torch.where(interior, curv, torch.ones_like(curv)),
                         torch.zeros_like(c0)).clamp(-0.5, 0.5)
    inv = 1.0 / depths.double()
    step = (inv[-1] - inv[0]) / (d_n - 1)
    depth = 1.0 / (inv[k] + offset.double() * step)
    finite_cost = torch.where(torch.isfinite(cost), cost, torch.full_like(cost, float("nan")))
    med = finite_cost.nanmedian(0).values
    conf = ((med - c0) / med.clamp_min(1e-6)).nan_to_num(0.0).clamp(0.0, 1.0)
    conf = torch.where(torch.isfinite(c0), conf, torch.zeros_like(conf))
    return depth.float(), conf.float()


def unproject(depth: torch.Tensor, c2w: torch.Tensor, camera: PinholeCamera) -> torch.Tensor:
    """``[H, W, 3]`` world points of a ``[H, W]`` depth map (depth along the optical axis)."""
    p = pixel_rays(camera, depth.device) * depth.double()[..., None]
    c2w = c2w.to(depth.device, torch.float64)
    return (p @ c2w[:3, :3].T + c2w[:3, 3]).float()


def neighbour_indices(n: int, i: int, offsets: tuple[int, ...]) -> list[int]:
    """Indices ``i + o`` inside ``[0, n)`` for the given offsets (no duplicates, never ``i``)."""
    return sorted({i + o for o in offsets if o != 0 and 0 <= i + o < n})


def stereo_points(images: torch.Tensor, c2w: torch.Tensor, camera: PinholeCamera, near: float,
                  far: float, n_planes: int = 48, window: int = 5, min_confidence: float = 0.3,
                  offsets: tuple[int, ...] = (-3, -2, -1, 1, 2, 3)
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Confident surface points of every view by plane sweeping against its neighbours in the list.

    Args:
        images: ``[N, H, W, C]`` linear images (e.g. EDI-deblurred frames), ``N >= 2``.
        c2w: ``[N, 4, 4]`` their camera-to-world poses.
        camera: intrinsics.
        near, far: depth range searched (scene units).
        n_planes: depth hypotheses, uniform in inverse depth.
        window: box-filter side of the cost.
        min_confidence: pixels with a lower :func:`depth_from_cost` confidence are dropped.
        offsets: index offsets of each view's source views; sources whose camera centre is
            closer than ``0.5 near / f`` (half a pixel of parallax at the nearest plane) are
            skipped, and a view without any source gives no points.

    Returns:
        ``(xyz [M, 3], colour [M, C], confidence [M])`` float32 on the CPU; ``colour`` is the
        reference pixel's (linear) value.
    """
    images = torch.as_tensor(images).detach().cpu()
    c2w = torch.as_tensor(c2w).detach().cpu()
    _check(images, c2w, camera, "images")
    if images.shape[0] < 2:
        raise InputError(WHERE, "images", "at least 2 posed images", images.shape[0])
    if not 0 <= min_confidence < 1:
        raise InputError(WHERE, "min_confidence", "a number in [0, 1)", min_confidence)
    depths = inverse_depth_planes(near, far, n_planes)
    pts, cols, confs = [], [], []
    n = images.shape[0]
    centres = c2w[:, :3, 3].double()
    # a source view must shift the nearest plane by half a pixel (f b / near >= 0.5): a static or
    # purely rotating camera gives no depth, and sweeping it would only cost time
    min_baseline = 0.5 * near / max(float(camera.fx), float(camera.fy))
    for i in range(n):                                                  # loop over views only
        nb = neighbour_indices(n, i, offsets) or [j for j in range(n) if j != i][:1]
        nb = [j for j in nb if float(torch.linalg.vector_norm(centres[j] - centres[i])) >= min_baseline]
        if not nb:
            continue
        cost = plane_sweep_cost(images[i], c2w[i], images[nb], c2w[nb], camera, depths, window)
        depth, conf = depth_from_cost(cost, depths)
        keep = conf >= min_confidence
        pts.append(unproject(depth, c2w[i], camera)[keep])
        cols.append(images[i].float()[keep])
        confs.append(conf[keep])
    if not pts:  # no view had a source with parallax
        c = images.shape[-1]
        return torch.zeros(0, 3), torch.zeros(0, c), torch.zeros(0)
    return torch.cat(pts), torch.cat(cols), torch.cat(confs)


def nearest_camera_distance(xyz: torch.Tensor, centres: torch.Tensor) -> torch.Tensor:
    """``[M]`` float64 distance of each point ``xyz [M, 3]`` to the nearest camera centre ``[N, 3]``."""
    return torch.cdist(xyz.double(), centres.double().to(xyz.device)).amin(1)


def far_bound(dist: torch.Tensor, least: float, most: float, quantile: float = 0.9,
              margin: float = 1.25) -> float:
    """A scene's far bound from its stereo points: ``margin`` times the ``quantile`` of their
    distances to the nearest camera centre, never below ``least`` nor above ``most``.

    A high quantile rather than the maximum: a plane sweep that reaches far beyond the scene puts
    its few weakly textured or low-parallax matches at the farthest planes.

    Args:
        dist: ``[M]`` the points' distances (:func:`nearest_camera_distance` of e.g.
            :func:`stereo_points`), scene units.
        least, most: clamp of the bound (``least`` alone when there are no points).

    Returns:
        The far bound (scene units).
    """
    if dist.numel() == 0:
        return float(least)
    k = min(max(1, round(quantile * dist.numel())), dist.numel())  # kthvalue: no size limit
    q = float(dist.kthvalue(k).values)
    return float(min(max(margin * q, least), most))
