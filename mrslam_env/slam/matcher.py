"""Scan-to-map matching: correlative search, then Gauss–Newton refinement (docs/design.md §4).

The map side is the set of likelihood fields an :class:`~mrslam_env.slam.grid.OccupancyGrid`
keeps current (sums of Gaussians on its OCCUPIED cells' mean hit points, scaled so that a
wall scores about 1). Matching a scan seeded by an odometry prediction runs three stages:

1. **Coarse correlative search** (Olson, "Real-time correlative scan matching", ICRA
   2009): over a window of headings, rotate the scan points once per heading, snap them to
   cells, and score every translation on a lattice of whole cells by lookups in the wide
   *coarse* field, which is smooth enough that the lattice cannot step over its peak.
2. **Fine correlative search** around the coarse winner, at a finer heading step and
   single cells, in the *fine* fields (each point in the facing sector of its surface
   normal, see :mod:`mrslam_env.slam.grid`).
3. **Gauss–Newton refinement**, point-to-line ICP against the fine fields' ridges: across a
   wall a fine field is a Gaussian of the distance to the wall, so the bicubically
   interpolated field and its slope give each point's distance to the wall along the
   scan's own surface normal (the point-to-line residual of Censi's PL-ICP, ICRA 2008,
   without a correspondence search; bicubic as in Cartographer's Ceres matcher, Hess et
   al. 2016). The Hessian of that least-squares problem is the match's information matrix;
   its eigenvalues tell how well the scan constrains each direction.

Search scores carry a small penalty for distance from the prediction and the refinement a
Gaussian odometry prior, so ties (a corridor, where every position along it scores the
same) go to odometry. Acceptance: enough points, a high enough mean likelihood, and the
result within 1.5 search windows of the prediction; otherwise the prediction is kept. In a
degenerate direction (the translational information's smallest eigenvalue far below its
largest) the correction along that direction is dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numba.core import types
from numpy.typing import NDArray

from mrslam_env.slam.config import MatcherConfig
from mrslam_env.slam.grid import OccupancyGrid, sector_of
from mrslam_env.slam.scan import scan_normals, scan_points

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]
IntArray = NDArray[np.int64]

__all__ = [
    "MatchResult",
    "correlative_search",
    "interpolate",
    "match_scan",
    "point_sectors",
    "prior_information",
    "refine_pose",
    "search_window",
    "snap_points",
    "translational_condition",
]

HUBER = 0.02
"""Residuals (m) beyond this get Huber weights (``HUBER / |r|``) in the refinement."""

MIN_RIDGE_VALUE = 0.1
"""Points where the fine field is below this are too far from any wall to measure their
distance to it; the refinement leaves them out."""


# --- the scan side ----------------------------------------------------------------------


@numba.njit(cache=True)
def point_sectors(points: FloatArray, normals: FloatArray, heading: float) -> IntArray:
    """The view sector (:func:`~mrslam_env.slam.grid.sector_of`) of each point (M,): that of
    its sensor-facing normal (M, 2), or where that is zero of the direction back to the
    sensor, turned by the sensor's ``heading`` (rad) in the map frame."""
    sectors = np.empty(points.shape[0], dtype=np.int64)
    for m in range(points.shape[0]):
        if normals[m, 0] != 0.0 or normals[m, 1] != 0.0:
            direction = math.atan2(normals[m, 1], normals[m, 0])
        else:
            direction = math.atan2(-points[m, 1], -points[m, 0])
        sectors[m] = sector_of(heading + direction)
    return sectors


# --- the search ------------------------------------------------------------------------------


@numba.njit(cache=True)
def snap_points(
    points: FloatArray,
    stride: int,
    n: int,
    x0: float,
    y0: float,
    theta: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
    reach: int,
    rows: int,
    cols: int,
    kept: IntArray,
    cells: IntArray,
) -> int:
    """Snap the first ``n`` of every ``stride``-th point (sensor frame) at pose ``(x0, y0,
    theta)`` to grid cells, keeping those at least ``reach`` cells inside the grid (a
    point whose translation window leaves the grid could only meet its empty margin):
    point ``kept[u]`` lies ``reach`` cells up and right of flat cell ``cells[u]``
    (``row * cols + col``). Returns how many were kept."""
    c, s = math.cos(theta), math.sin(theta)
    used = 0
    for m in range(n):
        px, py = points[m * stride, 0], points[m * stride, 1]
        ix = math.floor((x0 + c * px - s * py - origin_x) / resolution)
        iy = math.floor((y0 + s * px + c * py - origin_y) / resolution)
        if reach <= ix < cols - reach and reach <= iy < rows - reach:
            kept[used] = m
            cells[used] = (iy - reach) * cols + ix - reach
            used += 1
    return used


