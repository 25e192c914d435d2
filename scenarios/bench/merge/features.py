"""Map-merging baselines for ``mrslam bench merge``: the ROS ``multirobot_map_merge`` estimator.

:func:`estimate_transform_features` re-implements the transform estimation of the ROS
package ``multirobot_map_merge`` (m-explore, ``map_merge/src/combine_grids``:
``MergingPipeline::estimateTransforms`` with OpenCV's ``AffineBestOf2NearestMatcher``) for
two grids:

1. **Images.** ``MergingPipeline::feed`` views each ``nav_msgs/OccupancyGrid``'s int8 data
   as an 8-bit image without copying: FREE 0 -> 0, OCCUPIED 100 -> 100, UNKNOWN -1 -> 255,
   with image row 0 = the grid's first row. An OccupancyGrid's first row is the one at the
   origin (lowest y), exactly like :class:`~mrslam_env.gridmap.GridMap`, so the image is
   ``cells.view(uint8)`` with **no** vertical flip. (It is the PGM *file* that has row 0 at
   the top; ``map_merge`` never sees files.) Both images are mirror images of the maps, and
   the estimated similarity is undone consistently in :func:`pixel_affine_to_transform`.
2. **Features.** AKAZE (``map_merge``'s default ``estimation_feature_type``) or ORB with
   OpenCV's default parameters, detected on the whole image without a mask
   (``cv::detail::computeImageFeatures``).
3. **Matching** (``cv::detail::CpuMatcher`` with ``match_conf = 0.3``): the two nearest
   neighbours of each descriptor (Hamming distance: AKAZE's MLDB and ORB are binary), kept
   when ``best < (1 - 0.3) * second`` (Lowe's ratio test at 0.7), in both directions, the
   second direction adding only pairs not found by the first.
4. **Estimation** (``AffineBestOf2NearestMatcher`` with ``full_affine = false``): fewer than
   ``num_matches_thresh1 = 6`` matches give no transform; else
   ``cv2.estimateAffinePartial2D`` (RANSAC, 3 px reprojection threshold, then
   Levenberg-Marquardt on the inliers) fits rotation + uniform scale + translation, and the
   match confidence is ``inliers / (8 + 0.3 * matches)`` (Brown & Lowe's panorama rule).
5. **Decision** (``cv::detail::leaveBiggestComponent``): the pair is merged only when
   ``confidence >= confidence_threshold`` (``map_merge``'s ``estimation_confidence``,
   default 1.0); otherwise the maps stay apart, i.e. "no merge".

``map_merge`` then runs ``BundleAdjusterAffinePartial`` over all grids; for a single pair it
re-minimises the same inliers' reprojection error that ``estimateAffinePartial2D`` has
already refined, so it is left out. The pixel similarity is turned into the metric
``map1_from_map2`` through each grid's resolution and origin; its rotation is read as
``atan2(b, a)`` and a scale different from 1 is ignored, as ``map_merge``'s
``getTransforms`` does.

OpenCV comes from the optional ``baselines`` extra (``pip install mrslam[baselines]``);
:func:`opencv_available` says whether it is installed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mrslam_env.gridmap import GridMap
from mrslam_env.validation import check_fields, require

FloatArray = NDArray[np.float64]

__all__ = [
    "FEATURE_TYPES",
    "FeatureMergeConfig",
    "FeatureMergeResult",
    "estimate_transform_features",
    "grid_image",
    "map_from_pixel",
    "match_features",
    "opencv_available",
    "pixel_affine_to_transform",
]

FEATURE_TYPES = ("akaze", "orb")


def opencv_available() -> bool:
    """Whether ``cv2`` (the ``baselines`` extra) can be imported."""
    try:
        import cv2  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True, slots=True, kw_only=True)
class FeatureMergeConfig:
    """Settings of the ``multirobot_map_merge`` estimator; defaults are the package's."""

    feature: str = "akaze"
    """Feature detector and descriptor: ``"akaze"`` (the package's default) or ``"orb"``.
    An OpenCV build without AKAZE (OpenCV 5 moved it to contrib) falls back to ORB."""
    ratio: float = 0.7
    """Lowe's ratio test, ``1 - match_conf`` with OpenCV's ``match_conf = 0.3``, in (0, 1]."""
    min_matches: int = 6
    """Fewer matches than this give no transform (``num_matches_thresh1``)."""
    ransac_threshold: float = 3.0
    """RANSAC reprojection threshold, pixels (OpenCV's default)."""
    confidence_threshold: float = 1.0
    """Merge when ``inliers / (8 + 0.3 matches)`` reaches this (``estimation_confidence``)."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        feature = self.feature
        require(name, "feature", feature, feature in FEATURE_TYPES, f"one of {FEATURE_TYPES}")
        require(name, "ratio", self.ratio, 0.0 < self.ratio <= 1.0, "in (0, 1]")
        check_fields(
            self,
            positive=("ransac_threshold",),
            non_negative=("confidence_threshold",),
            counts=("min_matches",),
        )
        require(name, "min_matches", self.min_matches, self.min_matches >= 2, "an int >= 2")


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class FeatureMergeResult:
    """What the estimator found for one pair.

    Attributes
    ----------
    transform : ndarray (3,) or None
        ``map1_from_map2`` (m, m, rad) when the confidence reached the threshold, else None.
    estimate : ndarray (3,) or None
        The estimated ``map1_from_map2`` whatever its confidence (None: no estimate at all).
    confidence : float
        ``inliers / (8 + 0.3 matches)``; 0 without an estimate.
    matches, inliers : int
        Ratio-test matches and RANSAC inliers.
    scale : float
        The similarity's scale (1 for maps of one resolution and a perfect fit).
    feature : str
        The detector actually used.
    keypoints : tuple of int
        Keypoints found in map 1's and map 2's images.
    """

    transform: FloatArray | None
    estimate: FloatArray | None
    confidence: float
    matches: int
    inliers: int
    scale: float
    feature: str
    keypoints: tuple[int, int]


def grid_image(grid: GridMap) -> NDArray[np.uint8]:
    """The 8-bit image ``map_merge`` sees for a grid: its int8 cells viewed as uint8.

    FREE -> 0, OCCUPIED -> 100, UNKNOWN -> 255; shape (rows, cols), row 0 = lowest y (the
    OccupancyGrid data order), so pixel ``(u, v)`` is cell ``(iy, ix) = (v, u)``.
    """
    return np.ascontiguousarray(grid.cells).view(np.uint8)


def map_from_pixel(grid: GridMap) -> FloatArray:
    """Homogeneous 3x3 matrix from OpenCV pixel coordinates ``(u, v)`` of
    :func:`grid_image` (pixel centres at integers) to metric ``(x, y)`` in the grid's frame."""
    res = grid.resolution
    x0, y0 = grid.origin
    return np.array([[res, 0.0, x0 + 0.5 * res], [0.0, res, y0 + 0.5 * res], [0.0, 0.0, 1.0]])


