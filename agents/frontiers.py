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
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

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


def _goal_cells(
    labels: NDArray[np.int32],
    count: int,
    centroid_cells: FloatArray,
    reachable: BoolArray,
    occupied: BoolArray,
    resolution: float,
    max_goal_offset: float,
    offset: tuple[int, int],
    cells: IntArray,
) -> tuple[IntArray, BoolArray]:
    """Per frontier: a reachable cell that sees one of its cells, the one closest to its
    centroid that can be seen.

    A frontier cell is seen from a cell when no ``occupied`` cell lies on the segment
    between them (:func:`_seen_from`). Its goal is its nearest reachable cell when that is
    within ``max_goal_offset`` and sees it, else the nearest reachable cell within
    ``max_goal_offset`` that does; the frontier's cells are tried in order of distance to
    its centroid. A frontier with no such cell is invalid: the reachable space near it
    lies behind a wall (a frontier mapped through a gap in a wall, or behind a pillar),
    and a robot sent there would stand at the goal without ever seeing it. ``labels``,
    ``reachable`` and ``occupied`` may be a window of the map whose cell [0, 0] is the
    map's cell ``offset``; ``centroid_cells`` and the goal cells returned are in the map's
    cells; ``cells`` is ``np.argwhere(labels > 0)``.
    """
    goal_cells = np.zeros((count, 2), dtype=np.int64)
    valid = np.zeros(count, dtype=bool)
    if count == 0 or not reachable.any():
        return goal_cells, valid
    owner = (labels[cells[:, 0], cells[:, 1]] - 1).astype(np.int64)
    to_centroid = ((cells + np.asarray(offset) - centroid_cells[owner]) ** 2).sum(axis=1)
    # The nearest reachable cell at the frontier cells only (the transform scipy's
    # distance_transform_edt would compute everywhere, ties broken as it does).
    nearest = _nearest_feature_at(reachable, cells)
    steps = (nearest - cells).astype(np.float64)
    to_reachable = np.sqrt(steps[:, 0] * steps[:, 0] + steps[:, 1] * steps[:, 1]) * resolution
    # Cells closer to the middle first (the first in row-major order on a tie); cells
    # farther than max_goal_offset from reachable space are no candidates.
    key = np.where(to_reachable <= max_goal_offset, to_centroid, np.inf)
    order = np.lexsort((key, owner))  # stable: ties keep the row-major order
    order = order[np.isfinite(key[order])]
    reach = max_goal_offset / resolution
    disk = _disk_by_distance(reach)
    chosen = _first_seen(order, owner, cells, nearest, reachable, occupied, disk, reach)
    frontiers = np.flatnonzero(chosen[:, 0] >= 0)
    goal_cells[frontiers] = chosen[frontiers] + np.asarray(offset)
    valid[frontiers] = True
    return goal_cells, valid


def _disk_by_distance(radius_cells: float) -> IntArray:
    """Cell offsets (K, 2) within ``radius_cells`` of the centre, nearest first (row-major
    order on a tie)."""
    reach = math.floor(radius_cells)
    rows, cols = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    squared = (rows**2 + cols**2).ravel()
    inside = np.flatnonzero(squared <= radius_cells**2)
    inside = inside[np.argsort(squared[inside], kind="stable")]
    return np.stack([rows.ravel()[inside], cols.ravel()[inside]], axis=1).astype(np.int64)


@numba.njit(cache=True)
def _first_seen(
    order: IntArray,
    owner: IntArray,
    cells: IntArray,
    nearest: IntArray,
    reachable: BoolArray,
    occupied: BoolArray,
    disk: IntArray,
    reach: float,
) -> IntArray:
    """Per frontier (``owner.max() + 1`` rows), the goal cell of :func:`_goal_cells` or
    ``(-1, -1)``: ``order`` lists the candidate frontier cells (indices into ``cells``)
    frontier by frontier, best first."""
    count = 0
    for k in range(len(owner)):
        count = max(count, owner[k] + 1)
    out = np.full((count, 2), -1, dtype=np.int64)
    rows, cols = reachable.shape
    for k in order:
        frontier = owner[k]
        if out[frontier, 0] >= 0:
            continue
        r, c = cells[k, 0], cells[k, 1]
        nr, nc = nearest[k, 0], nearest[k, 1]
        if (nr - r) ** 2 + (nc - c) ** 2 <= reach * reach and _seen_from(occupied, nr, nc, r, c):
            out[frontier, 0], out[frontier, 1] = nr, nc
            continue
        for j in range(len(disk)):
            gr, gc = r + disk[j, 0], c + disk[j, 1]
            inside = 0 <= gr < rows and 0 <= gc < cols
            if inside and reachable[gr, gc] and _seen_from(occupied, gr, gc, r, c):
                out[frontier, 0], out[frontier, 1] = gr, gc
                break
    return out