@numba.njit(cache=True)
def correlative_search(
    fields: Float32Array,
    scale: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
    points: FloatArray,
    sectors: IntArray,
    stride: int,
    x0: float,
    y0: float,
    theta0: float,
    angle_half_window: float,
    angle_step: float,
    xy_half_cells: int,
    xy_step_cells: int,
    prior: FloatArray,
    prior_inverse_variance: FloatArray,
    prior_weight: float,
) -> tuple[float, float, float, float]:
    """Exhaustive search over a lattice of poses around ``(x0, y0, theta0)``.

    Headings ``theta0 + k angle_step`` for ``|k| <= angle_half_window / angle_step``,
    translations ``(x0, y0) + resolution * xy_step_cells * (i, j)`` for ``|i|, |j| <=
    xy_half_cells // xy_step_cells``. The points (every ``stride``-th row of ``points``
    (M, 2), sensor frame) are rotated once per heading and snapped to cells; translations
    by whole cells then only shift indices.

    Score of a candidate: the mean over the points of ``min(scale * fields[sector, cell],
    1)`` (``fields`` (S, rows, cols), ``sectors`` (M,) the field of each point; a point
    whose window leaves the grid scores 0), minus ``prior_weight`` times the squared
    Mahalanobis distance of the candidate from ``prior`` (3,) with diagonal
    ``prior_inverse_variance`` (3,).

    Returns
    -------
    x, y, theta, score : float
        The best candidate (the first among equals, in the loop order heading, y, x) and
        its score.
    """
    _, rows, cols = fields.shape
    n = (points.shape[0] + stride - 1) // stride
    k_max = int(angle_half_window / angle_step + 1e-9)
    j_max = xy_half_cells // xy_step_cells
    width = 2 * j_max + 1
    reach = j_max * xy_step_cells
    flat = fields.ravel()
    base = np.empty(n, dtype=np.int64)
    sums = np.empty(width * width)
    best_x, best_y, best_theta, best_score = x0, y0, theta0, -math.inf
    if n == 0:
        return best_x, best_y, best_theta, best_score
    inv_n = 1.0 / n
    row_step = xy_step_cells * cols
    kept = np.empty(n, dtype=np.int64)
    for k in range(-k_max, k_max + 1):
        theta = theta0 + k * angle_step
        used = snap_points(
            points, stride, n, x0, y0, theta, origin_x, origin_y, resolution, reach,
            rows, cols, kept, base,
        )  # fmt: skip
        for m in range(used):
            base[m] += sectors[kept[m] * stride] * rows * cols
        sums[:] = 0.0
        for m in range(used):
            corner = base[m]
            slot = 0
            for jy in range(width):
                index = corner + jy * row_step
                for _ in range(width):
                    sums[slot] += min(flat[index] * scale, 1.0)
                    index += xy_step_cells
                    slot += 1
        d_theta = (theta - prior[2] + math.pi) % (2.0 * math.pi) - math.pi
        penalty_theta = d_theta * d_theta * prior_inverse_variance[2]
        slot = 0
        for jy in range(-j_max, j_max + 1):
            cand_y = y0 + jy * xy_step_cells * resolution
            penalty_y = (cand_y - prior[1]) ** 2 * prior_inverse_variance[1]
            for jx in range(-j_max, j_max + 1):
                cand_x = x0 + jx * xy_step_cells * resolution
                penalty = penalty_theta + penalty_y
                penalty += (cand_x - prior[0]) ** 2 * prior_inverse_variance[0]
                score = sums[slot] * inv_n - prior_weight * penalty
                slot += 1
                if score > best_score:
                    best_x, best_y, best_theta, best_score = cand_x, cand_y, theta, score
    return best_x, best_y, best_theta, best_score


# --- the refinement --------------------------------------------------------------------------


