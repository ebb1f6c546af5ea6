"""Camera poses from images with pycolmap (docs/method.md §6), and similarity alignment of trajectories.

When a scene has no trajectory, sharp frames (EDI results, or truth in a simulation) are registered
by COLMAP's incremental structure from motion with the known pinhole intrinsics held fixed. Without
parallax, the verified matches of a COLMAP database (:func:`verified_matches`) give the rotation
between two views (:func:`pair_rotation`) and a chain of them a rotation-only path
(:func:`chain_rotations`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError, MissingDependencyError


def estimate_poses(image_dir: str | Path, camera: PinholeCamera, work_dir: str | Path, *,
                   sequential: bool = True, threads: int = 1, seed: int = 0) -> dict[str, np.ndarray]:
    """Register the images of ``image_dir`` with pycolmap (SIFT, fixed PINHOLE intrinsics).

    Args:
        image_dir: folder of images (all of them are used; names order a sequence).
        camera: the known intrinsics (``PINHOLE fx, fy, cx, cy``), not refined.
        work_dir: folder for COLMAP's database and sparse model (created; a previous database is
            replaced).
        sequential: sequential matching (video order) instead of exhaustive.
        threads, seed: COLMAP's CPU threads and random seed (one thread: the same poses on every
            run; COLMAP's matching with several threads is not deterministic).

    Returns:
        ``{image stem: c2w [4, 4] float64}`` for the registered images of the largest model, in
        COLMAP's arbitrary frame and scale (OpenCV camera axes).
    """
    try:
        import pycolmap
    except ImportError:  # pragma: no cover - a core dependency
        raise MissingDependencyError("pycolmap", "pose estimation") from None
    image_dir, work = Path(image_dir), Path(work_dir)
    if not image_dir.is_dir():
        raise InputError(image_dir, "images", "a folder of images", "not found")
    work.mkdir(parents=True, exist_ok=True)
    db = work / "database.db"
    db.unlink(missing_ok=True)
    (work / "sparse").mkdir(exist_ok=True)
    pycolmap.logging.minloglevel = 1
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "PINHOLE"
    reader.camera_params = f"{camera.fx},{camera.fy},{camera.cx},{camera.cy}"
    extract = pycolmap.FeatureExtractionOptions()
    extract.num_threads = threads
    pycolmap.extract_features(db, image_dir, camera_mode=pycolmap.CameraMode.SINGLE,
                              reader_options=reader, extraction_options=extract,
                              device=pycolmap.Device.cpu)
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = threads
    match = pycolmap.match_sequential if sequential else pycolmap.match_exhaustive
    match(db, matching_options=matching, device=pycolmap.Device.cpu)
    opts = pycolmap.IncrementalPipelineOptions()
    opts.ba_refine_focal_length = False
    opts.ba_refine_principal_point = False
    opts.num_threads = threads
    opts.random_seed = seed
    recs = pycolmap.incremental_mapping(db, image_dir, work / "sparse", options=opts)
    if not recs:
        return {}
    best = max(recs.values(), key=lambda r: r.num_reg_images())
    out = {}
    for im in best.images.values():
        w2c = np.eye(4)
        w2c[:3, :] = np.asarray(im.cam_from_world().matrix())
        out[Path(im.name).stem] = np.linalg.inv(w2c)
    return out


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity ``dst ≈ s R src + t`` minimising squared error (Umeyama, IEEE TPAMI 1991).

    Args:
        src, dst: ``[M, 3]`` corresponding points, M >= 3, not collinear.

    Returns:
        ``(s, R [3, 3], t [3])``.
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or src.shape[0] < 3:
        raise InputError("umeyama", "points", "two [M, 3] arrays with M >= 3", (src.shape, dst.shape))
    mu_s, mu_d = src.mean(0), dst.mean(0)
    u, d, vt = np.linalg.svd((dst - mu_d).T @ (src - mu_s) / len(src))
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ flip @ vt
    scale = float(np.trace(np.diag(d) @ flip) / ((src - mu_s) ** 2).sum(1).mean())
    return scale, rot, mu_d - scale * rot @ mu_s


def align_sim3(est_c2w: np.ndarray, true_c2w: np.ndarray, rotation_weight: float = 1.0
               ) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity that carries an estimated camera path onto the true one: ``true ≈ s R est + t``.

    Umeyama's closed form on the camera centres, with the orientations added to the
    cross-covariance so that the rotation stays determined when the centres lie nearly on a line
    (a sideways pan): the rotation maximises ``corr(R, centres) + rotation_weight x mean_i
    tr(R_true_i^T R R_est_i) / 3``, where ``corr`` is the centred centres' cross-covariance
    normalised by both spreads (1 for a perfect fit); scale and translation then minimise the
    squared centre error for that rotation. ``rotation_weight = 0`` is plain Umeyama.

    Args:
        est_c2w, true_c2w: ``[N, 4, 4]`` camera-to-world poses at the same instants, N >= 2.
        rotation_weight: weight of the orientations (0: centres only, then N >= 3, not collinear).

    Returns:
        ``(s, R [3, 3], t [3])``.
    """
    est, true = np.asarray(est_c2w, np.float64), np.asarray(true_c2w, np.float64)
    if est.shape != true.shape or est.ndim != 3 or est.shape[1:] != (4, 4) or est.shape[0] < 2:
        raise InputError("align_sim3", "poses", "two [N, 4, 4] arrays with N >= 2",
                         (est.shape, true.shape))
    if rotation_weight <= 0:
        return umeyama(est[:, :3, 3], true[:, :3, 3])
    a, b = est[:, :3, 3], true[:, :3, 3]
    da, db = a - a.mean(0), b - b.mean(0)
    var_a, var_b = (da ** 2).sum(1).mean(), (db ** 2).sum(1).mean()
    cov = db.T @ da / len(a)
    spread = np.sqrt(var_a * var_b)
    h = (cov / spread if spread > 0 else 0.0) + rotation_weight / 3 * np.einsum(
        "nij,nkj->ik", true[:, :3, :3], est[:, :3, :3]) / len(a)
    u, _, vt = np.linalg.svd(h)
    rot = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    scale = float(np.einsum("ij,ij->", cov, rot) / var_a) if var_a > 0 else 1.0
    return scale, rot, b.mean(0) - scale * rot @ a.mean(0)