def pixel_affine_to_transform(
    pixel1_from_pixel2: FloatArray, m1: GridMap, m2: GridMap
) -> tuple[FloatArray, float]:
    """Metric ``map1_from_map2`` (3,) and the scale of a pixel similarity (2, 3) or (3, 3)
    mapping image-2 pixels to image-1 pixels."""
    affine = np.eye(3)
    affine[:2] = np.asarray(pixel1_from_pixel2, dtype=np.float64)[:2]
    metric = map_from_pixel(m1) @ affine @ np.linalg.inv(map_from_pixel(m2))
    a, b = metric[0, 0], metric[1, 0]
    theta = math.atan2(b, a)
    return np.array([metric[0, 2], metric[1, 2], theta]), float(math.hypot(a, b))


def _detector(feature: str) -> tuple[Any, str]:
    import cv2

    if feature == "akaze" and hasattr(cv2, "AKAZE"):
        return cv2.AKAZE.create(), "akaze"
    return cv2.ORB.create(), "orb"


def match_features(
    descriptors1: NDArray[np.uint8] | None,
    descriptors2: NDArray[np.uint8] | None,
    ratio: float,
) -> list[tuple[int, int]]:
    """Ratio-test matches ``(index in 1, index in 2)`` in both directions, as OpenCV's
    ``CpuMatcher`` (binary descriptors, Hamming distance)."""
    import cv2

    if descriptors1 is None or descriptors2 is None:
        return []
    if len(descriptors1) < 2 or len(descriptors2) < 2:
        return []
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    found: list[tuple[int, int]] = []
    seen: set[tuple[int, int]] = set()
    for pair in matcher.knnMatch(descriptors1, descriptors2, k=2):
        if len(pair) == 2 and pair[0].distance < ratio * pair[1].distance:
            found.append((pair[0].queryIdx, pair[0].trainIdx))
            seen.add((pair[0].queryIdx, pair[0].trainIdx))
    for pair in matcher.knnMatch(descriptors2, descriptors1, k=2):
        if len(pair) == 2 and pair[0].distance < ratio * pair[1].distance:
            match = (pair[0].trainIdx, pair[0].queryIdx)
            if match not in seen:
                found.append(match)
    return found


