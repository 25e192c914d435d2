"""Where a robot may start: the one clearance rule of every automatic start pose.

Automatic starts are drawn in three places, each with its own way of spreading them out:
the simulator (:func:`mrslam_env.sim.simulator.choose_starts`, robots beyond the given
starts), worlds built from maps (:func:`mrslam_env.sim.mapworld.world_from_map`, before
any start exists) and the merge benchmark's runs
(:func:`scenarios.bench.merge.pairs.reachable_starts`). All three draw from the cells of
:func:`start_cells` (or :func:`world_start_points` for a :class:`WorldSpec`):

**The start clearance rule.** On a raster of wall cells, a cell's *clearance estimate* is
the distance from its centre to the nearest wall cell's centre, less half a cell
(:func:`cell_clearance`). A robot of radius ``r`` *fits* in a cell whose estimate is at
least ``r``; it can *start* in a cell that

* lies in the 4-connected region of *passable* cells (estimate at least
  ``r + PASSAGE_MARGIN``) that holds the reference cell (the world's first start; the
  largest such region when there is none), so that every start can plan a path to every
  other with the planner's safety margin, and
* has an estimate of at least ``r + START_MARGIN``.

The estimate is never below the true distance from the cell centre to the wall cells,
and at most ``(sqrt(2) - 1) / 2`` of a cell (0.21 cell) above it (a wall cell straight
across is exactly half a cell nearer than its centre, a diagonal one up to half a
diagonal nearer). A start cell's true clearance is therefore at least
``r + START_MARGIN - 0.21 * resolution``: 0.28 m beyond the radius on the 0.1 m raster
of a world (:data:`START_RESOLUTION`), more on finer map grids.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from mrslam_env.sim.world import WorldSpec, ground_truth_map

__all__ = [
    "PASSAGE_MARGIN",
    "START_MARGIN",
    "START_RESOLUTION",
    "cell_clearance",
    "reachable_floor",
    "start_cells",
    "world_start_points",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

START_MARGIN = 0.3
"""Clearance estimate beyond the robot radius that an automatic start needs, m."""
PASSAGE_MARGIN = 0.1
"""Clearance estimate beyond the robot radius that the passages between starts need, m:
the planner keeps ``PlannerConfig.safety_margin`` (0.08 m) beyond the radius clear, so a
gap a robot fits through by less is one it does not plan through while anything else is
left (only the explorer's last-resort plan, on the bare footprint, takes it; ``planner_test``:
robot 0's start room joins the rest only through gaps 0.20-0.24 m beyond the centre line)."""

START_RESOLUTION = 0.1
"""Cell size of the raster on which starts in a :class:`WorldSpec` are chosen, m."""


def cell_clearance(walls: ArrayLike, resolution: float) -> FloatArray:
    """The clearance estimate (m) of every cell: the distance from its centre to the
    nearest wall cell's centre, less half a cell (module docstring); negative on walls.

    Parameters
    ----------
    walls : array_like of bool, shape (rows, cols)
        Wall cells. Cells beyond the raster count as free: frame the raster with walls
        (or leave a margin) where the outside is closed.
    resolution : float
        Cell size, m.

    Returns
    -------
    ndarray of float64, shape (rows, cols)
    """
    free = ~np.asarray(walls, dtype=bool)
    return (ndimage.distance_transform_edt(free) - 0.5) * resolution


def start_cells(
    walls: ArrayLike,
    resolution: float,
    radius: float,
    *,
    reachable_from: tuple[int, int] | None = None,
) -> BoolArray:
    """The cells where a robot of ``radius`` can start, by the start clearance rule
    (module docstring).

    Parameters
    ----------
    walls : array_like of bool, shape (rows, cols)
        Wall cells (see :func:`cell_clearance`).
    resolution : float
        Cell size, m.
    radius : float
        Robot radius, m (>= 0).
    reachable_from : tuple of int, optional
        ``(row, col)`` of a cell the starts must be reachable from (the first start);
        default: the largest region of passable cells. A cell off the raster, or where
        the robot does not fit, reaches nothing.

    Returns
    -------
    ndarray of bool, shape (rows, cols)
        All False when there is no such cell.
    """
    clearance = cell_clearance(walls, resolution)
    labels, count = ndimage.label(clearance >= radius + PASSAGE_MARGIN)
    if reachable_from is None:
        if count == 0:
            return np.zeros(clearance.shape, dtype=bool)
        sizes = np.bincount(labels.ravel())
        sizes[0] = 0
        label = int(np.argmax(sizes))
    else:
        row, col = int(reachable_from[0]), int(reachable_from[1])
        rows, cols = clearance.shape
        if not (0 <= row < rows and 0 <= col < cols) or labels[row, col] == 0:
            return np.zeros(clearance.shape, dtype=bool)
        label = int(labels[row, col])
    return (labels == label) & (clearance >= radius + START_MARGIN)


def reachable_floor(
    free: ArrayLike,
    walls: ArrayLike,
    resolution: float,
    radius: float,
    seeds: ArrayLike,
    margin: float,
) -> BoolArray:
    """The floor a robot of ``radius`` can get to from the ``seeds`` cells, by the passage
    rule of the starts (module docstring) with clearance ``radius + margin``: the free
    cells within ``sqrt(2) (radius + margin)`` plus one cell, through free cells, of the
    regions of *passable* cells (4-connected, clearance estimate at least ``radius +
    margin``) that hold a seed. So a room's floor counts up to its walls and into its
    corners, but a room (or alcove) joined to the seeds' regions only through gaps
    narrower than that counts only for that distance past its gap. A seed outside every
    passable region (a hand-placed start in a tight spot) contributes its whole free
    8-connected component instead.

    Parameters
    ----------
    free : array_like of bool, shape (rows, cols)
        Free (floor) cells.
    walls : array_like of bool, shape (rows, cols)
        Wall cells (see :func:`cell_clearance`).
    resolution : float
        Cell size, m.
    radius : float
        Robot radius, m (>= 0).
    seeds : array_like of int, shape (k, 2)
        ``(row, col)`` of the starts; those off the raster are ignored.
    margin : float
        Clearance beyond the radius a passage needs, m (the starts' rule uses
        ``PASSAGE_MARGIN``).

    Returns
    -------
    ndarray of bool, shape (rows, cols)
    """
    free = np.asarray(free, dtype=bool)
    clear = radius + margin
    labels, _ = ndimage.label(cell_clearance(walls, resolution) >= clear)
    components, _ = ndimage.label(free, structure=np.ones((3, 3), dtype=bool))
    rows, cols = free.shape
    cells = np.asarray(seeds, dtype=np.int64).reshape(-1, 2)
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < rows) & (cells[:, 1] >= 0) & (cells[:, 1] < cols)
    cells = cells[inside]
    passable = labels[cells[:, 0], cells[:, 1]]
    region = np.isin(labels, passable[passable > 0])
    if region.any():
        steps = int(np.ceil(np.sqrt(2.0) * clear / resolution)) + 1
        region = ndimage.binary_dilation(
            region, structure=np.ones((3, 3), dtype=bool), iterations=steps, mask=free
        )
    tight = cells[passable == 0]
    loose = components[tight[:, 0], tight[:, 1]]
    region |= np.isin(components, loose[loose > 0])
    return region & free


def world_start_points(world: WorldSpec, radius: float, reachable_from: ArrayLike) -> FloatArray:
    """World points (N, 2) where a robot of ``radius`` can start, reachable from the point
    ``reachable_from`` (x, y): the centres of the :func:`start_cells` of the world's
    ground-truth raster (:func:`~mrslam_env.sim.world.ground_truth_map`,
    :data:`START_RESOLUTION`, one cell of margin), in row-major order.
    """
    grid = ground_truth_map(world, START_RESOLUTION, margin=START_RESOLUTION)
    iy, ix = grid.world_to_cell(np.asarray(reachable_from, dtype=np.float64)[:2])
    cells = start_cells(grid.occupied, START_RESOLUTION, radius, reachable_from=(iy, ix))
    return grid.cell_to_world(np.argwhere(cells))