@numba.njit(cache=True)
def _cubic_weights(t: float) -> tuple[float, float, float, float, float, float, float, float]:
    """Catmull–Rom weights of the samples at -1, 0, 1, 2 for a point at ``t`` in [0, 1),
    then their derivatives."""
    t2 = t * t
    t3 = t2 * t
    return (
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
        0.5 * (-3.0 * t2 + 4.0 * t - 1.0),
        0.5 * (9.0 * t2 - 10.0 * t),
        0.5 * (-9.0 * t2 + 8.0 * t + 1.0),
        0.5 * (3.0 * t2 - 2.0 * t),
    )


@numba.njit(cache=True)
def interpolate(
    fields: Float32Array, sector: int, scale: float, gx: float, gy: float
) -> tuple[float, float, float]:
    """Bicubic (Catmull–Rom) value of ``scale * fields[sector]`` at grid coordinates
    (gx, gy), and its gradient in cell units.

    Grid coordinates are in cells with the cell centres at integers: ``gx = (x -
    origin_x) / resolution - 0.5``. Returns zeros where the 4 x 4 stencil leaves the grid.
    Bicubic rather than bilinear: a bilinear interpolant peaks only at samples, which pulls
    matched walls onto cell centres (a bias of up to half a cell).
    """
    _, rows, cols = fields.shape
    ix, iy = math.floor(gx), math.floor(gy)
    if ix < 1 or iy < 1 or ix + 2 >= cols or iy + 2 >= rows:
        return 0.0, 0.0, 0.0
    wx0, wx1, wx2, wx3, dx0, dx1, dx2, dx3 = _cubic_weights(gx - ix)
    wy0, wy1, wy2, wy3, dy0, dy1, dy2, dy3 = _cubic_weights(gy - iy)
    value = 0.0
    d_gx = 0.0
    d_gy = 0.0
    for j in range(4):
        row = iy - 1 + j
        v0 = fields[sector, row, ix - 1]
        v1 = fields[sector, row, ix]
        v2 = fields[sector, row, ix + 1]
        v3 = fields[sector, row, ix + 2]
        along = wx0 * v0 + wx1 * v1 + wx2 * v2 + wx3 * v3
        slope = dx0 * v0 + dx1 * v1 + dx2 * v2 + dx3 * v3
        if j == 0:
            wy, dy = wy0, dy0
        elif j == 1:
            wy, dy = wy1, dy1
        elif j == 2:
            wy, dy = wy2, dy2
        else:
            wy, dy = wy3, dy3
        value += wy * along
        d_gx += wy * slope
        d_gy += dy * along
    return value * scale, d_gx * scale, d_gy * scale


@numba.njit(cache=True)
def _normal_equations(
    fields: Float32Array,
    scale: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
    ridge_sigma: float,
    points: FloatArray,
    normals: FloatArray,
    sectors: IntArray,
    x: float,
    y: float,
    theta: float,
    hessian: FloatArray,
    gradient: FloatArray,
) -> float:
    """Fill ``hessian`` (3, 3) and ``gradient`` (3,) with ``J^T W J`` and ``J^T W r`` of the
    point-to-wall residuals at pose (x, y, theta); return the mean of ``min(M, 1)``."""
    c, s = math.cos(theta), math.sin(theta)
    hessian[:, :] = 0.0
    gradient[:] = 0.0
    sigma2 = ridge_sigma * ridge_sigma
    total = 0.0
    n = points.shape[0]
    for m in range(n):
        px, py = points[m, 0], points[m, 1]
        gx = (x + c * px - s * py - origin_x) / resolution - 0.5
        gy = (y + s * px + c * py - origin_y) / resolution - 0.5
        value, d_gx, d_gy = interpolate(fields, sectors[m], scale, gx, gy)
        total += min(value, 1.0)
        if value < MIN_RIDGE_VALUE:
            continue
        nx = c * normals[m, 0] - s * normals[m, 1]
        ny = s * normals[m, 0] + c * normals[m, 1]
        if nx == 0.0 and ny == 0.0:
            continue
        # Across a wall the field is a Gaussian of the distance d to its ridge, so
        # d = -sigma^2 d(ln M)/dn. Only the slope along the scan's own normal counts: where
        # the scan continues a wall past its mapped end, the field slopes along the wall
        # and would drag the scan back onto the mapped part.
        residual = -sigma2 * (d_gx * nx + d_gy * ny) / (resolution * value)
        weight = 1.0 if abs(residual) <= HUBER else HUBER / abs(residual)  # Huber
        jt = nx * (-s * px - c * py) + ny * (c * px - s * py)
        gradient[0] += weight * nx * residual
        gradient[1] += weight * ny * residual
        gradient[2] += weight * jt * residual
        hessian[0, 0] += weight * nx * nx
        hessian[0, 1] += weight * nx * ny
        hessian[0, 2] += weight * nx * jt
        hessian[1, 1] += weight * ny * ny
        hessian[1, 2] += weight * ny * jt
        hessian[2, 2] += weight * jt * jt
    hessian[1, 0] = hessian[0, 1]
    hessian[2, 0] = hessian[0, 2]
    hessian[2, 1] = hessian[1, 2]
    return total / n if n > 0 else 0.0


