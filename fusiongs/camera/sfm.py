"""Camera poses from images with pycolmap (METHOD.md §6), and similarity alignment of trajectories.

When a scene has no trajectory, sharp frames (EDI results, or truth in a simulation) are registered
by COLMAP's incremental structure from motion with the known pinhole intrinsics held fixed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError, MissingDependencyError


def estimate_poses(image_dir: str | Path, camera: PinholeCamera, work_dir: str | Path, *,
                   sequential: bool = True, threads: int = 2, seed: int = 0) -> dict[str, np.ndarray]:
    """Register the images of ``image_dir`` with pycolmap (SIFT, fixed PINHOLE intrinsics).

    Args:
        image_dir: folder of images (all of them are used; names order a sequence).
        camera: the known intrinsics (``PINHOLE fx, fy, cx, cy``), not refined.
        work_dir: folder for COLMAP's database and sparse model (created; a previous database is
            replaced).
        sequential: sequential matching (video order) instead of exhaustive.
        threads, seed: COLMAP's CPU threads and random seed.

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
    if sequential:
        pycolmap.match_sequential(db, device=pycolmap.Device.cpu)
    else:
        pycolmap.match_exhaustive(db, device=pycolmap.Device.cpu)
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
