"""Step 3 of frontier extraction: what a frontier is worth (docs/design.md §6, building
blocks).

The information gain of a frontier is the unknown area within sensor range of its goal:
:func:`information_gain` reads all of it in the square around the goal from an integral
image of the known cells (:func:`known_integral_image`), O(1) per point (a cheap upper
bound); :func:`connected_information_gain` counts only the unknown space that the frontier
opens onto (its 4-connected unknown regions), so that unknown space behind a mapped wall
(outside the building, inside a pillar) does not lure the robot. :mod:`agents.frontiers`
re-exports them.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from mrslam_env.gridmap import GridMap

__all__ = ["connected_information_gain", "information_gain", "known_integral_image"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def known_integral_image(grid: GridMap) -> NDArray[np.int64]:
    """Summed-area table of the known (FREE or OCCUPIED) cells.

    Returns
    -------
    ndarray of int64, shape (rows + 1, cols + 1)
        ``table[r, c]`` = number of known cells in ``cells[:r, :c]``.
    """
    known = (~grid.unknown).astype(np.int64)
    table = np.zeros((grid.shape[0] + 1, grid.shape[1] + 1), dtype=np.int64)
    table[1:, 1:] = known.cumsum(axis=0).cumsum(axis=1)
    return table


def information_gain(
    grid: GridMap,
    points: ArrayLike,
    sensor_range: float,
    *,
    integral: NDArray[np.int64] | None = None,
) -> FloatArray:
    """Unknown area in the square of half-width ``sensor_range`` around each point.

    Space outside the grid is unknown (the SLAM grid only covers what was seen, plus a
    margin). Walls are ignored, so unknown space behind them counts too: a cheap upper
    bound, good enough to rank frontiers.

    Parameters
    ----------
    grid : GridMap
    points : array_like, shape (N, 2)
        Map-frame ``(x, y)``, m.
    sensor_range : float
        m.
    integral : ndarray, optional
        :func:`known_integral_image` of ``grid``, to share between calls.

    Returns
    -------
    ndarray of float64, shape (N,)
        m².
    """
    table = known_integral_image(grid) if integral is None else integral
    cells = grid.world_to_cell(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    half = max(round(sensor_range / grid.resolution), 0)
    rows, cols = grid.shape
    r0 = np.clip(cells[:, 0] - half, 0, rows)
    r1 = np.clip(cells[:, 0] + half + 1, 0, rows)
    c0 = np.clip(cells[:, 1] - half, 0, cols)
    c1 = np.clip(cells[:, 1] + half + 1, 0, cols)
    known = table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]
    box = (2 * half + 1) ** 2
    return (box - known).astype(np.float64) * grid.resolution**2


def connected_information_gain(
    grid: GridMap,
    labels: NDArray[np.int32],
    points: ArrayLike,
    sensor_range: float,
    *,
    min_open_fraction: float = 0.0,
    cells: tuple[IntArray, IntArray] | None = None,
) -> FloatArray:
    """Unknown area near each frontier's goal that the frontier actually opens onto.

    Unknown space is split into 4-connected regions (a mapped wall, even a diagonal run of
    cells, separates them; cells outside the grid join the region touching the border).
    Frontier ``f`` counts, in the square of half-width ``sensor_range`` around
    ``points[f]``, only the cells of the regions adjacent to its own cells. A region inside
    the grid whose border is almost all wall (FREE on less than ``min_open_fraction`` of
    its border) is the inside of an obstacle seen through a gap in its mapped outline and
    counts nothing.

    Parameters
    ----------
    grid : GridMap
    labels : ndarray of int32, shape (rows, cols)
        Frontier index + 1 per cell (:func:`cluster_frontiers`), F frontiers.
    points : array_like, shape (F, 2)
        Map-frame goal of each frontier, m.
    sensor_range : float
        m.
    min_open_fraction : float
        In [0, 1].
    cells : tuple of two int arrays, optional
        ``np.nonzero(labels)``, if already known.

    Returns
    -------
    ndarray of float64, shape (F,)
        m².
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    count = len(points)
    gains = np.zeros(count)
    if count == 0:
        return gains
    unknown = np.pad(grid.unknown, 1, constant_values=True)
    regions, region_count = ndimage.label(unknown)
    outside = regions[0, 0]
    # The unknown regions each frontier touches: labels of its cells' 4-neighbours.
    frontier_rows, frontier_cols = np.nonzero(labels) if cells is None else cells
    owner = labels[frontier_rows, frontier_cols] - 1
    touches = np.zeros((count, region_count + 1), dtype=bool)
    for d_row, d_col in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        touched = regions[frontier_rows + 1 + d_row, frontier_cols + 1 + d_col]
        touches[owner, touched] = True
    touches[:, 0] = False
    touches[
        :, _enclosed_regions(regions, region_count, np.pad(grid.free, 1), min_open_fraction)
    ] = False
    half = max(round(sensor_range / grid.resolution), 0)
    box = (2 * half + 1) ** 2
    centres = grid.world_to_cell(points) + 1  # padded coordinates
    counts, sizes = _touched_in_squares(regions, touches, centres, half, outside)
    for frontier in range(count):
        seen = int(counts[frontier])
        if outside and touches[frontier, outside]:
            seen += box - int(sizes[frontier])  # the square's part beyond the padded grid
        gains[frontier] = seen
    return gains * grid.resolution**2