# np.linalg.det and np.linalg.solve of a 3x3 system, the same LAPACK calls on the same
# copies as numba's implementations (so the same floats), without their generic checks and
# copies, which cost about ten seconds of compiling on a first run.
_XXGETRF: Any = types.ExternalFunction(
    "numba_xxgetrf",
    types.intc(
        types.char, types.intp, types.intp, types.CPointer(types.float64), types.intp,
        types.CPointer(types.int32),
    ),
)  # fmt: skip
_XGESV: Any = types.ExternalFunction(
    "numba_xgesv",
    types.intc(
        types.char, types.intp, types.intp, types.CPointer(types.float64), types.intp,
        types.CPointer(types.int32), types.CPointer(types.float64), types.intp,
    ),
)  # fmt: skip
_FLOAT64 = ord("d")


@numba.njit(cache=True)
def _check_finite(a: FloatArray) -> None:
    """The error np.linalg.det and np.linalg.solve raise on a non-finite entry."""
    for value in a.flat:
        if not math.isfinite(value):
            raise np.linalg.LinAlgError("Array must not contain infs or NaNs")


@numba.njit(cache=True)
def _to_fortran(a: FloatArray, out: FloatArray) -> None:
    """``out`` (C order) holds ``a`` column by column: ``a`` in Fortran order."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            out[j, i] = a[i, j]


@numba.njit(cache=True)
def _determinant(a: FloatArray, lu: FloatArray, pivots: NDArray[np.int32]) -> float:
    """``np.linalg.det(a)`` of a finite square ``a`` as numba computes it: LU by LAPACK's
    getrf, then ``sign * exp(sum log |u_kk|)``. ``lu`` and ``pivots`` are workspace."""
    n = a.shape[0]
    _to_fortran(a, lu)
    if _XXGETRF(_FLOAT64, n, n, lu.ctypes, n, pivots.ctypes) > 0:
        return 0.0
    sign = 1
    for k in range(n):
        sign = sign + (pivots[k] != (k + 1))
    sign = sign & 1
    if sign == 0:
        sign = -1
    total = 0.0
    for k in range(n):
        v = lu[k, k]
        if v < 0.0:
            sign = -sign
            v = -v
        total = total + np.log(v)
    return (sign + 0.0) * np.exp(total)


@numba.njit(cache=True)
def _solve(
    a: FloatArray, b: FloatArray, lu: FloatArray, pivots: NDArray[np.int32], out: FloatArray
) -> None:
    """``out = np.linalg.solve(a, b)`` for a finite, non-singular square ``a`` (LAPACK's
    gesv, as numba calls it). ``lu`` and ``pivots`` are workspace."""
    n = a.shape[0]
    _to_fortran(a, lu)
    for i in range(n):  # not out[:] = b, whose shape check compiles numba's string formatting
        out[i] = b[i]
    if _XGESV(_FLOAT64, n, 1, lu.ctypes, n, pivots.ctypes, out.ctypes, n) != 0:
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")


@numba.njit(cache=True)
def refine_pose(
    fields: Float32Array,
    scale: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
    ridge_sigma: float,
    points: FloatArray,
    normals: FloatArray,
    sectors: IntArray,
    x: float,
    y: float,
    theta: float,
    prior: FloatArray,
    prior_information: FloatArray,
    residual_std: float,
    iterations: int,
) -> tuple[float, float, float, float, FloatArray]:
    """Gauss–Newton refinement: point-to-wall distances read off the fine fields.

    ``M`` is ``scale * fields[sector]`` interpolated bicubically (:func:`interpolate`).
    Across a straight wall it is a Gaussian of width ``ridge_sigma`` (m) of the distance to
    the wall, so point ``i`` (sensor-frame ``points[i]`` with surface normal ``normals[i]``
    and field ``sectors[i]``) lies ``r_i = -ridge_sigma^2 dM/dn / M`` from the wall along
    its normal ``n`` (a zero normal or ``M < MIN_RIDGE_VALUE`` leaves the point out). Each
    iteration solves the Huber-weighted point-to-line problem

    ``(J^T W J / residual_std^2 + Omega) dT = -(J^T W r / residual_std^2 + Omega (T - prior))``

    with ``J_i = n^T dp_i/dT``, ``T = (x, y, theta)`` and ``Omega = prior_information``
    (3, 3). Steps are capped at one cell and 0.02 rad; iteration stops once a step is below
    1e-4 m and 1e-4 rad, or after ``iterations`` steps.

    Returns
    -------
    x, y, theta : float
        The refined pose.
    score : float
        Mean of ``min(M, 1)`` over the points at that pose, in [0, 1].
    information : ndarray, shape (3, 3)
        ``J^T W J / residual_std^2`` at that pose: the match term alone, without the prior.
    """
    inv_var = 1.0 / (residual_std * residual_std)
    hessian = np.zeros((3, 3))
    gradient = np.zeros(3)
    delta = np.zeros(3)
    lu, pivots, step = np.empty((3, 3)), np.empty(3, dtype=np.int32), np.empty(3)
    score = 0.0
    for iteration in range(iterations + 1):
        score = _normal_equations(
            fields, scale, origin_x, origin_y, resolution, ridge_sigma, points, normals,
            sectors, x, y, theta, hessian, gradient,
        )  # fmt: skip
        if iteration == iterations:
            break
        delta[0] = x - prior[0]
        delta[1] = y - prior[1]
        delta[2] = (theta - prior[2] + math.pi) % (2.0 * math.pi) - math.pi
        system = hessian * inv_var + prior_information
        rhs = -(gradient * inv_var + prior_information @ delta)
        _check_finite(system)  # as np.linalg.det, then np.linalg.solve, checked them
        if abs(_determinant(system, lu, pivots)) < 1e-12:
            break
        _check_finite(rhs)
        _solve(system, rhs, lu, pivots, step)
        step /= max(1.0, abs(step[0]) / resolution, abs(step[1]) / resolution, abs(step[2]) / 0.02)
        x, y, theta = x + step[0], y + step[1], theta + step[2]
        if abs(step[0]) < 1e-4 and abs(step[1]) < 1e-4 and abs(step[2]) < 1e-4:
            score = _normal_equations(
                fields, scale, origin_x, origin_y, resolution, ridge_sigma, points, normals,
                sectors, x, y, theta, hessian, gradient,
            )  # fmt: skip
            break
    theta = (theta + math.pi) % (2.0 * math.pi) - math.pi
    return x, y, theta, score, hessian * inv_var


# --- the whole match -------------------------------------------------------------------------


@numba.njit(cache=True)
def _match(
    fine_fields: Float32Array,
    fine_scale: float,
    coarse_field: Float32Array,
    coarse_scale: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
    ridge_sigma: float,
    ranges: FloatArray,
    normals: FloatArray,
    max_range: float,
    min_range: float,
    predicted: FloatArray,
    xy_window: float,
    angle_window: float,
    prior_information: FloatArray,
    coarse_stride: int,
    coarse_angle_step: float,
    coarse_cells: int,
    fine_angle_step: float,
    fine_cells: int,
    prior_weight: float,
    residual_std: float,
    iterations: int,
) -> tuple[float, float, float, float, FloatArray, int]:
    """The three stages of :func:`match_scan` in one compiled call: the pose ``(x, y,
    theta)``, its score, the information matrix and the number of points."""
    points = scan_points(ranges, max_range, min_range)
    n_points = points.shape[0]
    point_normals = np.empty((n_points, 2))
    count = 0
    for i in range(ranges.shape[0]):
        if min_range <= ranges[i] < max_range:
            point_normals[count, 0] = normals[i, 0]
            point_normals[count, 1] = normals[i, 1]
            count += 1
    sectors = point_sectors(points, point_normals, predicted[2])
    prior_inverse_variance = np.array(
        [prior_information[0, 0], prior_information[1, 1], prior_information[2, 2]]
    )
    x, y, theta, _ = correlative_search(
        coarse_field, coarse_scale, origin_x, origin_y, resolution, points,
        np.zeros(n_points, dtype=np.int64), coarse_stride,
        predicted[0], predicted[1], predicted[2], angle_window, coarse_angle_step,
        math.ceil(xy_window / resolution), coarse_cells,
        predicted, prior_inverse_variance, prior_weight,
    )  # fmt: skip
    if fine_cells > 0:
        x, y, theta, _ = correlative_search(
            fine_fields, fine_scale, origin_x, origin_y, resolution, points, sectors, 1,
            x, y, theta, 0.5 * coarse_angle_step, fine_angle_step, fine_cells, 1,
            predicted, prior_inverse_variance, prior_weight,
        )  # fmt: skip
    x, y, theta, score, information = refine_pose(
        fine_fields, fine_scale, origin_x, origin_y, resolution, ridge_sigma,
        points, point_normals, sectors, x, y, theta,
        predicted, prior_information, residual_std, iterations,
    )  # fmt: skip
    return x, y, theta, score, information, n_points


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class MatchResult:
    """The outcome of matching one scan.

    Attributes
    ----------
    pose : ndarray, shape (3,)
        The pose to use, in the map frame: the match if accepted (with the correction along
        a degenerate direction removed), else the prediction.
    matched_pose : ndarray, shape (3,)
        The refined match itself, accepted or not.
    score : float
        Mean likelihood of the scan points at ``matched_pose``, in [0, 1] (1: every point
        on a mapped wall).
    information : ndarray, shape (3, 3)
        Information matrix of the match term (Gauss–Newton Hessian), units 1/m^2,
        1/(m rad), 1/rad^2.
    prior_information : ndarray, shape (3, 3)
        Information matrix of the odometry prediction.
    condition : float
        Smallest / largest eigenvalue of the translational block of ``information``, in
        [0, 1]: near 0 the scan does not constrain some direction (a corridor).
    n_points : int
        Scan returns used.
    accepted : bool
        Whether ``pose`` comes from the match.
    reason : str
        ``"ok"``, ``"degenerate"`` (accepted, one direction kept from odometry),
        ``"few points"``, ``"low score"`` or ``"outside window"``.
    """

    pose: FloatArray
    matched_pose: FloatArray
    score: float
    information: FloatArray
    prior_information: FloatArray
    condition: float
    n_points: int
    accepted: bool
    reason: str

    @property
    def covariance(self) -> FloatArray:
        """Covariance (3, 3) of ``pose``: ``inverse(information + prior_information)`` if
        accepted, the odometry prior's alone if not."""
        information = self.prior_information
        if self.accepted:
            information = information + self.information
        return np.asarray(np.linalg.inv(information), dtype=np.float64)


