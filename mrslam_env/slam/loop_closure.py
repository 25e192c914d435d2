"""Loop-closure matching: one scan against a submap of older scans (docs/design.md §4).

A closure must be right or absent: a false one bends the map. So the scan is matched over
a wide window (the drift the robot may have gathered since it was last tied to older
scans) with no odometry prior, and accepted only with a margin:

1. **Coarse volume**: the mean coarse-field likelihood of the scan points at every pose of
   a lattice (:func:`correlative_scores`: the coarse search of
   :func:`~mrslam_env.slam.matcher.correlative_search`, every score kept, no prior).
2. **A unique best**: the best lattice pose (the first among equals in the order heading,
   y, x) must lie inside the window (not on its edge: the peak could lie beyond it), and
   its score must beat the best score of every position farther than
   ``loop_peak_separation`` from it by the factor ``1 / loop_max_peak_ratio``: a corridor
   (every position along it scores alike) or a repeated structure within the window has
   no unique best.
3. **Refinement** from the best lattice pose (:func:`~mrslam_env.slam.matcher.match_scan`
   with a one-step window and no prior), then a high enough mean likelihood
   (``loop_min_score``) and a well-conditioned translational information
   (``loop_min_condition``: no direction the scan does not pin down).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numba
import numpy as np
from numpy.typing import NDArray

from mrslam_env.slam.config import MatcherConfig, PoseGraphConfig
from mrslam_env.slam.grid import OccupancyGrid
from mrslam_env.slam.matcher import match_scan, snap_points
from mrslam_env.slam.scan import scan_points

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]

__all__ = ["LoopMatch", "correlative_scores", "match_loop", "peak_ratio"]


@numba.njit(cache=True)
def correlative_scores(
    field: Float32Array,
    scale: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
    points: FloatArray,
    stride: int,
    x0: float,
    y0: float,
    theta0: float,
    k_max: int,
    angle_step: float,
    j_max: int,
    step_cells: int,
) -> FloatArray:
    """Scores of every pose of a lattice around ``(x0, y0, theta0)``.

    Headings ``theta0 + k angle_step`` for ``|k| <= k_max``, translations ``(x0, y0) +
    resolution * step_cells * (jx, jy)`` for ``|jx|, |jy| <= j_max``. A pose's score is
    the mean over the points (every ``stride``-th row of ``points`` (M, 2), sensor frame)
    of ``min(scale * field[0, cell], 1)``; a point whose window leaves the grid scores 0.

    Returns
    -------
    ndarray, shape (2 k_max + 1, 2 j_max + 1, 2 j_max + 1)
        ``[k + k_max, jy + j_max, jx + j_max]``.
    """
    _, rows, cols = field.shape
    width = 2 * j_max + 1
    scores = np.zeros((2 * k_max + 1, width, width))
    n = (points.shape[0] + stride - 1) // stride
    if n == 0:
        return scores
    reach = j_max * step_cells
    flat = field[0].ravel()
    base = np.empty(n, dtype=np.int64)
    kept = np.empty(n, dtype=np.int64)
    for k in range(-k_max, k_max + 1):
        theta = theta0 + k * angle_step
        used = snap_points(
            points, stride, n, x0, y0, theta, origin_x, origin_y, resolution, reach,
            rows, cols, kept, base,
        )  # fmt: skip
        plane = scores[k + k_max]
        for m in range(used):
            corner = base[m]
            for jy in range(width):
                index = corner + jy * step_cells * cols
                for jx in range(width):
                    plane[jy, jx] += min(flat[index] * scale, 1.0)
                    index += step_cells
        for jy in range(width):
            for jx in range(width):
                plane[jy, jx] /= n
    return scores


def peak_ratio(planar: FloatArray, best: tuple[int, int], step: float, separation: float) -> float:
    """The best score of the positions farther than ``separation`` (m) from ``best``
    (``(jy, jx)`` in ``planar`` (W, W), the best score per position over headings, lattice
    step ``step`` m), over the score at ``best``; 0 when no position is that far or the
    best scores 0."""
    width = planar.shape[0]
    jy, jx = np.meshgrid(np.arange(width), np.arange(width), indexing="ij")
    far = step * np.hypot(jy - best[0], jx - best[1]) > separation
    top = float(planar[best])
    if top <= 0.0 or not far.any():
        return 0.0
    return float(planar[far].max()) / top


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class LoopMatch:
    """The outcome of one closure match.

    Attributes
    ----------
    pose : ndarray, shape (3,)
        The refined pose of the scan in the submap's frame (the best lattice pose if the
        refinement never ran).
    score : float
        Mean fine-field likelihood of the scan at ``pose``, in [0, 1] (0 if not refined).
    peak_ratio : float
        Second distinct peak over the best of the coarse volume (:func:`peak_ratio`).
    condition : float
        Smallest / largest eigenvalue of the translational information at ``pose``.
    information : ndarray, shape (3, 3)
        The refinement's information matrix (map frame), zeros if not refined.
    n_points : int
        Scan returns.
    accepted : bool
    reason : str
        ``"ok"``, ``"few points"``, ``"window edge"``, ``"ambiguous"``, ``"low score"``
        or ``"degenerate"``.
    """

    pose: FloatArray
    score: float
    peak_ratio: float
    condition: float
    information: FloatArray
    n_points: int
    accepted: bool
    reason: str


def _refine_config(matcher: MatcherConfig) -> MatcherConfig:
    """The front end's matcher reduced to a refinement: a window of one coarse lattice
    step around the seed, no prior, no acceptance rule of its own."""
    return replace(
        matcher,
        angle_window_base=matcher.coarse_angle_step,
        angle_window_per_rad=0.0,
        angle_window_per_m=0.0,
        angle_window_max=matcher.coarse_angle_step,
        xy_window_base=matcher.coarse_xy_step,
        xy_window_per_m=0.0,
        xy_window_per_rad=0.0,
        xy_window_max=matcher.coarse_xy_step,
        prior_xy_std_base=100.0,
        prior_xy_std_per_m=0.0,
        prior_angle_std_base=100.0,
        prior_angle_std_per_rad=0.0,
        prior_weight=0.0,
        min_points=1,
        min_score=0.0,
        degenerate_ratio=0.0,
    )


def match_loop(
    grid: OccupancyGrid,
    ranges: FloatArray,
    max_range: float,
    predicted: FloatArray,
    xy_window: float,
    angle_window: float,
    config: PoseGraphConfig,
    matcher: MatcherConfig,
) -> LoopMatch:
    """Match a scan to a submap over a wide window, accepting only a unique best.

    Parameters
    ----------
    grid : OccupancyGrid
        The submap (its likelihood fields), in a frame of the caller's choice.
    ranges : ndarray, shape (N,)
        The scan.
    max_range : float
        m.
    predicted : ndarray, shape (3,)
        The scan's pose in the submap's frame as the graph has it: the window's centre.
    xy_window, angle_window : float
        Half-widths of the search window, m and rad.
    config : PoseGraphConfig
        The acceptance thresholds (``loop_*``).
    matcher : MatcherConfig
        The lattice (coarse steps, point stride) and the refinement's settings.

    Returns
    -------
    LoopMatch
    """
    predicted = np.asarray(predicted, dtype=np.float64)
    ranges = np.asarray(ranges, dtype=np.float64)
    points = scan_points(ranges, max_range, grid.config.min_range)
    n_points = len(points)
    resolution = grid.resolution
    step_cells = max(1, round(matcher.coarse_xy_step / resolution))
    step = step_cells * resolution
    k_max = int(angle_window / matcher.coarse_angle_step + 1e-9)
    j_max = max(1, math.ceil(xy_window / step - 1e-9))

    def rejected(reason: str, pose: FloatArray, ratio: float = 0.0) -> LoopMatch:
        return LoopMatch(
            pose=pose,
            score=0.0,
            peak_ratio=ratio,
            condition=0.0,
            information=np.zeros((3, 3)),
            n_points=n_points,
            accepted=False,
            reason=reason,
        )

    if n_points < config.loop_min_points:
        return rejected("few points", predicted.copy())
    ox, oy = grid.origin
    scores = correlative_scores(
        grid.coarse_field, grid.coarse_scale, ox, oy, resolution, points,
        matcher.coarse_point_stride, float(predicted[0]), float(predicted[1]),
        float(predicted[2]), k_max, matcher.coarse_angle_step, j_max, step_cells,
    )  # fmt: skip
    k, jy, jx = np.unravel_index(int(np.argmax(scores)), scores.shape)
    best = np.array(
        [
            predicted[0] + (int(jx) - j_max) * step,
            predicted[1] + (int(jy) - j_max) * step,
            predicted[2] + (int(k) - k_max) * matcher.coarse_angle_step,
        ]
    )
    ratio = peak_ratio(scores.max(axis=0), (int(jy), int(jx)), step, config.loop_peak_separation)
    edge = {int(jy), int(jx)} & {0, 2 * j_max} or (k_max > 0 and int(k) in (0, 2 * k_max))
    if edge:
        return rejected("window edge", best, ratio)
    if ratio > config.loop_max_peak_ratio:
        return rejected("ambiguous", best, ratio)
    result = match_scan(grid, ranges, max_range, best, 0.0, 0.0, _refine_config(matcher))
    reason = "ok"
    if result.score < config.loop_min_score:
        reason = "low score"
    elif result.condition < config.loop_min_condition:
        reason = "degenerate"
    return LoopMatch(
        pose=result.matched_pose,
        score=result.score,
        peak_ratio=ratio,
        condition=result.condition,
        information=result.information,
        n_points=n_points,
        accepted=reason == "ok",
        reason=reason,
    )
