"""Exact 2-D lidar over wall segments and disc-shaped robots (numba kernels).

Beam ``i`` of ``N`` points at ``heading - pi + i * 2 pi / N`` (counter-clockwise, as in a
ROS ``LaserScan`` with ``angle_min = -pi``). A beam returns the distance to the first wall
segment or robot disc it meets, or ``max_range`` when it meets nothing within range.

Instead of testing every beam against every segment, each segment is projected onto the
range of beam indices it subtends as seen from the sensor, and only those beams are
intersected with it: the cost is about ``M + sum of beams per segment`` rather than
``M * N``. Segments whose nearest point is beyond ``max_range`` are skipped.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

__all__ = ["beam_angles", "cast_scan", "line_of_sight", "nearest_segment", "segments_within"]

_TWO_PI = 2.0 * math.pi
_EPS = 1e-9


def beam_angles(n_beams: int) -> FloatArray:
    """Beam angles (N,) relative to the robot heading: ``-pi + i * 2 pi / N``, radians."""
    return -np.pi + np.arange(n_beams, dtype=np.float64) * (2.0 * np.pi / n_beams)


@numba.njit(cache=True)
def _segment_point_distance(
    px: float, py: float, ax: float, ay: float, bx: float, by: float
) -> float:
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    t = 0.0
    if length2 > 0.0:
        t = ((px - ax) * ex + (py - ay) * ey) / length2
        t = min(max(t, 0.0), 1.0)
    dx, dy = ax + t * ex - px, ay + t * ey - py
    return math.sqrt(dx * dx + dy * dy)


@numba.njit(cache=True)
def _beam_index_span(
    angle_lo: float, width: float, alpha0: float, dtheta: float
) -> tuple[int, int]:
    """First and last (unwrapped) beam index whose direction lies in
    ``[angle_lo, angle_lo + width]``; the caller takes indices modulo N."""
    u = (angle_lo - alpha0) % _TWO_PI
    k_lo = math.ceil(u / dtheta - _EPS)
    k_hi = math.floor((u + width) / dtheta + _EPS)
    return k_lo, k_hi


@numba.njit(cache=True)
def cast_scan(
    x: float,
    y: float,
    heading: float,
    n_beams: int,
    max_range: float,
    segments: FloatArray,
    discs: FloatArray,
) -> FloatArray:
    """Cast one full scan.

    Parameters
    ----------
    x, y, heading : float
        Sensor pose in the world frame (m, m, rad).
    n_beams : int
        Number of beams N over the full circle.
    max_range : float
        Maximum range (m), returned for beams that hit nothing.
    segments : ndarray, shape (M, 4), float64
        Wall segments ``(x0, y0, x1, y1)``.
    discs : ndarray, shape (K, 3), float64
        Other bodies as discs ``(cx, cy, radius)``; a disc containing the sensor is ignored
        (that is the scanning robot itself).

    Returns
    -------
    ndarray, shape (N,), float64
        Ranges in metres, in ``(0, max_range]``.
    """
    ranges = np.full(n_beams, max_range)
    dtheta = _TWO_PI / n_beams
    alpha0 = heading - math.pi
    cos_b = np.empty(n_beams)
    sin_b = np.empty(n_beams)
    for i in range(n_beams):
        a = alpha0 + i * dtheta
        cos_b[i] = math.cos(a)
        sin_b[i] = math.sin(a)

    for m in range(segments.shape[0]):
        ax, ay = segments[m, 0] - x, segments[m, 1] - y
        bx, by = segments[m, 2] - x, segments[m, 3] - y
        if _segment_point_distance(0.0, 0.0, ax, ay, bx, by) >= max_range:
            continue
        ex, ey = bx - ax, by - ay
        phi_a = math.atan2(ay, ax)
        phi_b = math.atan2(by, bx)
        span = (phi_b - phi_a + math.pi) % _TWO_PI - math.pi
        start = phi_a if span >= 0.0 else phi_b
        k_lo, k_hi = _beam_index_span(start, abs(span), alpha0, dtheta)
        for k in range(k_lo, k_hi + 1):
            i = k % n_beams
            dx, dy = cos_b[i], sin_b[i]
            denom = dx * ey - dy * ex
            if abs(denom) < 1e-15:
                continue
            t = (ax * ey - ay * ex) / denom
            s = (ax * dy - ay * dx) / denom
            if t > 0.0 and -_EPS <= s <= 1.0 + _EPS and t < ranges[i]:
                ranges[i] = t

    for m in range(discs.shape[0]):
        cx, cy, r = discs[m, 0] - x, discs[m, 1] - y, discs[m, 2]
        d = math.sqrt(cx * cx + cy * cy)
        if d <= r or d - r >= max_range:
            continue
        half = math.asin(r / d)
        k_lo, k_hi = _beam_index_span(math.atan2(cy, cx) - half, 2.0 * half, alpha0, dtheta)
        for k in range(k_lo, k_hi + 1):
            i = k % n_beams
            proj = cx * cos_b[i] + cy * sin_b[i]
            perp2 = d * d - proj * proj
            if proj <= 0.0 or perp2 > r * r:
                continue
            t = proj - math.sqrt(r * r - perp2)
            if t < ranges[i]:
                ranges[i] = t
    return ranges


@numba.njit(cache=True)
def line_of_sight(x0: float, y0: float, x1: float, y1: float, segments: FloatArray) -> bool:
    """True when the open segment from (x0, y0) to (x1, y1) crosses no wall segment."""
    dx, dy = x1 - x0, y1 - y0
    for m in range(segments.shape[0]):
        ax, ay = segments[m, 0] - x0, segments[m, 1] - y0
        ex, ey = segments[m, 2] - segments[m, 0], segments[m, 3] - segments[m, 1]
        denom = dx * ey - dy * ex
        if abs(denom) < 1e-15:
            continue
        t = (ax * ey - ay * ex) / denom
        s = (ax * dy - ay * dx) / denom
        if 0.0 < t < 1.0 and 0.0 <= s <= 1.0:
            return False
    return True


@numba.njit(cache=True)
def nearest_segment(x: float, y: float, segments: FloatArray) -> tuple[float, float, float]:
    """Distance (m) from (x, y) to the nearest segment, and the unit vector pointing from
    that segment's closest point towards (x, y). ``(inf, 0, 0)`` when there are none."""
    best, best_nx, best_ny = math.inf, 0.0, 0.0
    for m in range(segments.shape[0]):
        ax, ay, bx, by = segments[m, 0], segments[m, 1], segments[m, 2], segments[m, 3]
        ex, ey = bx - ax, by - ay
        length2 = ex * ex + ey * ey
        t = 0.0
        if length2 > 0.0:
            t = min(max(((x - ax) * ex + (y - ay) * ey) / length2, 0.0), 1.0)
        dx, dy = x - (ax + t * ex), y - (ay + t * ey)
        d = math.sqrt(dx * dx + dy * dy)
        if d < best:
            best = d
            if d > 0.0:
                best_nx, best_ny = dx / d, dy / d
    return best, best_nx, best_ny


@numba.njit(cache=True)
def segments_within(x: float, y: float, reach: float, segments: FloatArray) -> FloatArray:
    """The segments (K, 4) that come within ``reach`` metres of (x, y)."""
    keep = np.zeros(segments.shape[0], dtype=np.bool_)
    for m in range(segments.shape[0]):
        s = segments[m]
        keep[m] = _segment_point_distance(x, y, s[0], s[1], s[2], s[3]) <= reach
    return segments[keep]
