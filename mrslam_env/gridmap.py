"""A trinary occupancy grid with its place in the world (docs/design.md §2).

``GridMap`` is the exchange type between the simulator's ground truth, map files
(:mod:`mrslam_env.mapio`), SLAM's trinary view and map merging. Cell values follow ROS
``nav_msgs/OccupancyGrid``: ``FREE = 0``, ``OCCUPIED = 100``, ``UNKNOWN = -1`` (int8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import cell_to_world, inverse, world_to_cell

FREE = np.int8(0)
OCCUPIED = np.int8(100)
UNKNOWN = np.int8(-1)

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "GridMap",
    "crop_to_known",
    "grid_footprint",
    "grid_in_frame",
    "known_window",
    "resample_cells",
]

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
        row, col = _first_invalid_cell(cells)
        if row >= 0:
            raise ValueError(
                f"GridMap.cells holds values other than 0, 100, -1 (e.g. {cells[row, col]})"
            )
        if not (np.isfinite(self.resolution) and self.resolution > 0):
            raise ValueError(f"GridMap.resolution must be > 0 m, got {self.resolution}")
        if len(self.origin) != 2 or not np.all(np.isfinite(self.origin)):
            raise ValueError(f"GridMap.origin must be two finite numbers, got {self.origin}")
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))
        object.__setattr__(self, "resolution", float(self.resolution))

    @classmethod
    def trusted(
        cls, cells: NDArray[np.int8], resolution: float, origin: tuple[float, float]
    ) -> GridMap:
        """A GridMap without the checks, for cells that hold only FREE, OCCUPIED and
        UNKNOWN by construction (2-D int8) and a valid placement (float resolution > 0,
        two finite floats): a SLAM grid's trinary view, read every step."""
        grid = object.__new__(cls)
        object.__setattr__(grid, "cells", cells)
        object.__setattr__(grid, "resolution", float(resolution))
        object.__setattr__(grid, "origin", (float(origin[0]), float(origin[1])))
        return grid

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
    target_from_source: ArrayLike,
    origin: tuple[float, float],
    shape: tuple[int, int],
    resolution: float,
) -> NDArray[np.int8]:
    """Resample a grid (nearest cell) onto a raster in another frame, at any resolution.

    Inverse nearest-neighbour mapping: each target cell centre is taken into the source
    frame and gets the class of the source cell under it. Lattice-exact transforms
    (quarter turns, whole-cell shifts at the source's resolution) are reproduced exactly.
    The one warping implementation of the library
    (:func:`mrslam_env.merge.fuse.warp_map` resamples through it).

    Parameters
    ----------
    source : GridMap
        The grid, in its own frame.
    target_from_source : array_like, shape (3,)
        Pose of the source frame in the target frame.
    origin, shape, resolution
        The target raster: outer corner of its cell [0, 0] (m, target frame), (rows, cols),
        cell size (m).

    Returns
    -------
    ndarray of int8, shape ``shape``
        The source cell under each target cell centre; UNKNOWN outside the source grid.
    """
    source_from_target = inverse(np.asarray(target_from_source, dtype=np.float64))
    theta = float(source_from_target[2])
    return _resample_kernel(
        np.ascontiguousarray(source.cells),
        float(source.origin[0]),
        float(source.origin[1]),
        float(source.resolution),
        int(shape[0]),
        int(shape[1]),
        float(origin[0]),
        float(origin[1]),
        float(resolution),
        float(source_from_target[0]),
        float(source_from_target[1]),
        math.cos(theta),
        math.sin(theta),
    )