def search_window(
    translation: float, rotation: float, config: MatcherConfig
) -> tuple[float, float]:
    """Half-widths ``(xy m, heading rad)`` of the search window after an odometry motion of
    ``translation`` m and ``rotation`` rad since the last matched scan."""
    angle = (
        config.angle_window_base
        + config.angle_window_per_rad * abs(rotation)
        + config.angle_window_per_m * abs(translation)
    )
    xy = (
        config.xy_window_base
        + config.xy_window_per_m * abs(translation)
        + config.xy_window_per_rad * abs(rotation)
    )
    return min(xy, config.xy_window_max), min(angle, config.angle_window_max)


def prior_information(translation: float, rotation: float, config: MatcherConfig) -> FloatArray:
    """Information matrix (3, 3) of the odometry prediction after a motion of
    ``translation`` m and ``rotation`` rad."""
    xy_std = config.prior_xy_std_base + config.prior_xy_std_per_m * abs(translation)
    angle_std = config.prior_angle_std_base + config.prior_angle_std_per_rad * abs(rotation)
    return np.diag([xy_std**-2, xy_std**-2, angle_std**-2])


def translational_condition(information: FloatArray) -> tuple[float, FloatArray]:
    """Smallest / largest eigenvalue of the translational (2 x 2) block of an information
    matrix, in [0, 1], and the unit eigenvector of the smallest (the weakest direction)."""
    a, b, d = float(information[0, 0]), float(information[0, 1]), float(information[1, 1])
    half_trace = 0.5 * (a + d)
    root = math.sqrt(max(0.25 * (a - d) ** 2 + b * b, 0.0))
    largest, smallest = half_trace + root, half_trace - root
    if abs(b) > 1e-12 * max(largest, 1e-300):
        weak = np.array([smallest - d, b])
        weak /= math.hypot(weak[0], weak[1])
    else:
        weak = np.array([1.0, 0.0]) if a <= d else np.array([0.0, 1.0])
    condition = max(smallest, 0.0) / largest if largest > 0 else 0.0
    return condition, weak


