"""Frontier extraction on an occupancy grid (docs/design.md §6, building blocks).

A frontier is the border between known free space and unknown space: where a robot must go
to see more (Yamauchi, "A frontier-based approach for autonomous exploration", 1997).
One step per function:

1. :func:`frontier_cells`: FREE cells with an UNKNOWN 4- or 8-neighbour (cells outside the
   grid count as UNKNOWN); tiny unknown specks inside mapped space (beams too sparse at
   long range) do not count.
2. :func:`cluster_frontiers`: connected components of frontier cells (8-connected), small
   ones dropped, long ones split into pieces of at most ``max_size`` along their main axis.
3. :func:`information_gain`: the unknown area within sensor range of a point, read from an
   integral image of the known cells in O(1) per point (a cheap upper bound), or
   :func:`connected_information_gain`: only the unknown space that the frontier opens onto
   (its 4-connected unknown regions), so that unknown space behind a mapped wall (outside
   the building, inside a pillar) does not lure the robot.
4. :func:`extract_frontiers` puts them together and gives each frontier a goal cell the
   robot can reach and see it from (the reachable cell nearest to the frontier's middle
   with no mapped wall between them).

Steps 1, 2 and 4 live here; step 3 in :mod:`agents.frontiers_gain`, the goal cells of
step 4 in :mod:`agents.frontiers_goals`. Every name is importable from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from agents.frontiers_gain import _touched_in_squares as _touched_in_squares
from agents.frontiers_gain import (
    connected_information_gain,
    information_gain,
    known_integral_image,
)
from agents.frontiers_goals import _goal_cells
from agents.frontiers_goals import _nearest_feature_at as _nearest_feature_at
from mrslam_env.gridmap import OCCUPIED, GridMap, known_window
from mrslam_env.validation import check_fields, require

__all__ = [
    "FrontierConfig",
    "Frontiers",
    "cluster_frontiers",
    "connected_information_gain",
    "extract_frontiers",
    "frontier_cells",
    "information_gain",
    "known_integral_image",
]

GainModel = Literal["box", "connected"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True, slots=True, kw_only=True)
class FrontierConfig:
    """How frontiers are found, grouped and valued."""

    connectivity: int = 4
    """A FREE cell is a frontier cell when one of its 4 (edge) or 8 (edge and corner)
    neighbours is UNKNOWN: 4 or 8."""
    min_unknown_area: float = 0.05
    """Connected UNKNOWN regions smaller than this, m², are specks inside mapped space and
    make no frontier (>= 0; 0 keeps every unknown cell)."""
    min_free_width: int = 3
    """Frontier cells must belong to FREE space at least this many cells wide (a
    morphological opening with a square of this side; 1 turns it off)."""
    min_size: float = 0.25
    """Frontiers shorter than this are dropped, m (size = cell count x resolution)."""
    max_size: float = 3.0
    """Longer frontiers are split into pieces of at most this size, m (> min_size)."""
    sensor_range: float = 4.0
    """Half-width of the square around a goal in which unknown area counts as the
    information gain, m (> 0); a cheap stand-in for the lidar's reach."""
    gain_model: GainModel = "connected"
    """``"box"``: all unknown area in the square (:func:`information_gain`);
    ``"connected"``: only unknown regions the frontier touches
    (:func:`connected_information_gain`)."""
    view_depth: float = 4.0
    """The gain of a frontier is at most its size times this depth, m² per m (> 0): one
    sees only so much through a narrow gap, however much unknown space lies behind it
    (often the outside of the building, behind a wall not yet mapped)."""
    min_open_fraction: float = 0.15
    """With the ``"connected"`` model, an unknown region enclosed in the map whose border
    is FREE on less than this fraction (the rest OCCUPIED) is an obstacle's inside and
    counts no gain, in [0, 1]."""
    max_goal_offset: float = 1.5
    """Largest distance from a frontier cell to the reachable goal cell that views it, m;
    frontiers with no reachable cell this close are dropped (> 0)."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        connectivity = self.connectivity
        require(name, "connectivity", connectivity, connectivity in (4, 8), "4 or 8")
        check_fields(
            self,
            counts=("min_free_width",),
            non_negative=("min_unknown_area", "min_size"),
            positive=("sensor_range", "max_goal_offset", "view_depth"),
        )
        model = self.gain_model
        require(name, "gain_model", model, model in ("box", "connected"), "'box' or 'connected'")
        fraction = self.min_open_fraction
        require(name, "min_open_fraction", fraction, 0 <= fraction <= 1, "in [0, 1]")
        size = self.max_size
        ok = isinstance(size, int | float) and math.isfinite(size) and size > self.min_size
        require(name, "max_size", size, ok, f"a finite number > min_size ({self.min_size})")


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class Frontiers:
    """The frontiers of one map, as parallel arrays (F frontiers).

    Attributes
    ----------
    labels : ndarray of int32, shape (rows, cols)
        Frontier index + 1 of each frontier cell, 0 elsewhere.
    centroids : ndarray of float64, shape (F, 2)
        Map-frame mean ``(x, y)`` of each frontier's cells, m.
    sizes : ndarray of float64, shape (F,)
        Cell count times resolution, m.
    goal_cells : ndarray of int64, shape (F, 2)
        A reachable cell ``(row, col)`` from which the frontier is seen.
    goals : ndarray of float64, shape (F, 2)
        Map-frame centres of ``goal_cells``, m.
    gains : ndarray of float64, shape (F,)
        Unknown area within ``sensor_range`` of the goal (``gain_model``), at most
        ``size * view_depth``, m².
    """

    labels: NDArray[np.int32]
    centroids: FloatArray
    sizes: FloatArray
    goal_cells: IntArray
    goals: FloatArray
    gains: FloatArray

    def __len__(self) -> int:
        return len(self.sizes)

    def cells_of(self, index: int) -> IntArray:
        """Cells ``(row, col)`` (K, 2) of frontier ``index``."""
        return np.argwhere(self.labels == index + 1)


def _padded_unknown(grid: GridMap, min_unknown_area: float) -> BoolArray:
    """UNKNOWN mask padded by one ring of UNKNOWN (outside the grid), specks removed."""
    unknown = np.pad(grid.unknown, 1, constant_values=True)
    min_cells = min_unknown_area / grid.resolution**2
    if min_cells > 1:
        _clear_specks(unknown, min_cells)
    return unknown


@numba.njit(cache=True)
def _fill8(
    mask: BoolArray, labels: NDArray[np.int32], label: int, r0: int, c0: int, queue: IntArray
) -> int:
    """Breadth-first fill of the 8-connected True component of ``mask`` holding cell
    ``(r0, c0)``: its unlabelled cells get ``label`` and their flat indices ``queue[:n]``,
    in the order visited; returns ``n``."""
    cols = mask.shape[1]
    rows = mask.shape[0]
    labels[r0, c0] = label
    queue[0] = r0 * cols + c0
    head, tail = 0, 1
    while head < tail:
        r, c = divmod(queue[head], cols)
        head += 1
        for nr in range(max(r - 1, 0), min(r + 2, rows)):
            for nc in range(max(c - 1, 0), min(c + 2, cols)):
                if mask[nr, nc] and not labels[nr, nc]:
                    labels[nr, nc] = label
                    queue[tail] = nr * cols + nc
                    tail += 1
    return tail


@numba.njit(cache=True)
def _clear_specks(unknown: BoolArray, min_cells: float) -> None:
    """Set False, in place, the 8-connected True components of ``unknown`` with fewer
    than ``min_cells`` cells, except the one holding cell (0, 0) (the outside ring):
    ``ndimage.label`` with the 3 x 3 square and a size test per label, by one
    breadth-first fill per component."""
    rows, cols = unknown.shape
    seen = np.zeros((rows, cols), dtype=np.int32)
    queue = np.empty(rows * cols, dtype=np.int64)
    for r0 in range(rows):
        for c0 in range(cols):
            if not unknown[r0, c0] or seen[r0, c0]:
                continue
            tail = _fill8(unknown, seen, 1, r0, c0, queue)
            if tail < min_cells and (r0 > 0 or c0 > 0):  # the outside is never a speck
                for k in range(tail):
                    r, c = divmod(queue[k], cols)
                    unknown[r, c] = False


def frontier_cells(
    grid: GridMap,
    config: FrontierConfig | None = None,
    *,
    reachable: BoolArray | None = None,
) -> BoolArray:
    """FREE cells next to UNKNOWN space.

    Parameters
    ----------
    grid : GridMap
    config : FrontierConfig, optional
        Uses ``connectivity`` and ``min_unknown_area``.
    reachable : ndarray of bool, shape (rows, cols), optional
        Cells the robot can reach; when given, only frontier cells within
        ``max_goal_offset`` of one are kept.

    Returns
    -------
    ndarray of bool, shape (rows, cols)
    """
    config = config if config is not None else FrontierConfig()
    unknown = _padded_unknown(grid, config.min_unknown_area)
    near_unknown = _dilated_inside(unknown, config.connectivity == 8)
    free = grid.free
    if config.min_free_width > 1:
        # Single beams through gaps leave one-cell-wide streaks of FREE in unknown space
        # (often outside the building): no place to go, and all frontier along their length.
        width = config.min_free_width
        if width % 2:
            free = _open_square(free, width // 2)
        else:
            free = ndimage.binary_opening(free, structure=np.ones((width, width), dtype=bool))
    cells = free & near_unknown
    if reachable is not None:
        cells &= _near_reachable(reachable, grid.resolution, config.max_goal_offset)
    return cells


@numba.njit(cache=True)
def _dilated_inside(padded: BoolArray, corners: bool) -> BoolArray:
    """``ndimage.binary_dilation`` of ``padded`` by the cross (``corners``: the 3 x 3
    square), without its one-cell border."""
    rows, cols = padded.shape[0] - 2, padded.shape[1] - 2
    out = np.empty((rows, cols), dtype=np.bool_)
    for r in range(rows):
        for c in range(cols):
            near = (
                padded[r + 1, c + 1]
                or padded[r, c + 1]
                or padded[r + 2, c + 1]
                or padded[r + 1, c]
                or padded[r + 1, c + 2]
            )
            if corners and not near:
                near = padded[r, c] or padded[r, c + 2] or padded[r + 2, c] or padded[r + 2, c + 2]
            out[r, c] = near
    return out


@numba.njit(cache=True)
def _open_square(mask: BoolArray, half: int) -> BoolArray:
    """Morphological opening by a ``(2 * half + 1)``-square (cells outside are False):
    ``ndimage.binary_opening`` with that structure, by running counts in one pass each."""
    rows, cols = mask.shape
    # Erosion: a cell survives when the whole square around it is True and inside.
    across = np.zeros((rows, cols), dtype=np.bool_)
    for r in range(rows):
        run = 0
        for c in range(cols):
            run = run + 1 if mask[r, c] else 0
            if run >= 2 * half + 1 and c - half >= half:
                across[r, c - half] = True
    eroded = np.zeros((rows, cols), dtype=np.bool_)
    for c in range(cols):
        run = 0
        for r in range(rows):
            run = run + 1 if across[r, c] else 0
            if run >= 2 * half + 1:
                eroded[r - half, c] = True
    # Dilation: a cell is True when a surviving cell lies within the square around it.
    grown = np.zeros((rows, cols), dtype=np.bool_)
    for r in range(rows):
        last = -(10**9)
        for c in range(cols + half):
            if c < cols and eroded[r, c]:
                last = c
            if c - half >= 0 and c - last <= 2 * half:
                grown[r, c - half] = True
    opened = np.zeros((rows, cols), dtype=np.bool_)
    for c in range(cols):
        last = -(10**9)
        for r in range(rows + half):
            if r < rows and grown[r, c]:
                last = r
            if r - half >= 0 and r - last <= 2 * half:
                opened[r - half, c] = True
    return opened


def _near_reachable(reachable: BoolArray, resolution: float, distance: float) -> BoolArray:
    if not reachable.any():
        return np.zeros_like(reachable)
    return np.asarray(ndimage.distance_transform_edt(~reachable) * resolution <= distance)


def cluster_frontiers(
    cells: BoolArray, resolution: float, config: FrontierConfig | None = None
) -> tuple[NDArray[np.int32], int]:
    """Group frontier cells into frontiers.

    8-connected components; components shorter than ``min_size`` are dropped; a component
    longer than ``max_size`` is cut into ``ceil(size / max_size)`` pieces of equal cell
    count along its principal axis.

    Parameters
    ----------
    cells : ndarray of bool, shape (rows, cols)
        Frontier cells (:func:`frontier_cells`).
    resolution : float
        m per cell.
    config : FrontierConfig, optional

    Returns
    -------
    labels : ndarray of int32, shape (rows, cols)
        Frontier index + 1 per cell, 0 = no frontier.
    count : int
        Number of frontiers.
    """
    config = config if config is not None else FrontierConfig()
    # Every component's cells at once, in row-major order within each component.
    cell_rows, cell_cols, bounds, count = _components(np.asarray(cells, dtype=bool))
    labels = np.zeros(cells.shape, dtype=np.int32)
    if count == 0:
        return labels, 0
    min_cells = config.min_size / resolution
    max_cells = max(config.max_size / resolution, 1.0)
    next_label = 1
    for index in range(count):
        begin, end = bounds[index], bounds[index + 1]
        if end - begin < min_cells:
            continue
        rows, cols = cell_rows[begin:end], cell_cols[begin:end]
        pieces = math.ceil((end - begin) / max_cells)
        piece = np.zeros(end - begin, dtype=np.int64)
        if pieces > 1:
            # Cell coordinates from the corner of the component's bounding box.
            local = np.stack([rows - rows.min(), cols - cols.min()], axis=1)
            centred = local - local.mean(axis=0)
            # Principal axis of the cell cloud: the eigenvector of the largest eigenvalue.
            _, vectors = np.linalg.eigh(centred.T @ centred)
            order = np.argsort(centred @ vectors[:, -1], kind="stable")
            piece[order] = np.arange(len(local)) * pieces // len(local)
        labels[rows, cols] = next_label + piece
        next_label += pieces
    return labels, next_label - 1


@numba.njit(cache=True)
def _components(cells: BoolArray) -> tuple[IntArray, IntArray, IntArray, int]:
    """The 8-connected components of the True cells, numbered as ``ndimage.label`` numbers
    them (in row-major order of their first cell), each one's cells in row-major order:
    ``rows``, ``cols`` (all cells, component after component), ``bounds`` (C + 1 entries: the
    cells of component ``k`` are ``[bounds[k], bounds[k + 1])``) and the count C. One
    breadth-first fill per component over the (sparse) True cells, then one counting
    pass."""
    rows, cols = cells.shape
    labels = np.zeros((rows, cols), dtype=np.int32)
    total = 0
    for r in range(rows):
        for c in range(cols):
            total += cells[r, c]
    queue = np.empty(total, dtype=np.int64)
    sizes = np.zeros(total + 1, dtype=np.int64)
    count = 0
    for r0 in range(rows):
        for c0 in range(cols):
            if not cells[r0, c0] or labels[r0, c0]:
                continue
            count += 1
            sizes[count] = _fill8(cells, labels, count, r0, c0, queue)
    bounds = np.zeros(count + 1, dtype=np.int64)
    for k in range(count):
        bounds[k + 1] = bounds[k] + sizes[k + 1]
    fill = bounds.copy()
    out_rows = np.empty(total, dtype=np.int64)
    out_cols = np.empty(total, dtype=np.int64)
    for r in range(rows):
        for c in range(cols):
            k = labels[r, c] - 1
            if k >= 0:
                out_rows[fill[k]] = r
                out_cols[fill[k]] = c
                fill[k] += 1
    return out_rows, out_cols, bounds, count


def extract_frontiers(
    grid: GridMap,
    config: FrontierConfig | None = None,
    *,
    reachable: BoolArray | None = None,
) -> Frontiers:
    """All frontiers of a map with their goals and information gains.

    Parameters
    ----------
    grid : GridMap
    config : FrontierConfig, optional
    reachable : ndarray of bool, shape (rows, cols), optional
        Cells the robot can reach (e.g. ``DistanceField.reachable``). When given, each
        frontier's goal is a reachable cell with no mapped wall between it and one of the
        frontier's cells, and frontiers with none within ``max_goal_offset`` are dropped;
        without it, FREE cells count as reachable.

    Returns
    -------
    Frontiers
        Sorted by decreasing size.
    """
    config = config if config is not None else FrontierConfig()
    reach = grid.free if reachable is None else np.asarray(reachable, dtype=bool)
    if reach.shape != grid.shape:
        raise ValueError(f"reachable has shape {reach.shape}, the map {grid.shape}")
    # The work runs on the known part of the map (the bounding box of the known and
    # reachable cells, grown by a margin): everything outside is UNKNOWN and unreachable,
    # which the frontier steps treat exactly as the space beyond the grid's edge, so they
    # give the same frontiers (with a margin >= 2: the one-cell UNKNOWN ring that keeps the
    # outside connected, and the erosion's neighbourhood). Positions come back in the
    # map's cells; the window's cells are a slice of a checked map.
    rows, cols = known_window(grid, max(config.min_free_width, 2), also=reach)
    offset = (rows.start, cols.start)
    window = GridMap.trusted(
        grid.cells[rows, cols],
        grid.resolution,
        (
            grid.origin[0] + cols.start * grid.resolution,
            grid.origin[1] + rows.start * grid.resolution,
        ),
    )
    reach = reach[rows, cols]
    cells = frontier_cells(window, config)
    labels, count = cluster_frontiers(cells, grid.resolution, config)
    window_rows, window_cols = np.nonzero(labels)
    owner = labels[window_rows, window_cols]
    frontier_rows = window_rows + offset[0]
    frontier_cols = window_cols + offset[1]
    sizes = np.bincount(owner, minlength=count + 1)[1:].astype(np.float64)
    safe = np.maximum(sizes, 1.0)
    centroid_cells = np.stack(
        [
            np.bincount(owner, weights=frontier_rows, minlength=count + 1)[1:] / safe,
            np.bincount(owner, weights=frontier_cols, minlength=count + 1)[1:] / safe,
        ],
        axis=1,
    ).reshape(-1, 2)
    goal_cells, valid = _goal_cells(
        labels,
        count,
        centroid_cells,
        reach,
        window.cells == OCCUPIED,
        grid.resolution,
        config.max_goal_offset,
        offset,
        np.stack([window_rows, window_cols], axis=1),
    )
    order = np.flatnonzero(valid)
    order = order[np.argsort(-sizes[order], kind="stable")]
    relabel = np.zeros(count + 1, dtype=np.int32)
    relabel[order + 1] = np.arange(1, len(order) + 1, dtype=np.int32)
    goals = grid.cell_to_world(goal_cells[order]).reshape(-1, 2)
    labels = relabel[labels]
    if config.gain_model == "box":
        gains = information_gain(grid, goals, config.sensor_range)
    else:
        kept = labels[window_rows, window_cols] > 0  # the valid frontiers' cells
        gains = connected_information_gain(
            window,
            labels,
            goals,
            config.sensor_range,
            cells=(window_rows[kept], window_cols[kept]),
        )
    gains = np.minimum(gains, sizes[order] * grid.resolution * config.view_depth)
    if labels.shape != grid.shape:
        full_labels = np.zeros(grid.shape, dtype=np.int32)
        full_labels[rows, cols] = labels
        labels = full_labels
    return Frontiers(
        labels=labels,
        centroids=grid.cell_to_world(centroid_cells[order]).reshape(-1, 2),
        sizes=sizes[order] * grid.resolution,
        goal_cells=goal_cells[order],
        goals=goals,
        gains=gains,
    )