@numba.njit(cache=True)
def _resample_kernel(
    source: NDArray[np.int8],
    source_x: float,
    source_y: float,
    source_resolution: float,
    rows: int,
    cols: int,
    origin_x: float,
    origin_y: float,
    resolution: float,
    tx: float,
    ty: float,
    cos_t: float,
    sin_t: float,
) -> NDArray[np.int8]:
    """Inverse nearest-neighbour mapping: each output cell centre is taken by
    ``(tx, ty, theta)`` = source_from_output into the source grid, whose cell under it
    gives the class (UNKNOWN outside)."""
    source_rows, source_cols = source.shape
    out = np.full((rows, cols), UNKNOWN, dtype=np.int8)
    for row in range(rows):
        y = origin_y + (row + 0.5) * resolution
        for col in range(cols):
            x = origin_x + (col + 0.5) * resolution
            sx = cos_t * x - sin_t * y + tx
            sy = sin_t * x + cos_t * y + ty
            source_col = math.floor((sx - source_x) / source_resolution)
            source_row = math.floor((sy - source_y) / source_resolution)
            if 0 <= source_row < source_rows and 0 <= source_col < source_cols:
                out[row, col] = source[source_row, source_col]
    return out


def grid_footprint(grid: GridMap, frame_from_grid: FloatArray) -> FloatArray:
    """Corners (4, 2) of a grid's extent in another frame."""
    xmin, ymin, xmax, ymax = grid.extent
    corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
    c, s = math.cos(frame_from_grid[2]), math.sin(frame_from_grid[2])
    return corners @ np.array([[c, s], [-s, c]]) + frame_from_grid[:2]


def crop_to_known(grid: GridMap, margin: int = 0) -> GridMap:
    """The grid cut to the bounding box of its known cells, grown by ``margin`` cells.

    The box is grown with UNKNOWN cells where it passes the grid's edge, so the result
    depends only on the known cells and the lattice: a map padded with unknown cells (as
    gmapping's 4000 x 4000 default) crops to the same grid as the map itself. The frame is
    unchanged (the origin moves with the box).

    Parameters
    ----------
    grid : GridMap
    margin : int
        Unknown cells kept (or added) around the known box, >= 0.

    Returns
    -------
    GridMap
        ``grid`` itself when it has no known cell or is already the box.
    """
    if margin < 0:
        raise ValueError(f"margin must be >= 0 cells, got {margin}")
    # One pass over the cells without a temporary as large as the grid: a 4000 x 4000
    # map costs no more memory to crop than its known box.
    low_row, high_row, low_col, high_col = _known_box(grid.cells)
    if high_row < 0:
        return grid
    r0, r1 = low_row - margin, high_row + 1 + margin
    c0, c1 = low_col - margin, high_col + 1 + margin
    rows, cols = grid.shape
    if (r0, c0, r1, c1) == (0, 0, rows, cols):
        return grid
    cells = np.full((r1 - r0, c1 - c0), UNKNOWN, dtype=np.int8)
    inner = grid.cells[max(r0, 0) : min(r1, rows), max(c0, 0) : min(c1, cols)]
    cells[
        max(-r0, 0) : max(-r0, 0) + inner.shape[0], max(-c0, 0) : max(-c0, 0) + inner.shape[1]
    ] = inner
    origin = (grid.origin[0] + c0 * grid.resolution, grid.origin[1] + r0 * grid.resolution)
    return GridMap(cells=cells, resolution=grid.resolution, origin=origin)


def known_window(
    grid: GridMap, margin: int, *, also: NDArray[np.bool_] | None = None
) -> tuple[slice, slice]:
    """Rows and columns of the bounding box of the map's known cells (and of the True cells
    of ``also``, a mask of the grid's shape) grown by ``margin`` cells and clipped to the
    grid; the whole grid when there is no such cell. One pass over the cells, no
    grid-sized temporary but ``also``'s."""
    rows, cols = grid.shape
    boxes = []
    low_row, high_row, low_col, high_col = _known_box(grid.cells)
    if high_row >= 0:
        boxes.append((low_row, high_row, low_col, high_col))
    if also is not None:
        also_rows = np.flatnonzero(also.any(axis=1))
        if len(also_rows):
            also_cols = np.flatnonzero(also[also_rows[0] : also_rows[-1] + 1].any(axis=0))
            boxes.append(
                (int(also_rows[0]), int(also_rows[-1]), int(also_cols[0]), int(also_cols[-1]))
            )
    if not boxes:
        return slice(0, rows), slice(0, cols)
    r0, r1 = min(b[0] for b in boxes), max(b[1] for b in boxes)
    c0, c1 = min(b[2] for b in boxes), max(b[3] for b in boxes)
    return (
        slice(max(r0 - margin, 0), min(r1 + margin + 1, rows)),
        slice(max(c0 - margin, 0), min(c1 + margin + 1, cols)),
    )


