"""SE(2) poses and grid/world conversions, used everywhere (docs/design.md §2).

A pose or rigid transform is a float64 array ``(x, y, theta)`` in metres and radians,
theta wrapped to (-pi, pi]. Transforms are named by frames: ``map1_from_map2`` maps points
given in map-2's frame into map-1's frame, ``p1 = R(theta) @ p2 + (x, y)``.

Grids are indexed ``[row, col] = [iy, ix]`` with row 0 at the lowest y; a grid has a
``resolution`` (metres per cell) and an ``origin`` (world x, y of the outer corner of cell
[0, 0]); cell (iy, ix) has its centre at ``origin + ((ix + 0.5) * res, (iy + 0.5) * res)``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

__all__ = [
    "cell_to_world",
    "compose",
    "inverse",
    "pose",
    "transform_points",
    "world_to_cell",
    "wrap_angle",
    "wrap_scalar",
]


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Wrap angles (radians) to (-pi, pi]."""
    # mod(pi - a, 2 pi) lies in [0, 2 pi), so the result lies in (-pi, pi].
    return np.pi - np.mod(np.pi - np.asarray(angle, dtype=np.float64), 2.0 * np.pi)


def wrap_scalar(angle: float) -> float:
    """Wrap one angle (radians) to (-pi, pi]; a fast path for Python floats."""
    wrapped = math.remainder(angle, 2.0 * math.pi)
    return math.pi if wrapped <= -math.pi else wrapped


def pose(x: float, y: float, theta: float) -> FloatArray:
    """Build a pose array ``(x, y, theta)`` with theta wrapped."""
    return np.array([x, y, float(wrap_angle(theta))], dtype=np.float64)


def compose(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Return ``a ∘ b``: first apply ``b``, then ``a``.

    If ``a`` is ``world_from_robot`` and ``b`` is ``robot_from_sensor``, the result is
    ``world_from_sensor``. Both inputs have shape (3,) or (..., 3) and broadcast.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def inverse(a: ArrayLike) -> FloatArray:
    """Return the inverse transform: ``inverse(a_from_b)`` is ``b_from_a``."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -(c * a[..., 0] + s * a[..., 1])
    y = -(-s * a[..., 0] + c * a[..., 1])
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def mean_pose(poses: ArrayLike, weights: ArrayLike | None = None) -> FloatArray:
    """The (weighted) mean of poses (K, 3): positions averaged, headings by their unit
    vectors (so that headings either side of ±π average to ±π, not 0)."""
    array = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    w = np.full(len(array), 1.0) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    heading = math.atan2(float(w @ np.sin(array[:, 2])), float(w @ np.cos(array[:, 2])))
    return np.array([float(w @ array[:, 0]), float(w @ array[:, 1]), heading])


def transform_points(a_from_b: ArrayLike, points_in_b: ArrayLike) -> FloatArray:
    """Map points (N, 2) given in frame b into frame a."""
    t = np.asarray(a_from_b, dtype=np.float64)
    p = np.asarray(points_in_b, dtype=np.float64)
    c, s = np.cos(t[2]), np.sin(t[2])
    rotation = np.array([[c, -s], [s, c]])
    return p @ rotation.T + t[:2]


def world_to_cell(points: ArrayLike, origin: ArrayLike, resolution: float) -> IntArray:
    """Cell indices ``(iy, ix)`` (..., 2) int64 of world points ``(x, y)`` (..., 2).

    Indices are not clipped: callers check bounds against their grid's shape.
    """
    p = np.asarray(points, dtype=np.float64)
    o = np.asarray(origin, dtype=np.float64)
    ix = np.floor((p[..., 0] - o[0]) / resolution).astype(np.int64)
    iy = np.floor((p[..., 1] - o[1]) / resolution).astype(np.int64)
    return np.stack([iy, ix], axis=-1)


def cell_to_world(cells: ArrayLike, origin: ArrayLike, resolution: float) -> FloatArray:
    """World coordinates ``(x, y)`` (..., 2) of the centres of cells ``(iy, ix)`` (..., 2)."""
    c = np.asarray(cells, dtype=np.float64)
    o = np.asarray(origin, dtype=np.float64)
    x = o[0] + (c[..., 1] + 0.5) * resolution
    y = o[1] + (c[..., 0] + 0.5) * resolution
    return np.stack([x, y], axis=-1)
