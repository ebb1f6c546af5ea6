"""Intrinsics and a camera trajectory from sharp images at known times (docs/method.md §6).

The images (EDI results at the frames' mid-exposure, or several instants per exposure) are
registered by COLMAP's incremental structure from motion (pycolmap). Images narrower than
``sfm_min_width`` are first enlarged by an integer factor (bicubic): at the simulator's 173x130,
SIFT finds about 30 features per image, and rotations came out up to 0.9° wrong even from
perfectly sharp views; at twice the size, 3x as many points and 0.1-0.3° (benchmarks/RESULTS.md,
"Withheld trajectory"). Then SIFT features, exhaustive
matching for up to ``exhaustive_max`` images, else sequential neighbours plus loop candidates
(every ``loop_stride``-th image matched with every other one), one shared camera. A known camera
is held fixed (PINHOLE). An unknown one is SIMPLE_PINHOLE with the principal point at the centre:
the model is built with the focal length held at ``1.2 x width``, then a profile of bundle
adjustments over focal lengths refines it, or keeps the guess when the images do not constrain it
(:mod:`fusiongs.sfm.focal`; shallow hand-held recordings often do not).

Without parallax (a camera on a tripod, or one that only turns) structure from motion cannot
start. With ``no_parallax`` (the pose stage sets it), the matches decide instead: when every
matched pair of images is still to within ``static_px`` the camera is static (checked before the
incremental mapper, which would search for minutes in vain), otherwise, when the mapper fails,
each image's rotation is fitted to its matches with its best-connected neighbour
(:func:`fusiongs.sfm.align.pair_rotation`) and chained; translation is zero either way.

Registered images give camera-to-world poses (OpenCV axes, the trajectory convention of
docs/scene-format.md); the ones that failed are interpolated over time (and extrapolated at the ends) between
registered neighbours. The reconstruction is moved so that the first registered camera is the
origin and scaled so that the median depth of its points is ``median_depth`` scene units (COLMAP's
scale is arbitrary; the default 3 sits inside the trainer's default depth range [1, 12]).
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from fusiongs.camera.pinhole import PinholeCamera, SceneCamera
from fusiongs.camera.tum import PoseSamples
from fusiongs.errors import InputError
from fusiongs.sfm.colmap import (
    best_of_attempts,
    extract_and_match,
    load_pycolmap,
    model_points,
    model_poses,
    scaled_camera,
    upscale_factor,
    write_sfm_images,
)
from fusiongs.sfm.options import PoseOptions

WHERE = "pose estimation"
HINT = ("give the trajectory (a TUM file named by scene.json \"trajectory\") and/or the intrinsics "
        "(camera.fx, fy, cx, cy) instead")



@dataclass(frozen=True)
class PoseReport:
    """What the pose stage did (``camera.json``'s ``"report"``).

    Attributes:
        n_images: images given.
        registered: images registered in the largest model.
        failed: names of the images that did not register (their poses are interpolated).
        focal: ``(fx, fy)`` in pixels of the returned camera.
        focal_estimated: whether the focal length was estimated (else the given one, held fixed).
        focal_observable: whether the images constrain the focal length (``None`` when it was
            given); when not, ``focal`` is the starting guess.
        focal_profile: ``[(focal px, mean reprojection error px)]`` of the profile (empty when
            the focal length was given).
        reprojection_error_px: mean reprojection error of the model (pixels).
        n_points: 3D points of the model.
        n_models: models COLMAP built (more than one: the images split into unconnected groups).
        scale: factor applied to COLMAP's units.
        seconds: wall time of the stage.
        motion: ``"general"`` (structure from motion), ``"rotation"`` (no parallax: rotations
            from pairwise matches, no translation) or ``"static"`` (every pose the same).
        upscale: factor the images were enlarged by for feature extraction.
    """

    n_images: int
    registered: int
    failed: tuple[str, ...]
    focal: tuple[float, float]
    focal_estimated: bool
    focal_observable: bool | None
    focal_profile: tuple[tuple[float, float], ...]
    reprojection_error_px: float
    n_points: int
    n_models: int
    scale: float
    seconds: float
    motion: str = "general"
    upscale: int = 1

    def to_dict(self) -> dict:
        d = asdict(self)
        d["failed"], d["focal"] = list(self.failed), list(self.focal)
        d["focal_profile"] = [list(p) for p in self.focal_profile]
        return d


@dataclass(frozen=True)
class PoseEstimate:
    """Result of :func:`estimate_camera_and_trajectory`.

    Attributes:
        camera: the pinhole camera (given, or with the estimated focal length).
        poses: camera-to-world poses at every input time (failed ones interpolated) plus the ends
            of ``t_range`` when it reaches beyond them (extrapolated).
        report: registration summary.
        points: ``[P, 3]`` float64 reconstructed points in the poses' frame and scale.
        colors: ``[P, 3]`` uint8 colours of the points.
    """

    camera: PinholeCamera
    poses: PoseSamples
    report: PoseReport
    points: np.ndarray
    colors: np.ndarray


def _check_inputs(camera: SceneCamera, images: np.ndarray, times: np.ndarray,
                  names: Sequence[str]) -> None:
    if (images.ndim != 4 or images.shape[1:3] != (camera.height, camera.width)
            or images.shape[3] not in (1, 3)):
        raise InputError(WHERE, "images", f"[N, {camera.height}, {camera.width}, 1 or 3] linear images",
                         images.shape)
    if times.shape != (images.shape[0],) or not np.all(np.isfinite(times)):
        raise InputError(WHERE, "times", f"{images.shape[0]} finite times (s), one per image", times.shape)
    if times.size > 1 and np.any(np.diff(times) <= 0):
        raise InputError(WHERE, "times", "strictly increasing times", times.tolist())
    if len(names) != images.shape[0] or len(set(names)) != len(names):
        raise InputError(WHERE, "names", f"{images.shape[0]} unique image names", len(names))


def _median_depth(c2w: np.ndarray, xyz: np.ndarray) -> float:
    """Median depth of the points in front of the cameras (over all registered cameras; at most
    about 20,000 points, an even subsample)."""
    if not len(xyz) or not len(c2w):
        return float("nan")
    xyz = xyz[::max(len(xyz) // 20000, 1)]
    w2c = np.linalg.inv(c2w)
    z = np.einsum("cj,pj->cp", w2c[:, 2, :3], xyz) + w2c[:, 2, 3:4]
    z = z[z > 0]
    return float(np.median(z)) if z.size else float("nan")


def fill_poses(t: np.ndarray, known: np.ndarray, c2w: np.ndarray, t_out: np.ndarray) -> np.ndarray:
    """Poses at ``t_out`` from the ``known`` ones: slerp / linear between the two nearest known
    samples, continued at constant velocity beyond the first and last one.

    Args:
        t: ``[N]`` increasing times (s); known: ``[N]`` bool; c2w: ``[N, 4, 4]`` (rows of unknown
            samples are ignored); t_out: ``[T]`` times.

    Returns:
        ``[T, 4, 4]`` float64 camera-to-world poses.
    """
    from fusiongs.camera.trajectory import interpolate_linear

    kt = torch.from_numpy(np.asarray(t, np.float64)[known])
    kp = torch.from_numpy(np.asarray(c2w, np.float64)[known])
    out = interpolate_linear(kt, kp, torch.from_numpy(np.asarray(t_out, np.float64)))
    return out.numpy().copy()


def _normalise(c2w: np.ndarray, xyz: np.ndarray, depth: float) -> tuple[np.ndarray, np.ndarray, float]:
    """First camera at the origin with identity rotation, median point depth ``depth``."""
    ref = np.linalg.inv(c2w[0])
    med = _median_depth(c2w, xyz)
    if not np.isfinite(med) or med <= 0:  # no points: use the camera path instead
        centres = c2w[:, :3, 3]
        med = float(np.linalg.norm(np.diff(centres, axis=0), axis=1).sum()) or 1.0
    s = depth / med
    c2w = ref @ c2w
    c2w[:, :3, 3] *= s
    xyz = (xyz @ ref[:3, :3].T + ref[:3, 3]) * s
    return c2w, xyz, s


def estimate_camera_and_trajectory(camera: SceneCamera, images: np.ndarray, times: np.ndarray,
                                   names: Sequence[str] | None = None, *,
                                   t_range: tuple[float, float] | None = None,
                                   options: PoseOptions | None = None,
                                   work_dir: str | Path | None = None) -> PoseEstimate:
    """Register sharp images with pycolmap and return the camera and its trajectory.

    Args:
        camera: a :class:`PinholeCamera` (held fixed) or an
            :class:`~fusiongs.camera.pinhole.UncalibratedCamera` (focal length estimated).
        images: ``[N, H, W, C]`` linear images (C = 1 or 3), e.g. EDI results.
        times: ``[N]`` strictly increasing times of the images (s).
        names: image names for the report (default ``"0"``, ``"1"``, ...).
        t_range: ``(t0, t1)`` the poses must cover (e.g. the first exposure's start and the last
            one's end); poses are extrapolated to these ends when they lie outside ``times``.
        options: :class:`PoseOptions`.
        work_dir: folder for COLMAP's images, database and model (kept); default a temporary one.

    Returns:
        :class:`PoseEstimate`.

    Raises:
        InputError: on images or times of the wrong shape, or when fewer than
            ``options.min_registered`` images register (too little parallax or texture), naming
            the counts and how to supply the trajectory or intrinsics instead.
    """
    opts = options or PoseOptions()
    images, times = np.asarray(images), np.asarray(times, np.float64)
    names = [str(i) for i in range(len(images))] if names is None else [str(n) for n in names]
    _check_inputs(camera, images, times, names)
    pycolmap = load_pycolmap()
    start = time.perf_counter()
    level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 3  # quiet: a failure is reported as one InputError below
    k = upscale_factor(camera.width, opts.sfm_min_width)
    motion, links, recs, best = "general", None, {}, None
    try:
        with tempfile.TemporaryDirectory(prefix="fusiongs_sfm_") as tmp:
            work = Path(work_dir) if work_dir is not None else Path(tmp)
            work.mkdir(parents=True, exist_ok=True)
            files = write_sfm_images(images, work / "images", k)
            cam_k = scaled_camera(camera, k)
            db = extract_and_match(pycolmap, cam_k, files, work / "images", work, opts)
            if opts.no_parallax:
                from fusiongs.sfm.align import is_static, verified_matches

                links = verified_matches(db, files)
                if is_static(links, opts.static_px * k, max(opts.min_inliers // 2, 6)):
                    motion = "static"
            if motion == "general":
                recs = best_of_attempts(pycolmap, db, files, work / "images", work, opts)
        best = max(recs.values(), key=lambda r: r.num_reg_images(), default=None)
        ok = model_poses(best, files)[0] if best is not None else np.zeros(len(files), bool)
        if ok.sum() < opts.min_registered and links is not None:
            motion = "static" if motion == "static" else "rotation"
            from fusiongs.sfm.align import rotation_only_poses

            guess = cam_k if cam_k.intrinsics_known else cam_k.guess(opts.focal_factor)
            ok, c2w, residual = rotation_only_poses(links, len(files), guess.K(torch.float64).numpy(),
                                                    static=motion == "static",
                                                    min_matches=max(opts.min_inliers // 2, 6))
            residual *= guess.fx / k  # radians -> pixels of the input images
        if ok.sum() < opts.min_registered:
            raise InputError(WHERE, "frames", f"at least {opts.min_registered} images registered by "
                             f"structure from motion (pycolmap) to estimate the camera path; {HINT}",
                             f"{int(ok.sum())} of {len(files)} registered (too little texture or "
                             "parallax: rotation-only motion cannot be reconstructed)")
        prof = None
        if not camera.intrinsics_known and motion == "general":
            from fusiongs.sfm.focal import profile_focal

            best, prof = profile_focal(best, opts.focal_factor * cam_k.width, threads=opts.threads)
    finally:
        pycolmap.logging.minloglevel = level
    if motion == "general":
        ok, c2w = model_poses(best, files)
        xyz, rgb = model_points(best)
        residual = float(best.compute_mean_reprojection_error()) / k
    else:
        xyz, rgb = np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    if prof is not None:
        f = prof.focal / k
        out_cam = PinholeCamera(camera.width, camera.height, f, f, camera.width / 2, camera.height / 2,
                                camera.distortion)
    else:
        out_cam = camera if camera.intrinsics_known else camera.guess(opts.focal_factor)
    if motion == "general":
        reg_c2w, xyz, scale = _normalise(c2w[ok], xyz, opts.median_depth)
        c2w[ok] = reg_c2w
    else:  # no points and no translation: nothing to scale
        scale = 1.0
    t_out = times
    if t_range is not None:
        t_out = np.unique(np.concatenate([[min(t_range[0], times[0])], times, [max(t_range[1], times[-1])]]))
    poses = PoseSamples(t=t_out, c2w=fill_poses(times, ok, c2w, t_out))
    report = PoseReport(
        n_images=len(files), registered=int(ok.sum()), failed=tuple(n for n, g in zip(names, ok) if not g),
        focal=(out_cam.fx, out_cam.fy), focal_estimated=not camera.intrinsics_known,
        focal_observable=None if camera.intrinsics_known else (prof is not None and prof.observable),
        focal_profile=() if prof is None else tuple((f / k, e / k) for f, e in prof.grid),
        reprojection_error_px=residual, n_points=len(xyz), n_models=len(recs), scale=scale,
        seconds=time.perf_counter() - start, motion=motion, upscale=k)
    return PoseEstimate(out_cam, poses, report, xyz, rgb)