def grid_in_frame(grid: GridMap, frame_from_grid: ArrayLike) -> GridMap:
    """The grid resampled (nearest cell, :func:`resample_cells`) into another frame, at its
    own resolution, axis-aligned in that frame.

    The raster is the bounding box of the grid's footprint in the frame (cells outside
    the grid are UNKNOWN). A quarter turn with a lattice-exact translation reproduces every
    cell; any other rotation is the nearest-cell picture of the turned grid (a wall one
    cell thick stays unbroken: turned by less than 45 degrees, it still covers a cell
    centre in every row or column it crosses).

    Parameters
    ----------
    grid : GridMap
    frame_from_grid : array_like, shape (3,)
        Pose of the grid's frame in the target frame (m, m, rad).

    Returns
    -------
    GridMap
        ``grid`` itself when ``frame_from_grid`` is the identity.
    """
    transform = np.asarray(frame_from_grid, dtype=np.float64)
    if transform.shape != (3,) or not np.all(np.isfinite(transform)):
        raise ValueError(f"frame_from_grid must be 3 finite numbers, got {frame_from_grid!r}")
    if not transform.any():
        return grid
    corners = grid_footprint(grid, transform)
    resolution = grid.resolution
    low = corners.min(axis=0)
    span = corners.max(axis=0) - low
    # Shave float noise so that a quarter turn of an n x m grid is exactly m x n cells.
    cols, rows = (math.ceil(float(v) / resolution - 1e-6) for v in span)
    origin = (float(low[0]), float(low[1]))
    cells = resample_cells(grid, transform, origin, (max(rows, 1), max(cols, 1)), resolution)
    return GridMap(cells=cells, resolution=resolution, origin=origin)


@numba.njit(cache=True)
def _known_box(cells: NDArray[np.int8]) -> tuple[int, int, int, int]:
    """First and last row, first and last column holding a known cell; (-1, -1, -1, -1)
    when none is known."""
    rows, cols = cells.shape
    low_row, high_row, low_col, high_col = -1, -1, cols, -1
    for row in range(rows):
        first = -1
        for col in range(cols):
            if cells[row, col] != -1:
                first = col
                break
        if first < 0:
            continue
        if low_row < 0:
            low_row = row
        high_row = row
        low_col = min(low_col, first)
        for col in range(cols - 1, max(first, high_col) - 1, -1):
            if cells[row, col] != -1:
                high_col = max(high_col, col)
                break
    if low_row < 0:
        return -1, -1, -1, -1
    return low_row, high_row, low_col, high_col


@numba.njit(cache=True)
def _first_invalid_cell(cells: NDArray[np.int8]) -> tuple[int, int]:
    """(row, col) of the first cell that is not FREE, OCCUPIED or UNKNOWN, or (-1, -1): one
    pass with no temporary and no branch per cell (the check runs on every map built)."""
    for row in range(cells.shape[0]):
        bad = False
        for col in range(cells.shape[1]):
            value = cells[row, col]
            bad |= (value != 0) & (value != 100) & (value != -1)
        if bad:
            for col in range(cells.shape[1]):
                value = cells[row, col]
                if value != 0 and value != 100 and value != -1:
                    return row, col
    return -1, -1
