"""A trinary occupancy grid with its place in the world (docs/design.md §2).

``GridMap`` is the exchange type between the simulator's ground truth, map files
(:mod:`mrslam_env.mapio`), SLAM's trinary view and map merging. Cell values follow ROS
``nav_msgs/OccupancyGrid``: ``FREE = 0``, ``OCCUPIED = 100``, ``UNKNOWN = -1`` (int8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import cell_to_world, inverse, world_to_cell

FREE = np.int8(0)
OCCUPIED = np.int8(100)
UNKNOWN = np.int8(-1)

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "GridMap", "grid_footprint", "resample_cells"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class GridMap:
    """A trinary occupancy grid.

    Attributes
    ----------
    cells : ndarray of int8, shape (rows, cols)
        ``FREE``, ``OCCUPIED`` or ``UNKNOWN``; row 0 is the lowest y.
    resolution : float
        Cell edge length in metres.
    origin : tuple of float
        World ``(x, y)`` of the outer corner of cell [0, 0], metres.
    """

    cells: NDArray[np.int8]
    resolution: float
    origin: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        cells = np.asarray(self.cells)
        if cells.ndim != 2:
            raise ValueError(f"GridMap.cells must be 2-D, got shape {cells.shape}")
        if cells.dtype != np.int8:
            raise ValueError(f"GridMap.cells must be int8, got {cells.dtype}")
        bad = ~np.isin(cells, (FREE, OCCUPIED, UNKNOWN))
        if bad.any():
            raise ValueError(
                f"GridMap.cells holds values other than 0, 100, -1 (e.g. {cells[bad][0]})"
            )
        if not (np.isfinite(self.resolution) and self.resolution > 0):
            raise ValueError(f"GridMap.resolution must be > 0 m, got {self.resolution}")
        if len(self.origin) != 2 or not np.all(np.isfinite(self.origin)):
            raise ValueError(f"GridMap.origin must be two finite numbers, got {self.origin}")
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))
        object.__setattr__(self, "resolution", float(self.resolution))

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.cells.shape[0]), int(self.cells.shape[1]))

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """World bounds ``(xmin, ymin, xmax, ymax)`` in metres."""
        rows, cols = self.shape
        x0, y0 = self.origin
        return (x0, y0, x0 + cols * self.resolution, y0 + rows * self.resolution)

    def world_to_cell(self, points: ArrayLike) -> NDArray[np.int64]:
        """Cell indices ``(iy, ix)`` of world points ``(x, y)``, not clipped."""
        return world_to_cell(points, self.origin, self.resolution)

    def cell_to_world(self, cells: ArrayLike) -> NDArray[np.float64]:
        """World centres ``(x, y)`` of cells ``(iy, ix)``."""
        return cell_to_world(cells, self.origin, self.resolution)

    def contains(self, cells: ArrayLike) -> NDArray[np.bool_]:
        """Whether cell indices ``(iy, ix)`` lie inside the grid."""
        c = np.asarray(cells)
        rows, cols = self.shape
        return (c[..., 0] >= 0) & (c[..., 0] < rows) & (c[..., 1] >= 0) & (c[..., 1] < cols)

    @property
    def free(self) -> NDArray[np.bool_]:
        return self.cells == FREE

    @property
    def occupied(self) -> NDArray[np.bool_]:
        return self.cells == OCCUPIED

    @property
    def unknown(self) -> NDArray[np.bool_]:
        return self.cells == UNKNOWN


def resample_cells(
    source: GridMap,
    target_from_source: FloatArray,
    origin: tuple[float, float],
    shape: tuple[int, int],
    resolution: float,
) -> NDArray[np.int8]:
    """Resample a grid (nearest cell) onto a raster in another frame.

    Parameters
    ----------
    source : GridMap
        The grid, in its own frame.
    target_from_source : ndarray (3,)
        Pose of the source frame in the target frame.
    origin, shape, resolution
        The target raster: outer corner of its cell [0, 0] (m, target frame), (rows, cols),
        cell size (m).

    Returns
    -------
    ndarray of int8, shape ``shape``
        The source cell under each target cell centre; UNKNOWN outside the source grid.
    """
    rows, cols = shape
    xs = origin[0] + (np.arange(cols) + 0.5) * resolution
    ys = origin[1] + (np.arange(rows) + 0.5) * resolution
    source_from_target = inverse(target_from_source)
    c, s = math.cos(source_from_target[2]), math.sin(source_from_target[2])
    # Points in the source frame, separably: x_s = c x - s y + tx, y_s = s x + c y + ty.
    px = c * xs[None, :] - s * ys[:, None] + source_from_target[0]
    py = s * xs[None, :] + c * ys[:, None] + source_from_target[1]
    ix = np.floor((px - source.origin[0]) / source.resolution).astype(np.int64)
    iy = np.floor((py - source.origin[1]) / source.resolution).astype(np.int64)
    src_rows, src_cols = source.shape
    inside = (ix >= 0) & (ix < src_cols) & (iy >= 0) & (iy < src_rows)
    cells = np.full(shape, UNKNOWN, dtype=np.int8)
    cells[inside] = source.cells[iy[inside], ix[inside]]
    return cells


def grid_footprint(grid: GridMap, frame_from_grid: FloatArray) -> FloatArray:
    """Corners (4, 2) of a grid's extent in another frame."""
    xmin, ymin, xmax, ymax = grid.extent
    corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
    c, s = math.cos(frame_from_grid[2]), math.sin(frame_from_grid[2])
    return corners @ np.array([[c, s], [-s, c]]) + frame_from_grid[:2]