def pose_errors(est_c2w: np.ndarray, true_c2w: np.ndarray, rotation_weight: float = 1.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per-pose errors of an estimated path after :func:`align_sim3`.

    Returns:
        ``(position [N] in the true path's units, rotation [N] in degrees)``: the distance between
        the aligned and the true camera centres, and the angle of ``R_true^T R R_est``.
    """
    s, rot, t = align_sim3(est_c2w, true_c2w, rotation_weight)
    est, true = np.asarray(est_c2w, np.float64), np.asarray(true_c2w, np.float64)
    pos = np.linalg.norm(s * est[:, :3, 3] @ rot.T + t - true[:, :3, 3], axis=1)
    rel = np.einsum("nji,jk,nkl->nil", true[:, :3, :3], rot, est[:, :3, :3])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    return pos, np.degrees(np.arccos(cos))


def verified_matches(database: str | Path, files: list[str]
                     ) -> dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]:
    """Inlier matches of every geometrically verified pair of a COLMAP database.

    Args:
        database: ``database.db`` after feature matching.
        files: image names in the order to index them.

    Returns:
        ``{(i, j): (xy_i [M, 2], xy_j [M, 2])}`` with ``i < j`` indices into ``files`` and the
        matched keypoints in pixels (COLMAP's convention: pixel centres at +0.5).
    """
    import pycolmap

    db = pycolmap.Database.open(str(database))
    try:
        index = {im.image_id: files.index(im.name) for im in db.read_all_images() if im.name in files}
        keys = {i: np.asarray(db.read_keypoints(i))[:, :2] for i in index}
        out = {}
        for pair_id, geom in zip(*db.read_two_view_geometries()):
            a, b = pycolmap.pair_id_to_image_pair(pair_id)
            m = np.asarray(geom.inlier_matches).reshape(-1, 2)
            if a not in index or b not in index or not len(m):
                continue
            xa, xb = keys[a][m[:, 0]].astype(np.float64), keys[b][m[:, 1]].astype(np.float64)
            i, j = index[a], index[b]
            out[(i, j) if i < j else (j, i)] = (xa, xb) if i < j else (xb, xa)
    finally:
        db.close()
    return out


def pair_rotation(xy_i: np.ndarray, xy_j: np.ndarray, K: np.ndarray, trim: float = 3.0
                  ) -> tuple[np.ndarray, float, int]:
    """Rotation of camera j relative to camera i from matched pixels, assuming no translation.

    Wahba's problem on the unit rays ``K^-1 [x, 1]``: ``R`` maximises ``sum r_j . R r_i`` (SVD),
    then once more on the matches whose angle residual is within ``trim`` times the median
    (matches on moving things drop out).

    Args:
        xy_i, xy_j: ``[M, 2]`` matched pixel positions in images i and j (M >= 3).
        K: ``[3, 3]`` intrinsics.
        trim: residual factor of the second pass.

    Returns:
        ``(R [3, 3] camera j from camera i, median residual angle in rad, matches kept)``.
    """
    if len(xy_i) < 3 or xy_i.shape != xy_j.shape:
        raise InputError("pair_rotation", "matches", "two [M, 2] arrays with M >= 3",
                         (np.shape(xy_i), np.shape(xy_j)))
    k_inv = np.linalg.inv(np.asarray(K, np.float64))

    def rays(xy):
        r = np.c_[xy, np.ones(len(xy))] @ k_inv.T
        return r / np.linalg.norm(r, axis=1, keepdims=True)

    ri, rj = rays(xy_i), rays(xy_j)
    keep = np.ones(len(ri), bool)
    for _ in range(2):
        u, _, vt = np.linalg.svd(rj[keep].T @ ri[keep])
        rot = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
        rr = ri @ rot.T  # the angle from atan2(|cross|, dot): arccos of a dot product near 1 has
        # a floor of ~1.5e-8 rad, above the 1e-9 floor below, so exact matches read 0 or 1.5e-8
        res = np.arctan2(np.linalg.norm(np.cross(rj, rr), axis=1), np.einsum("nk,nk->n", rj, rr))
        med = float(np.median(res[keep]))
        keep = res <= max(trim * med, 1e-9)
    return rot, med, int(keep.sum())


def chain_rotations(n: int, links: dict[tuple[int, int], tuple[np.ndarray, float]]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Camera-to-world rotations of ``n`` views from pairwise ones along a maximum spanning tree.

    Args:
        n: number of views.
        links: ``{(i, j): (R camera j from camera i, weight)}``; the heaviest links are used.

    Returns:
        ``(linked [n] bool, R_c2w [n, 3, 3])``: the views of the largest connected group, the
        first of them with the identity; the others are not linked (identity rotation).
    """
    import heapq

    rot = np.tile(np.eye(3), (n, 1, 1))
    best = np.zeros(n, bool)
    adj: dict[int, list[tuple[float, int, int]]] = {}
    for (i, j), (_, w) in links.items():
        adj.setdefault(i, []).append((w, i, j))
        adj.setdefault(j, []).append((w, j, i))
    done = np.zeros(n, bool)
    for root in range(n):
        if done[root]:
            continue
        seen = np.zeros(n, bool)
        seen[root] = True
        group = np.tile(np.eye(3), (n, 1, 1))
        heap = [(-w, a, b) for w, a, b in adj.get(root, [])]
        heapq.heapify(heap)
        while heap:
            _, a, b = heapq.heappop(heap)
            if seen[b]:
                continue
            r_ab = links[(a, b)][0] if (a, b) in links else links[(b, a)][0].T  # camera b from a
            group[b] = group[a] @ r_ab.T
            seen[b] = True
            for w, c, d in adj.get(b, []):
                if not seen[d]:
                    heapq.heappush(heap, (-w, c, d))
        done |= seen
        if seen.sum() > best.sum():
            best, rot = seen, group
    first = int(np.argmax(best))
    return best, np.einsum("ij,njk->nik", rot[first].T, rot)


def is_static(links: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]], tol_px: float,
              min_matches: int) -> bool:
    """Whether the camera stood still: every pair of :func:`verified_matches` with at least
    ``min_matches`` matches (one pair at least) has a median match shift below ``tol_px``."""
    shifts = [float(np.median(np.linalg.norm(a - b, axis=1))) for a, b in links.values()
              if len(a) >= min_matches]
    return bool(shifts) and max(shifts) < tol_px


def rotation_only_poses(links: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]], n: int,
                        K: np.ndarray, *, static: bool = False, min_matches: int = 15
                        ) -> tuple[np.ndarray, np.ndarray, float]:
    """Poses of a camera without translation from the matches of :func:`verified_matches`.

    Pairs with at least ``min_matches`` matches (after :func:`pair_rotation`'s trimming) link
    their images; rotations are chained by :func:`chain_rotations` (all identity when ``static``).

    Returns:
        ``(linked [n] bool, c2w [n, 4, 4], median angle residual of the pair fits in rad)``.
    """
    fits, residuals = {}, []
    for pair, (a, b) in links.items():
        if len(a) < min_matches:
            continue
        rot, res, kept = pair_rotation(a, b, K)
        if kept >= min_matches:
            fits[pair] = (np.eye(3) if static else rot, float(kept))
            residuals.append(res)
    linked, rots = chain_rotations(n, fits)
    c2w = np.tile(np.eye(4), (n, 1, 1))
    c2w[:, :3, :3] = rots
    return linked, c2w, float(np.median(residuals)) if residuals else float("nan")