def estimate_transform_features(
    m1: GridMap, m2: GridMap, config: FeatureMergeConfig | None = None
) -> FeatureMergeResult:
    """Estimate ``map1_from_map2`` the way ROS ``multirobot_map_merge`` does (module docs).

    Parameters
    ----------
    m1, m2 : GridMap
        The two maps, each in its own frame.
    config : FeatureMergeConfig, optional

    Returns
    -------
    FeatureMergeResult
        ``transform`` is None ("no merge") below the confidence threshold.

    Raises
    ------
    ImportError
        Without OpenCV (install the ``baselines`` extra).

    Notes
    -----
    Deterministic except for RANSAC, which draws from OpenCV's global generator; it is
    reseeded (``cv2.setRNGSeed(0)``) on every call so results are reproducible.
    """
    import cv2

    config = config if config is not None else FeatureMergeConfig()
    detector, used = _detector(config.feature)
    keypoints1, descriptors1 = detector.detectAndCompute(grid_image(m1), None)
    keypoints2, descriptors2 = detector.detectAndCompute(grid_image(m2), None)
    counts = (len(keypoints1), len(keypoints2))
    # Query = map 2, train = map 1: the similarity maps image-2 pixels onto image-1 pixels.
    matches = [(j, i) for i, j in match_features(descriptors2, descriptors1, config.ratio)]
    nothing = FeatureMergeResult(
        transform=None,
        estimate=None,
        confidence=0.0,
        matches=len(matches),
        inliers=0,
        scale=math.nan,
        feature=used,
        keypoints=counts,
    )
    if len(matches) < config.min_matches:
        return nothing
    points2 = np.array([keypoints2[j].pt for _, j in matches], dtype=np.float32)
    points1 = np.array([keypoints1[i].pt for i, _ in matches], dtype=np.float32)
    cv2.setRNGSeed(0)
    affine, inlier_mask = cv2.estimateAffinePartial2D(
        points2, points1, method=cv2.RANSAC, ransacReprojThreshold=config.ransac_threshold
    )
    if affine is None:
        return nothing
    inliers = int(np.count_nonzero(inlier_mask))
    confidence = inliers / (8.0 + 0.3 * len(matches))
    estimate, scale = pixel_affine_to_transform(np.asarray(affine, dtype=np.float64), m1, m2)
    return FeatureMergeResult(
        transform=estimate if confidence >= config.confidence_threshold else None,
        estimate=estimate,
        confidence=confidence,
        matches=len(matches),
        inliers=inliers,
        scale=scale,
        feature=used,
        keypoints=counts,
    )
