"""Running COLMAP (pycolmap, CPU) on a list of images: grey PNGs for SIFT, feature extraction and
matching, incremental mapping with several seeds, and reading poses and points back.

Used by :func:`fusiongs.sfm.register.estimate_camera_and_trajectory`, which prepares the
images (EDI at mid-exposure) and turns the model into a trajectory.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fusiongs.camera.pinhole import PinholeCamera, SceneCamera, UncalibratedCamera
from fusiongs.errors import InputError, MissingDependencyError

if TYPE_CHECKING:
    from fusiongs.sfm.options import PoseOptions


def load_pycolmap():
    try:
        import pycolmap
    except ImportError:  # pragma: no cover - a core dependency
        raise MissingDependencyError("pycolmap", "pose estimation") from None
    return pycolmap


def upscale_factor(width: int, min_width: int) -> int:
    """Integer enlargement for feature extraction: ``ceil(min_width / width)``, 1 to 4."""
    return int(min(max(-(-int(min_width) // max(int(width), 1)), 1), 4))


def write_sfm_images(images: np.ndarray, folder: Path, upscale: int = 1) -> list[str]:
    """Grey 8-bit PNGs for SIFT: luminance scaled by the 99.5th percentile of all images (one
    scale, so brightness changes stay), then sRGB-encoded, enlarged ``upscale`` times (bicubic,
    pixel centres kept: a point at ``u`` moves to ``upscale u``). Returns the file names in order."""
    import cv2

    lum = images.mean(axis=-1).astype(np.float64)
    if upscale > 1:
        h, w = lum.shape[1:3]
        lum = np.stack([cv2.resize(im, (w * upscale, h * upscale), interpolation=cv2.INTER_CUBIC)
                        for im in lum])
    finite = lum[np.isfinite(lum)]
    top = float(np.percentile(finite, 99.5)) if finite.size else 1.0
    lum = np.clip(np.nan_to_num(lum / max(top, 1e-12)), 0.0, 1.0)
    enc = np.where(lum <= 0.0031308, 12.92 * lum, 1.055 * np.power(lum, 1 / 2.4) - 0.055)
    folder.mkdir(parents=True, exist_ok=True)
    files = [f"{i:06d}.png" for i in range(len(images))]
    for f, img in zip(files, np.round(enc * 255).astype(np.uint8)):
        if not cv2.imwrite(str(folder / f), img):
            raise InputError(folder / f, "image", "a writable folder for COLMAP's images", "write failed")
    return files


def match_pairs(files: list[str], overlap: int, loop_stride: int) -> list[tuple[str, str]]:
    """Sequential neighbours within ``overlap`` plus all pairs of every ``loop_stride``-th image."""
    n = len(files)
    pairs = {(i, j) for i in range(n) for j in range(i + 1, min(i + 1 + overlap, n))}
    keys = range(0, n, max(loop_stride, 1))
    pairs |= {(i, j) for i in keys for j in keys if j > i}
    return [(files[i], files[j]) for i, j in sorted(pairs)]


def scaled_camera(camera: SceneCamera, k: int) -> SceneCamera:
    """The camera of the enlarged images (pixel centres at +0.5, so every length scales by k)."""
    if k == 1:
        return camera
    if not camera.intrinsics_known:
        return UncalibratedCamera(camera.width * k, camera.height * k)
    return PinholeCamera(camera.width * k, camera.height * k, camera.fx * k, camera.fy * k,
                         camera.cx * k, camera.cy * k, camera.distortion)


def extract_and_match(pycolmap, camera: SceneCamera, files: list[str], image_dir: Path, work: Path,
                       opts: PoseOptions) -> Path:
    """SIFT features and verified matches in ``work/database.db`` (returned)."""
    db = work / "database.db"
    db.unlink(missing_ok=True)
    reader = pycolmap.ImageReaderOptions()
    if camera.intrinsics_known:
        reader.camera_model = "PINHOLE"
        reader.camera_params = f"{camera.fx},{camera.fy},{camera.cx},{camera.cy}"
    else:
        reader.camera_model = "SIMPLE_PINHOLE"
        reader.camera_params = (f"{opts.focal_factor * camera.width},{camera.width / 2},"
                                f"{camera.height / 2}")
    extract = pycolmap.FeatureExtractionOptions()
    extract.num_threads = opts.threads
    extract.sift.peak_threshold = opts.peak_threshold
    extract.sift.max_num_features = opts.max_features
    cpu = pycolmap.Device.cpu
    pycolmap.extract_features(db, image_dir, image_names=files, camera_mode=pycolmap.CameraMode.SINGLE,
                              reader_options=reader, extraction_options=extract, device=cpu)
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = opts.threads
    if len(files) <= opts.exhaustive_max:
        pycolmap.match_exhaustive(db, matching_options=matching, device=cpu)
    else:
        pair_file = work / "pairs.txt"
        pair_file.write_text("".join(f"{a} {b}\n" for a, b in match_pairs(files, opts.overlap,
                                                                           opts.loop_stride)))
        pairing = pycolmap.ImportedPairingOptions()
        pairing.match_list_path = str(pair_file)
        pycolmap.match_image_pairs(db, matching_options=matching, pairing_options=pairing, device=cpu)
    return db


def _map(pycolmap, db: Path, files: list[str], image_dir: Path, work: Path, opts: PoseOptions,
         attempt: int = 0) -> dict:
    """Incremental mapping (seed ``opts.seed + attempt``); all models COLMAP kept."""
    mapping = pycolmap.IncrementalPipelineOptions()
    mapping.num_threads = opts.threads
    mapping.random_seed = opts.seed + attempt
    mapping.min_model_size = min(opts.min_registered, len(files))
    mapping.ba_refine_focal_length = False  # unknown: profiled afterwards (fusiongs.sfm.focal)
    mapping.ba_refine_principal_point = False
    mapping.ba_refine_extra_params = False
    mapping.mapper.abs_pose_refine_focal_length = False
    mapping.mapper.abs_pose_refine_extra_params = False
    mapping.mapper.init_min_num_inliers = opts.min_inliers
    mapping.mapper.abs_pose_min_num_inliers = max(opts.min_inliers // 2, 6)
    sparse = work / ("sparse" if attempt == 0 else f"sparse_{attempt}")
    sparse.mkdir(exist_ok=True)
    return pycolmap.incremental_mapping(db, image_dir, sparse, options=mapping)


def _rank(recs: dict) -> tuple[int, float]:
    """Sort key of a mapping attempt: more registered images first, then lower mean reprojection
    error (both computed on its largest model)."""
    best = max(recs.values(), key=lambda r: r.num_reg_images(), default=None)
    if best is None:
        return 0, 0.0
    return best.num_reg_images(), -float(best.compute_mean_reprojection_error())


def best_of_attempts(pycolmap, db: Path, files: list[str], image_dir: Path, work: Path,
                      opts: PoseOptions) -> dict:
    """Up to ``opts.mapping_attempts`` incremental mappings (other seeds) when the first one
    builds a model; the one with the most registered images and then the lowest reprojection
    error. A wrong start can converge to a bent reconstruction that still registers every image
    (forward motion down the simulated corridor: rotations 45° off in 4 of 10 runs, at twice the
    reprojection error of the right one)."""
    recs = _map(pycolmap, db, files, image_dir, work, opts)
    if _rank(recs)[0] < opts.min_registered:
        return recs  # no model: other seeds will not find parallax either (and cost minutes)
    for attempt in range(1, max(opts.mapping_attempts, 1)):
        other = _map(pycolmap, db, files, image_dir, work, opts, attempt)
        if _rank(other) > _rank(recs):
            recs = other
    return recs


def model_poses(rec, files: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(registered [N] bool, c2w [N, 4, 4])`` in COLMAP's frame, in the order of ``files``."""
    index = {f: i for i, f in enumerate(files)}
    ok = np.zeros(len(files), bool)
    c2w = np.tile(np.eye(4), (len(files), 1, 1))
    for im in rec.images.values():
        if not im.has_pose or im.name not in index:
            continue
        w2c = np.eye(4)
        w2c[:3, :] = np.asarray(im.cam_from_world().matrix())
        i = index[im.name]
        ok[i], c2w[i] = True, np.linalg.inv(w2c)
    return ok, c2w


def model_points(rec) -> tuple[np.ndarray, np.ndarray]:
    """``(xyz [P, 3] float64, rgb [P, 3] uint8)``: the 3D points of a COLMAP model."""
    pts = list(rec.points3D.values())
    xyz = np.array([p.xyz for p in pts], np.float64).reshape(-1, 3)
    rgb = np.array([p.color for p in pts], np.uint8).reshape(-1, 3)
    return xyz, rgb
