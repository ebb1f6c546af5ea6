"""Settings of the pose estimation (:func:`fusiongs.sfm.register.estimate_camera_and_trajectory`).

Kept apart from the registration so that every layer can name them without importing it.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PoseOptions:
    """Settings of :func:`estimate_camera_and_trajectory`.

    Attributes:
        focal_factor: starting focal length of an unknown camera, in image widths.
        exhaustive_max: match every pair of images up to this many images; beyond, sequential.
        overlap: sequential matching: each image is matched with the next ``overlap`` ones.
        loop_stride: sequential matching: every ``loop_stride``-th image is also matched with all
            the others of that subset (loop candidates, no vocabulary tree needed).
        peak_threshold: SIFT detection threshold (COLMAP's default 0.0067; lower finds more
            features in the low-contrast grey images of event cameras).
        max_features: SIFT features per image.
        min_inliers: inlier matches to start a model (init) and to register an image (half of it).
        min_registered: fewer registered images than this is an error.
        median_depth: median depth of the reconstructed points after scaling (scene units).
        threads: CPU threads of COLMAP (feature extraction, matching, mapping, the focal
            profile's bundle adjustments). 1, the default, makes the poses reproducible: with
            several threads COLMAP's matching gives run-to-run different inliers (measured: 1.5 %
            of runs of a 6-image scene registered 2-4 images instead of 6 under load), and the
            mapping different poses; on eslnet_cups 1 thread costs 14.3 s instead of 12.7 s.
        seed: COLMAP's random seed.
        sfm_min_width: images narrower than this are enlarged by ``ceil(sfm_min_width / width)``
            (at most 4) for feature extraction; poses and intrinsics are reported at the input
            size.
        no_parallax: when structure from motion cannot reconstruct (too little parallax), return
            a static or rotation-only camera from the pairwise matches instead of raising.
        mapping_attempts: incremental mappings with different seeds when the first one builds a
            model; the best one is kept (see :func:`fusiongs.sfm.colmap.best_of_attempts`).
        static_px: a camera counts as static when the median shift of the inlier matches of every
            matched pair is below this (pixels at the input size).
    """

    focal_factor: float = 1.2
    exhaustive_max: int = 30
    overlap: int = 10
    loop_stride: int = 5
    peak_threshold: float = 0.002
    max_features: int = 8192
    min_inliers: int = 30
    min_registered: int = 3
    median_depth: float = 3.0
    threads: int = 1
    seed: int = 0
    sfm_min_width: int = 320
    no_parallax: bool = False
    static_px: float = 0.5
    mapping_attempts: int = 3
