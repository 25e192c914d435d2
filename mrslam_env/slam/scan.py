"""A lidar scan as geometry: its returns as points and their surface normals.

Beam ``i`` of ``N`` points at ``-pi + i 2 pi / N`` from the sensor's heading, as in
:func:`mrslam_env.sim.lidar.beam_angles`; a range at or beyond the maximum range is no return.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

__all__ = [
    "NORMAL_HALF_WIDTH",
    "NORMAL_MAX_GAP",
    "NORMAL_MAX_HALF_WIDTH",
    "NORMAL_MIN_SPAN",
    "mask_returns_near",
    "scan_normals",
    "scan_points",
    "sighted_positions",
]

NORMAL_HALF_WIDTH = 2
"""Neighbours either side (beams) that :func:`scan_normals` fits a line through, at
least."""

NORMAL_MIN_SPAN = 0.2
"""Length of surface (m) a normal is fitted over, at least: near the sensor, where beams
are closer than ``NORMAL_MIN_SPAN / (2 NORMAL_HALF_WIDTH)``, :func:`scan_normals` takes more
neighbours (up to ``NORMAL_MAX_HALF_WIDTH`` either side), so that texture shorter than
this (the 5 cm steps of a wall rasterised from a map, clutter) does not set a surface's
direction. With five beams (2 cm at 0.3 m), a rasterised diagonal wall seen close gave
the normals of single steps, or none (not line-like), and the matcher drifted up to 1.8°
in heading along such a corridor (docs/decisions.md, "Onboard SLAM")."""

NORMAL_MAX_HALF_WIDTH = 16
"""Cap on the neighbours either side that ``NORMAL_MIN_SPAN`` may ask for (reached within
0.36 m of a 1° lidar)."""

NORMAL_MAX_GAP = 0.05
"""Neighbours further apart than this (m) plus twice the beam spacing at the return's range
are not on the same surface."""


@numba.njit(cache=True)
def scan_points(ranges: FloatArray, max_range: float, min_range: float) -> FloatArray:
    """Returns of a scan as points (M, 2) in the sensor frame, m.

    Beam i points at ``-pi + i 2 pi / N``; beams at or beyond ``max_range`` (no return),
    below ``min_range`` or NaN are left out.
    """
    n = ranges.shape[0]
    dtheta = 2.0 * math.pi / n
    points = np.empty((n, 2))
    count = 0
    for i in range(n):
        r = ranges[i]
        if min_range <= r < max_range:
            a = -math.pi + i * dtheta
            points[count, 0] = r * math.cos(a)
            points[count, 1] = r * math.sin(a)
            count += 1
    return points[:count]


@numba.njit(cache=True)
def scan_normals(
    ranges: FloatArray,
    max_range: float,
    min_range: float,
    half_width: int = NORMAL_HALF_WIDTH,
    max_gap: float = NORMAL_MAX_GAP,
    min_span: float = NORMAL_MIN_SPAN,
    max_half_width: int = NORMAL_MAX_HALF_WIDTH,
) -> FloatArray:
    """Unit surface normals (N, 2) of a scan's returns, sensor frame, facing the sensor.

    The normal of a return is the direction of least spread (total least squares) of it
    and its returning neighbours up to ``half_width`` beams either side (more where the
    beams are close: as many as span ``min_span`` m of surface, capped at
    ``max_half_width``) that lie within ``max_gap`` m plus twice the beam spacing at its
    range (or plus ``min_span / 2``, if that is more), turned to face the sensor.
    Beams without a return, returns with fewer than two such neighbours, and returns whose
    neighbourhood is not line-like (spread across above a quarter of the spread along) get
    ``(0, 0)``. Row i belongs to beam i (not compacted like :func:`scan_points`).
    """
    n = ranges.shape[0]
    dtheta = 2.0 * math.pi / n
    xs = np.empty(n)
    ys = np.empty(n)
    valid = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        r = ranges[i]
        if min_range <= r < max_range:
            a = -math.pi + i * dtheta
            xs[i] = r * math.cos(a)
            ys[i] = r * math.sin(a)
            valid[i] = True
    normals = np.zeros((n, 2))
    for i in range(n):
        if not valid[i]:
            continue
        spacing = ranges[i] * dtheta
        limit = max(max_gap + 2.0 * spacing, max_gap + 0.5 * min_span)
        reach = max(half_width, min(math.ceil(0.5 * min_span / spacing), max_half_width))
        sx = sy = sxx = syy = sxy = 0.0
        members = 0
        for k in range(-reach, reach + 1):
            j = (i + k) % n
            if not valid[j]:
                continue
            dx, dy = xs[j] - xs[i], ys[j] - ys[i]
            if dx * dx + dy * dy > limit * limit:
                continue
            sx += dx
            sy += dy
            sxx += dx * dx
            syy += dy * dy
            sxy += dx * dy
            members += 1
        if members < 3:
            continue
        mx, my = sx / members, sy / members
        cxx = sxx / members - mx * mx
        cyy = syy / members - my * my
        cxy = sxy / members - mx * my
        half_trace = 0.5 * (cxx + cyy)
        root = math.sqrt(max(0.25 * (cxx - cyy) ** 2 + cxy * cxy, 0.0))
        largest, smallest = half_trace + root, half_trace - root
        if not (largest > 0.0 and smallest <= 0.0625 * largest):
            continue
        # Eigenvector of the smallest eigenvalue of the 2 x 2 covariance.
        if abs(cxy) > 1e-15:
            nx, ny = smallest - cyy, cxy
        elif cxx <= cyy:
            nx, ny = 1.0, 0.0
        else:
            nx, ny = 0.0, 1.0
        norm = math.sqrt(nx * nx + ny * ny)
        if nx * xs[i] + ny * ys[i] > 0.0:  # face the sensor
            norm = -norm
        normals[i, 0] = nx / norm
        normals[i, 1] = ny / norm
    return normals


def sighted_positions(peers: ArrayLike) -> FloatArray:
    """Sensor-frame positions (K, 2) of the robots a peer observation detects (rows
    ``(detected, range, bearing, heading)``; rows with ``detected`` < 0.5 are skipped)."""
    rows = np.asarray(peers, dtype=np.float64).reshape(-1, 4)
    rows = rows[rows[:, 0] > 0.5]
    return rows[:, 1:2] * np.column_stack([np.cos(rows[:, 2]), np.sin(rows[:, 2])])


def mask_returns_near(
    ranges: FloatArray, points: FloatArray, radius: float, max_range: float
) -> FloatArray:
    """A copy of ``ranges`` with the returns that end within ``radius`` (m) of any of
    ``points`` (K, 2), sensor frame, set to NaN (skipped by mapping and matching).

    SLAM maps a static world: another robot is not part of it. Where the peer sensor
    says a robot stands, its returns would put a phantom wall into the map and, when the
    robots touch, pull the scan match; they are dropped before SLAM sees the scan.
    """
    out = np.array(ranges, dtype=np.float64)
    peers = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(peers) == 0:
        return out
    n = len(out)
    angles = -np.pi + np.arange(n) * (2.0 * np.pi / n)
    returned = out < max_range
    ends = out[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
    distance = np.linalg.norm(ends[:, None, :] - peers[None, :, :], axis=2).min(axis=1)
    out[returned & (distance <= radius)] = np.nan
    return out