@numba.njit(cache=True)
def _seen_from(occupied: BoolArray, r0: int, c0: int, r1: int, c1: int) -> bool:
    """Whether no ``occupied`` cell lies on the segment between cells ``(r0, c0)`` and
    ``(r1, c1)``, ends excluded: sampled twice per cell along its longer axis, so that a
    diagonal wall (cells touching at corners) blocks it too."""
    dr, dc = r1 - r0, c1 - c0
    n = 2 * max(abs(dr), abs(dc))
    for k in range(1, n):
        r = r0 + (2 * k * dr + n) // (2 * n)  # k dr / n, rounded
        c = c0 + (2 * k * dc + n) // (2 * n)
        if (r != r0 or c != c0) and (r != r1 or c != c1) and occupied[r, c]:
            return False
    return True


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


@numba.njit(cache=True)
def _nearest_feature_at(features: BoolArray, cells: IntArray) -> IntArray:
    """The nearest ``True`` cell ``(row, col)`` of each of ``cells`` (K, 2), row-major
    sorted, as ``ndimage.distance_transform_edt(~features, return_indices=True)`` gives
    it, ties included: the same exact algorithm (Maurer, Qi and Raghavan 2003), a pass
    along each column then one along each row, in integers, the row pass only on the
    rows of ``cells``. Needs one ``True`` cell at least."""
    rows, cols = features.shape
    # Per column, for each row: the nearest feature row in the column (ties: the lower
    # row), or -1 when the column has none; from the last feature at or above and the
    # first at or below.
    above = np.empty((rows, cols), dtype=np.int32)
    below = np.empty((rows, cols), dtype=np.int32)
    for c in range(cols):  # row by row, for the cache
        above[0, c] = 0 if features[0, c] else -1
        below[rows - 1, c] = rows - 1 if features[rows - 1, c] else -1
    for r in range(1, rows):
        for c in range(cols):
            above[r, c] = r if features[r, c] else above[r - 1, c]
    for r in range(rows - 2, -1, -1):
        for c in range(cols):
            below[r, c] = r if features[r, c] else below[r + 1, c]
    out = np.empty((len(cells), 2), dtype=np.int64)
    sites = np.empty(cols, dtype=np.int64)  # the columns of the envelope's sites
    site_row = np.empty(cols, dtype=np.int64)
    k = 0
    while k < len(cells):
        r = cells[k, 0]
        # The column pass's feature at (r, c) for every column c.
        top = -1
        for c in range(cols):
            up, down = np.int64(above[r, c]), np.int64(below[r, c])
            if up < 0:
                feature = down
            elif down < 0 or r - up <= down - r:
                feature = up
            else:
                feature = down
            if feature < 0:
                continue
            # Drop the sites the new one hides along this row (the lower envelope).
            w = (feature - r) ** 2
            while top >= 1:
                a = sites[top] - sites[top - 1]
                b = c - sites[top]
                u = (site_row[top - 1] - r) ** 2
                v = (site_row[top] - r) ** 2
                if (a + b) * v - b * u - a * w - a * b * (a + b) <= 0:
                    break
                top -= 1
            top += 1
            sites[top] = c
            site_row[top] = feature
        # Query the row's cells left to right: advance while the next site is closer.
        at = 0
        while k < len(cells) and cells[k, 0] == r:
            c = cells[k, 1]
            here = (site_row[at] - r) ** 2 + (sites[at] - c) ** 2
            while at < top:
                there = (site_row[at + 1] - r) ** 2 + (sites[at + 1] - c) ** 2
                if here <= there:
                    break
                here = there
                at += 1
            out[k, 0] = site_row[at]
            out[k, 1] = sites[at]
            k += 1
    return out