@numba.njit(cache=True)
def _touched_in_squares(
    regions: NDArray[np.int32], touches: BoolArray, centres: IntArray, half: int, outside: int
) -> tuple[IntArray, IntArray]:
    """Per frontier ``f``, the cells of the square of half-width ``half`` around
    ``centres[f]`` (clipped to ``regions``) whose region ``f`` touches, and the number of
    cells of the clipped square. A frontier that touches the region ``outside`` (> 0) and
    no other (the usual case) counts them from a summed-area table of that region."""
    rows, cols = regions.shape
    count = len(centres)
    counts = np.zeros(count, dtype=np.int64)
    sizes = np.zeros(count, dtype=np.int64)
    only_outside = np.zeros(count, dtype=np.bool_)
    if outside > 0:
        for f in range(count):
            only = touches[f, outside]
            for region in range(touches.shape[1]):
                if only and region != outside and touches[f, region]:
                    only = False
            only_outside[f] = only
    use_table = only_outside.any()
    table = np.zeros((rows + 1, cols + 1) if use_table else (1, 1), dtype=np.int64)
    if use_table:
        for r in range(rows):
            run = 0
            for c in range(cols):
                run += regions[r, c] == outside
                table[r + 1, c + 1] = table[r, c + 1] + run
    for f in range(count):
        r0, r1 = max(centres[f, 0] - half, 0), min(centres[f, 0] + half + 1, rows)
        c0, c1 = max(centres[f, 1] - half, 0), min(centres[f, 1] + half + 1, cols)
        if r0 >= r1 or c0 >= c1:
            continue
        sizes[f] = (r1 - r0) * (c1 - c0)
        if only_outside[f]:
            counts[f] = table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]
            continue
        total = 0
        for r in range(r0, r1):
            for c in range(c0, c1):
                if touches[f, regions[r, c]]:
                    total += 1
        counts[f] = total
    return counts, sizes


def _enclosed_regions(
    regions: NDArray[np.int32], region_count: int, free: BoolArray, min_open_fraction: float
) -> NDArray[np.bool_]:
    """(region_count + 1,) bool: unknown regions not touching the border whose border
    cells are FREE less than ``min_open_fraction`` of the time (the rest is OCCUPIED)."""
    enclosed = np.zeros(region_count + 1, dtype=bool)
    if min_open_fraction <= 0 or region_count == 0:
        return enclosed
    border = np.zeros(region_count + 1)
    open_border = np.zeros(region_count + 1)
    inner = regions[1:-1, 1:-1]
    for d_row, d_col in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        neighbour = regions[
            1 + d_row : regions.shape[0] - 1 + d_row, 1 + d_col : regions.shape[1] - 1 + d_col
        ]
        neighbour_free = free[
            1 + d_row : free.shape[0] - 1 + d_row, 1 + d_col : free.shape[1] - 1 + d_col
        ]
        edge = (inner > 0) & (neighbour == 0)
        border += np.bincount(inner[edge], minlength=region_count + 1)
        open_border += np.bincount(inner[edge & neighbour_free], minlength=region_count + 1)
    enclosed = open_border < min_open_fraction * np.maximum(border, 1)
    enclosed[0] = False
    enclosed[regions[0, 0]] = False  # the region around the grid is never an obstacle
    return enclosed