def match_scan(
    grid: OccupancyGrid,
    ranges: FloatArray,
    max_range: float,
    predicted: FloatArray,
    translation: float,
    rotation: float,
    config: MatcherConfig,
    normals: FloatArray | None = None,
) -> MatchResult:
    """Match a scan to a grid's map, seeded by an odometry prediction.

    Parameters
    ----------
    grid : OccupancyGrid
        The map (its likelihood fields).
    ranges : ndarray, shape (N,), float64
        The scan, beam i at ``-pi + i 2 pi / N`` from the heading; ``>= max_range`` is no
        return.
    max_range : float
        m.
    predicted : ndarray, shape (3,)
        Odometry prediction of the sensor pose in the map frame.
    translation, rotation : float
        Odometry motion since the last matched scan (m, rad, absolute values): they set
        the search window and the prior.
    config : MatcherConfig
    normals : ndarray, shape (N, 2), optional
        The scan's normals (:func:`~mrslam_env.slam.scan.scan_normals`), if already known.

    Returns
    -------
    MatchResult
    """
    predicted = np.asarray(predicted, dtype=np.float64)
    ranges = np.asarray(ranges, dtype=np.float64)
    min_range = grid.config.min_range
    prior = prior_information(translation, rotation, config)
    if normals is None:
        normals = scan_normals(ranges, max_range, min_range)
    xy_window, angle_window = search_window(translation, rotation, config)
    ox, oy = grid.origin
    resolution = grid.resolution
    x, y, theta, score, information, n_points = _match(
        grid.fine_fields, grid.fine_scale, grid.coarse_field, grid.coarse_scale,
        ox, oy, resolution, grid.config.fine_sigma,
        ranges, normals, max_range, min_range, predicted, xy_window, angle_window, prior,
        config.coarse_point_stride, config.coarse_angle_step,
        max(1, round(config.coarse_xy_step / resolution)),
        config.fine_angle_step, config.fine_search_cells,
        config.prior_weight, config.residual_std, config.refine_iterations,
    )  # fmt: skip
    matched = np.array([x, y, theta])
    condition, weak = translational_condition(information)
    correction = matched - predicted
    correction[2] = math.remainder(correction[2], 2.0 * math.pi)
    reason = "ok"
    if n_points < config.min_points:
        reason = "few points"
    elif score < config.min_score:
        reason = "low score"
    # The refinement may step a little past the searched window (when the truth lies just
    # outside it); anything further is a jump.
    elif (
        abs(correction[0]) > 1.5 * xy_window + resolution
        or abs(correction[1]) > 1.5 * xy_window + resolution
        or abs(correction[2]) > 1.5 * angle_window
    ):
        reason = "outside window"
    accepted = reason == "ok"
    if not accepted:
        pose = predicted.copy()
    else:
        if condition < config.degenerate_ratio:
            correction[:2] -= weak * float(weak @ correction[:2])
            reason = "degenerate"
        pose = predicted + correction
        pose[2] = math.remainder(pose[2], 2.0 * math.pi)
    return MatchResult(
        pose=pose,
        matched_pose=matched,
        score=score,
        information=information,
        prior_information=prior,
        condition=condition,
        n_points=n_points,
        accepted=accepted,
        reason=reason,
    )
