"""Path planning on an inflated occupancy grid (docs/design.md §6, building blocks).

Three steps, one function each:

1. :func:`inflate` turns a trinary :class:`~mrslam_env.gridmap.GridMap` into a
   :class:`CostGrid`: cells closer to an OCCUPIED cell than the robot radius plus a safety
   margin are blocked (``inf``); the others cost ``1`` plus a soft penalty that decays with
   the distance to the nearest wall, so that shortest paths keep clearance; UNKNOWN cells
   are either blocked or cost a configurable multiple.
2. :func:`distance_field` runs one Dijkstra search from the robot over the 8-connected
   grid (a numba kernel) and returns the path cost to every cell plus the tree to trace a
   path back; :func:`plan_path` is the single-goal query (the same search, stopped at the
   goal).
3. :func:`shorten_path` prunes the cell path by line of sight on the cost grid, without
   giving up the clearance the soft cost bought.

An edge between neighbouring cells ``a`` and ``b`` costs ``length * (c[a] + c[b]) / 2``
(``length`` = resolution or resolution * sqrt(2), metres), so on an all-free map far from
walls a path's cost is its length in metres. A diagonal step is allowed only when both
cells it cuts between are passable (no squeezing between two blocked cells).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.robot import DEFAULT_ENV, EnvFigures, build_for_env, check_against_env
from mrslam_env.config import EnvConfig
from mrslam_env.geometry import cell_to_world, world_to_cell
from mrslam_env.gridmap import OCCUPIED, UNKNOWN, GridMap, known_window
from mrslam_env.validation import check_fields, require

__all__ = [
    "CostGrid",
    "DistanceField",
    "PlannerConfig",
    "best_goal_field",
    "distance_field",
    "inflate",
    "line_is_clear",
    "nearest_passable_cell",
    "plan_path",
    "reachable_cells",
    "shorten_path",
    "trace_path",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

UnknownPolicy = Literal["blocked", "costly"]


@dataclass(frozen=True, slots=True, kw_only=True)
class PlannerConfig:
    """How a map becomes a cost grid."""

    robot_radius: float = DEFAULT_ENV.robot.radius
    """Footprint radius, m: the env's ``RobotConfig.radius`` (:meth:`for_env`)."""
    safety_margin: float = 0.08
    """Added to the radius: a cell whose centre is closer than ``robot_radius +
    safety_margin`` to an OCCUPIED cell's centre is blocked, m (>= 0)."""
    clearance: float = 0.5
    """Width of the soft-cost band beyond the blocked zone, m (>= 0; 0 turns it off)."""
    clearance_cost: float = 4.0
    """Extra cost multiplier at the edge of the blocked zone, decaying quadratically to 0
    across the ``clearance`` band (>= 0): a cell touching the blocked zone costs
    ``1 + clearance_cost`` times a free cell."""
    unknown: UnknownPolicy = "blocked"
    """UNKNOWN cells: ``"blocked"`` (never entered) or ``"costly"`` (entered at
    ``unknown_cost`` times the cost of a free cell)."""
    unknown_cost: float = 5.0
    """Cost multiplier of an UNKNOWN cell when ``unknown == "costly"`` (>= 1)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=("robot_radius",),
            non_negative=("safety_margin", "clearance", "clearance_cost"),
        )
        name = type(self).__name__
        unknown = self.unknown
        require(name, "unknown", unknown, unknown in ("blocked", "costly"), "'blocked' or 'costly'")
        cost = self.unknown_cost
        ok = isinstance(cost, int | float) and math.isfinite(cost) and cost >= 1
        require(name, "unknown_cost", cost, ok, "a finite number >= 1")

    @staticmethod
    def env_figures(env: EnvConfig) -> EnvFigures:
        """The fields that are the env's figures: the robot's radius."""
        return {"robot_radius": ("robot.radius", env.robot.radius)}

    @classmethod
    def for_env(cls, env: EnvConfig, **overrides: Any) -> PlannerConfig:
        """The planner for the env's robot; ``overrides`` set the tuning fields."""
        return build_for_env(cls, cls.env_figures(env), overrides)

    def check_env(self, env: EnvConfig) -> None:
        """Raise a ``ValueError`` if this config contradicts the env's robot."""
        check_against_env(self, self.env_figures(env))

    @property
    def blocked_radius(self) -> float:
        """Distance from a wall cell inside which a cell is blocked, m."""
        return self.robot_radius + self.safety_margin


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class CostGrid:
    """Per-cell traversal cost of a map, on the map's own grid.

    Attributes
    ----------
    cost : ndarray of float64, shape (rows, cols)
        Cost multiplier per cell, ``>= 1``; ``inf`` = blocked.
    wall_distance : ndarray of float64, shape (rows, cols)
        Distance from each cell centre to the nearest OCCUPIED cell centre, m (``inf``
        when the map has no OCCUPIED cell). Exact wherever it is below the planner's
        ``blocked_radius + clearance`` (all the cost depends on); far out in the unknown
        space around the map's known part it may be a lower bound no smaller than that.
    resolution : float
        Cell edge, m.
    origin : tuple of float
        Map-frame ``(x, y)`` of the outer corner of cell [0, 0], m.
    """

    cost: FloatArray
    wall_distance: FloatArray
    resolution: float
    origin: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.cost.shape[0]), int(self.cost.shape[1]))

    @property
    def passable(self) -> NDArray[np.bool_]:
        """Cells the robot's centre may occupy (finite cost), (rows, cols) bool."""
        return np.isfinite(self.cost)

    def world_to_cell(self, points: ArrayLike) -> IntArray:
        """Cell indices ``(iy, ix)`` of map-frame points ``(x, y)``, not clipped."""
        return world_to_cell(points, self.origin, self.resolution)

    def cell_to_world(self, cells: ArrayLike) -> FloatArray:
        """Map-frame centres ``(x, y)`` of cells ``(iy, ix)``."""
        return cell_to_world(cells, self.origin, self.resolution)

    def contains(self, cells: ArrayLike) -> NDArray[np.bool_]:
        c = np.asarray(cells)
        rows, cols = self.shape
        return (c[..., 0] >= 0) & (c[..., 0] < rows) & (c[..., 1] >= 0) & (c[..., 1] < cols)


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class DistanceField:
    """Result of one Dijkstra search from a start cell.

    Attributes
    ----------
    cost : ndarray of float64, shape (rows, cols)
        Path cost from the start to every cell (metres weighted by the cell costs; equal
        to path length where the cost multiplier is 1); ``inf`` = unreachable. With an
        early stop at a goal, only cells settled before the goal hold final values.
    parent : ndarray of int64, shape (rows, cols)
        Flat index (``row * cols + col``) of each reached cell's predecessor; ``-1`` at
        the start and at unreached cells.
    start : tuple of int
        The start cell ``(row, col)`` (after :func:`nearest_passable_cell`).
    grid : CostGrid
        The cost grid searched.
    """

    cost: FloatArray
    parent: IntArray
    start: tuple[int, int]
    grid: CostGrid

    @property
    def reachable(self) -> NDArray[np.bool_]:
        """(rows, cols) bool: cells with a finite path cost."""
        return np.isfinite(self.cost)

    def path_to(self, goal_cell: ArrayLike) -> IntArray:
        """Cells ``(row, col)`` (P, 2) from the start to ``goal_cell``; empty if unreached."""
        return trace_path(self.parent, np.asarray(goal_cell, dtype=np.int64), self.start)


def inflate(grid: GridMap, config: PlannerConfig | None = None) -> CostGrid:
    """The cost grid of a map: blocked near walls, soft cost for clearance.

    Parameters
    ----------
    grid : GridMap
        Trinary map (any frame).
    config : PlannerConfig, optional

    Returns
    -------
    CostGrid
        Same shape, resolution and origin as ``grid``.

    Raises
    ------
    ValueError
        If the map has no FREE cell.
    """
    config = config if config is not None else PlannerConfig()
    if not grid.free.any():
        raise ValueError("cannot plan on a map with no FREE cell")
    band = config.blocked_radius + config.clearance
    # Walls lie in the known part of the map, so the distances the cost depends on (up to
    # ``band``) all lie inside it grown by ``band``: a SLAM grid grows in chunks and is
    # mostly unknown margin, where the cost is that of an unknown cell far from walls.
    rows, cols = known_window(grid, math.ceil(band / grid.resolution) + 1)
    far_unknown = np.inf if config.unknown == "blocked" else config.unknown_cost
    cost, wall_distance, has_wall = _inflated(
        grid.cells,
        rows.start,
        rows.stop,
        cols.start,
        cols.stop,
        grid.resolution,
        config.blocked_radius,
        config.clearance if config.clearance_cost > 0 else 0.0,
        config.clearance_cost,
        config.unknown == "blocked",
        config.unknown_cost,
        far_unknown,
        band,
    )
    if not has_wall:
        cells = grid.cells[rows, cols]
        cost = np.full(grid.shape, far_unknown)
        wall_distance = np.full(grid.shape, np.inf)
        near_cost = np.ones(cells.shape)
        unknown = cells == UNKNOWN
        if config.unknown == "blocked":
            near_cost[unknown] = np.inf
        else:
            near_cost[unknown] *= config.unknown_cost
        cost[rows, cols] = near_cost
    return CostGrid(
        cost=cost, wall_distance=wall_distance, resolution=grid.resolution, origin=grid.origin
    )


@numba.njit(cache=True)
def _inflated(
    cells: NDArray[np.int8],
    r0: int,
    r1: int,
    c0: int,
    c1: int,
    resolution: float,
    blocked_radius: float,
    clearance: float,
    clearance_cost: float,
    unknown_blocked: bool,
    unknown_cost: float,
    far_unknown: float,
    band: float,
) -> tuple[FloatArray, FloatArray, bool]:
    """The cost and the wall distance (m) of every cell of a map whose OCCUPIED cells all
    lie in the window ``[r0, r1) x [c0, c1)``, in one pass, and whether there is one:
    outside the window ``far_unknown`` and ``band``; inside, the exact Euclidean distance
    to the nearest OCCUPIED cell centre (Meijster et al.'s two-pass algorithm in integers,
    the square root of ``ndimage.distance_transform_edt`` over the window) and the cost
    from it; ``clearance`` 0 turns the soft cost off."""
    full_rows, full_cols = cells.shape
    cost = np.empty((full_rows, full_cols))
    near = np.empty((full_rows, full_cols))
    for r in range(full_rows):
        inside = r0 <= r < r1
        for c in range(full_cols):
            if not (inside and c0 <= c < c1):
                cost[r, c] = far_unknown
                near[r, c] = band
    rows, cols = r1 - r0, c1 - c0
    far = rows + cols + 1
    # Distance to the nearest wall in the same column (row by row, for the cache).
    column = np.empty((rows, cols), dtype=np.int64)
    has_wall = False
    for c in range(cols):
        wall = cells[r0, c0 + c] == OCCUPIED
        has_wall |= wall
        column[0, c] = 0 if wall else far
    for r in range(1, rows):
        for c in range(cols):
            wall = cells[r0 + r, c0 + c] == OCCUPIED
            has_wall |= wall
            column[r, c] = 0 if wall else min(column[r - 1, c] + 1, far)
    if not has_wall:
        return cost, near, False
    for r in range(rows - 2, -1, -1):
        for c in range(cols):
            column[r, c] = min(column[r, c], column[r + 1, c] + 1)
    sites = np.empty(cols, dtype=np.int64)
    starts = np.empty(cols, dtype=np.int64)
    for r in range(rows):
        g = column[r]
        q = 0
        sites[0] = 0
        starts[0] = 0
        for u in range(1, cols):
            while (
                q >= 0
                and (starts[q] - sites[q]) ** 2 + g[sites[q]] ** 2
                > (starts[q] - u) ** 2 + g[u] ** 2
            ):
                q -= 1
            if q < 0:
                q = 0
                sites[0] = u
            else:
                i = sites[q]
                w = 1 + (u * u - i * i + g[u] ** 2 - g[i] ** 2) // (2 * (u - i))
                if w < cols:
                    q += 1
                    sites[q] = u
                    starts[q] = w
        for u in range(cols - 1, -1, -1):
            i = sites[q]
            distance = math.sqrt(float((u - i) ** 2 + g[i] ** 2)) * resolution
            if u == starts[q]:
                q -= 1
            value = 1.0
            if clearance > 0:
                beyond = min(max((distance - blocked_radius) / clearance, 0.0), 1.0)
                value = 1.0 + clearance_cost * ((1.0 - beyond) * (1.0 - beyond))
            cell = cells[r0 + r, c0 + u]
            if cell == OCCUPIED or distance < blocked_radius:
                value = np.inf
            if cell == UNKNOWN:
                value = np.inf if unknown_blocked else value * unknown_cost
            near[r0 + r, c0 + u] = distance
            cost[r0 + r, c0 + u] = value
    return cost, near, True


def nearest_passable_cell(
    grid: CostGrid, point: ArrayLike, max_distance: float = math.inf
) -> tuple[int, int] | None:
    """The passable cell nearest to a map-frame point (the point's own cell if passable).

    A robot pushed against a wall, or drawn a little inside a wall's inflation by SLAM
    noise, still needs somewhere to start planning from.

    Parameters
    ----------
    grid : CostGrid
    point : array_like, shape (2,)
        Map-frame ``(x, y)``, m.
    max_distance : float
        Search radius, m.

    Returns
    -------
    tuple of int or None
        ``(row, col)``, or None when no passable cell lies within ``max_distance``.
    """
    cell = grid.world_to_cell(np.asarray(point, dtype=np.float64)[:2])
    rows, cols = grid.shape
    if grid.contains(cell) and math.isfinite(grid.cost[cell[0], cell[1]]):
        return int(cell[0]), int(cell[1])
    radius = max_distance / grid.resolution if math.isfinite(max_distance) else rows + cols
    radius_cells = int(min(math.ceil(radius), rows + cols))
    r0, r1 = max(cell[0] - radius_cells, 0), min(cell[0] + radius_cells + 1, rows)
    c0, c1 = max(cell[1] - radius_cells, 0), min(cell[1] + radius_cells + 1, cols)
    if r0 >= r1 or c0 >= c1:
        return None
    window = np.isfinite(grid.cost[r0:r1, c0:c1])  # the passable cells
    candidates = np.argwhere(window)
    if len(candidates) == 0:
        return None
    offsets = candidates + np.array([r0, c0]) - cell
    squared = (offsets**2).sum(axis=1)
    best = int(np.argmin(squared))
    if squared[best] > radius**2:
        return None
    return int(candidates[best, 0] + r0), int(candidates[best, 1] + c0)


# The heap helpers are inlined into the search (numba IR inlining): called, each push and
# pop would pass the arrays through reference counting, which cost a third of the search.
@numba.njit(cache=True, inline="always")
def _heap_push(
    keys: FloatArray, items: IntArray, size: int, key: float, item: int
) -> tuple[FloatArray, IntArray, int]:
    if size == len(keys):
        keys = np.concatenate((keys, np.empty(len(keys))))
        items = np.concatenate((items, np.empty(len(items), dtype=np.int64)))
    position = size
    while position > 0:
        up = (position - 1) >> 1
        if keys[up] <= key:
            break
        keys[position] = keys[up]
        items[position] = items[up]
        position = up
    keys[position] = key
    items[position] = item
    return keys, items, size + 1


@numba.njit(cache=True, inline="always")
def _heap_pop(keys: FloatArray, items: IntArray, size: int) -> tuple[float, int, int]:
    top_key, top_item = keys[0], items[0]
    size -= 1
    last_key, last_item = keys[size], items[size]
    position = 0
    while True:
        child = 2 * position + 1
        if child >= size:
            break
        if child + 1 < size and keys[child + 1] < keys[child]:
            child += 1
        if keys[child] >= last_key:
            break
        keys[position] = keys[child]
        items[position] = items[child]
        position = child
    if size > 0:
        keys[position] = last_key
        items[position] = last_item
    return top_key, top_item, size


@numba.njit(cache=True, inline="always")
def _relax_neighbours(
    cost: FloatArray,
    distance: FloatArray,
    parent: IntArray,
    done: NDArray[np.bool_],
    rows: int,
    cols: int,
    item: int,
    key: float,
    resolution: float,
    diagonal: float,
    keys: FloatArray,
    items: IntArray,
    size: int,
) -> tuple[FloatArray, IntArray, int]:
    """One Dijkstra expansion of the settled cell ``item`` (flat index into the flat
    ``cost``, ``distance``, ``parent`` and ``done`` of a ``rows`` x ``cols`` grid) at path
    cost ``key``: each of its 8 neighbours not yet settled (a diagonal step needs both
    cells it passes), orthogonal steps first (the order the searches' ties depend on), gets
    a shorter path through it, pushed on the heap; returns the heap. Inlined into the
    searches, like the heap helpers."""
    row = item // cols
    col = item - row * cols
    here = cost[item]
    for k in range(8):
        if k == 0:
            dr, dc = 1, 0
        elif k == 1:
            dr, dc = -1, 0
        elif k == 2:
            dr, dc = 0, 1
        elif k == 3:
            dr, dc = 0, -1
        elif k == 4:
            dr, dc = 1, 1
        elif k == 5:
            dr, dc = 1, -1
        elif k == 6:
            dr, dc = -1, 1
        else:
            dr, dc = -1, -1
        r = row + dr
        c = col + dc
        if r < 0 or r >= rows or c < 0 or c >= cols:
            continue
        other = item + dr * cols + dc
        if done[other]:
            continue
        there = cost[other]
        if not math.isfinite(there):
            continue
        if k >= 4:
            if not (math.isfinite(cost[item + dr * cols]) and math.isfinite(cost[item + dc])):
                continue
            length = diagonal
        else:
            length = resolution
        candidate = key + length * 0.5 * (here + there)
        if candidate < distance[other]:
            distance[other] = candidate
            parent[other] = item
            keys, items, size = _heap_push(keys, items, size, candidate, other)
    return keys, items, size


@numba.njit(cache=True)
def _dijkstra_kernel(
    cost2d: FloatArray,
    start_row: int,
    start_col: int,
    goal_row: int,
    goal_col: int,
    resolution: float,
) -> tuple[FloatArray, IntArray]:
    """Dijkstra over the 8-connected grid with a binary heap and lazy deletion.

    Edge ``a -> b`` costs ``length * (cost[a] + cost[b]) / 2``; a diagonal step needs both
    orthogonal cells it passes between to be finite. ``goal_row < 0`` searches everything.
    The grids are worked on flat (row-major indices, as the parents are given).
    """
    rows, cols = cost2d.shape
    cost = np.ascontiguousarray(cost2d).ravel()
    distance = np.full(rows * cols, np.inf)
    parent = np.full(rows * cols, -1, dtype=np.int64)
    done = np.zeros(rows * cols, dtype=np.bool_)
    capacity = 1024
    keys = np.empty(capacity)
    items = np.empty(capacity, dtype=np.int64)
    size = 0
    start = start_row * cols + start_col
    goal = goal_row * cols + goal_col if goal_row >= 0 else -1
    distance[start] = 0.0
    keys, items, size = _heap_push(keys, items, size, 0.0, start)
    diagonal = resolution * math.sqrt(2.0)
    while size > 0:
        key, item, size = _heap_pop(keys, items, size)
        if done[item]:
            continue
        done[item] = True
        if item == goal:
            break
        keys, items, size = _relax_neighbours(
            cost,
            distance,
            parent,
            done,
            rows,
            cols,
            item,
            key,
            resolution,
            diagonal,
            keys,
            items,
            size,
        )
    return distance.reshape(rows, cols), parent.reshape(rows, cols)


@numba.njit(cache=True)
def _best_goal_kernel(
    cost2d: FloatArray,
    start_row: int,
    start_col: int,
    resolution: float,
    goal_items: IntArray,
    goal_values: FloatArray,
    cost_weight: float,
    min_cost: float,
    margin: float,
) -> tuple[FloatArray, IntArray]:
    """:func:`_dijkstra_kernel` (the same pushes and pops, in the same order) stopped as
    soon as no unsettled goal can score above the best settled one (see
    :func:`best_goal_field`)."""
    rows, cols = cost2d.shape
    cost = np.ascontiguousarray(cost2d).ravel()
    distance = np.full(rows * cols, np.inf)
    parent = np.full(rows * cols, -1, dtype=np.int64)
    done = np.zeros(rows * cols, dtype=np.bool_)
    is_goal = np.zeros(rows * cols, dtype=np.bool_)
    goal_count = len(goal_items)
    settled = np.zeros(goal_count, dtype=np.bool_)
    for g in range(goal_count):
        is_goal[goal_items[g]] = True
    best = -np.inf
    open_value = -np.inf  # the highest value of an unsettled goal
    for g in range(goal_count):
        open_value = max(open_value, goal_values[g])
    capacity = 1024
    keys = np.empty(capacity)
    items = np.empty(capacity, dtype=np.int64)
    size = 0
    start = start_row * cols + start_col
    distance[start] = 0.0
    keys, items, size = _heap_push(keys, items, size, 0.0, start)
    diagonal = resolution * math.sqrt(2.0)
    while size > 0:
        key, item, size = _heap_pop(keys, items, size)
        if done[item]:
            continue
        done[item] = True
        if is_goal[item]:
            open_value = -np.inf
            for g in range(goal_count):
                if goal_items[g] == item:
                    settled[g] = True
                    if key >= min_cost:
                        best = max(best, goal_values[g] - cost_weight * key)
                elif not settled[g]:
                    open_value = max(open_value, goal_values[g])
        # Every unsettled cell's path cost is at least ``key``.
        if open_value - cost_weight * key < best - margin:
            break
        keys, items, size = _relax_neighbours(
            cost,
            distance,
            parent,
            done,
            rows,
            cols,
            item,
            key,
            resolution,
            diagonal,
            keys,
            items,
            size,
        )
    return distance.reshape(rows, cols), parent.reshape(rows, cols)


@numba.njit(cache=True)
def _reachable_kernel(cost: FloatArray, start_row: int, start_col: int) -> NDArray[np.bool_]:
    """The 4-connected component of finite cells holding the start (a flood fill)."""
    rows, cols = cost.shape
    reached = np.zeros((rows, cols), dtype=np.bool_)
    stack = np.empty(rows * cols, dtype=np.int64)
    reached[start_row, start_col] = True
    stack[0] = start_row * cols + start_col
    size = 1
    while size > 0:
        size -= 1
        item = stack[size]
        row = item // cols
        col = item - row * cols
        for k in range(4):
            r = row + (1 if k == 0 else -1 if k == 1 else 0)
            c = col + (1 if k == 2 else -1 if k == 3 else 0)
            inside = 0 <= r < rows and 0 <= c < cols
            if inside and not reached[r, c] and math.isfinite(cost[r, c]):
                reached[r, c] = True
                stack[size] = r * cols + c
                size += 1
    return reached


def _start_cell(grid: CostGrid, start: ArrayLike, snap_distance: float) -> tuple[int, int]:
    start_cell = nearest_passable_cell(grid, start, snap_distance)
    if start_cell is None:
        point = np.asarray(start, dtype=np.float64)[:2].tolist()
        raise ValueError(
            f"no passable cell within {snap_distance} m of the start {point}: the robot is "
            "boxed in or off the map"
        )
    return start_cell


def distance_field(
    grid: CostGrid, start: ArrayLike, *, snap_distance: float = 0.5
) -> DistanceField:
    """Path cost from a start point to every cell (one Dijkstra search).

    Parameters
    ----------
    grid : CostGrid
    start : array_like, shape (2,) or (3,)
        Map-frame start ``(x, y[, theta])``, m.
    snap_distance : float
        If the start cell is blocked, start from the nearest passable cell within this
        distance, m.

    Returns
    -------
    DistanceField

    Raises
    ------
    ValueError
        If no passable cell lies within ``snap_distance`` of the start.
    """
    row, col = _start_cell(grid, start, snap_distance)
    cost, parent = _dijkstra_kernel(grid.cost, row, col, -1, -1, grid.resolution)
    return DistanceField(cost=cost, parent=parent, start=(row, col), grid=grid)


def reachable_cells(
    grid: CostGrid, start: ArrayLike, *, snap_distance: float = 0.5
) -> tuple[tuple[int, int], NDArray[np.bool_]]:
    """The start cell and the cells reachable from it, without the search's costs.

    The same start cell as :func:`distance_field` and the same cells as its
    ``reachable`` (a diagonal step needs both cells it passes between, so the reachable
    cells are the start's 4-connected component of passable cells), by a flood fill.

    Returns
    -------
    start_cell : tuple of int
        ``(row, col)``.
    reachable : ndarray of bool, shape (rows, cols)

    Raises
    ------
    ValueError
        If no passable cell lies within ``snap_distance`` of the start.
    """
    row, col = _start_cell(grid, start, snap_distance)
    return (row, col), _reachable_kernel(grid.cost, row, col)


def best_goal_field(
    grid: CostGrid,
    start_cell: tuple[int, int],
    goal_cells: ArrayLike,
    goal_values: ArrayLike,
    *,
    cost_weight: float,
    min_cost: float = 0.0,
) -> DistanceField:
    """:func:`distance_field` from a start cell, stopped once the best goal is known.

    Goal ``i`` at path cost ``c`` scores ``goal_values[i] - cost_weight * c``, or nothing
    when ``c < min_cost``. The search stops as soon as no unsettled goal (path cost at
    least the search's current radius ``d``, so a score of at most ``goal_values[i] -
    cost_weight * d``) can score above the best settled one. Every cell settled by then,
    the best goal among them, holds the cost and the parent :func:`distance_field` gives
    it (the search is the same, cut short); the other cells hold upper bounds of their
    cost (``inf`` if not yet reached), so a goal's score from them is never above its
    true score.

    Parameters
    ----------
    grid : CostGrid
    start_cell : tuple of int
        ``(row, col)``, passable (:func:`reachable_cells`).
    goal_cells : array_like of int, shape (G, 2)
        ``(row, col)`` inside the grid.
    goal_values : array_like, shape (G,)
        An upper bound of each goal's score plus ``cost_weight`` times its path cost
        (``-inf``: never the best).
    cost_weight : float
        >= 0; with 0 the search runs to the end.
    min_cost : float
        Goals nearer than this never count as the best.

    Returns
    -------
    DistanceField
    """
    cells = np.asarray(goal_cells, dtype=np.int64).reshape(-1, 2)
    values = np.asarray(goal_values, dtype=np.float64).reshape(-1)
    if len(values) != len(cells):
        raise ValueError(f"{len(cells)} goal cells but {len(values)} goal values")
    items = cells[:, 0] * grid.shape[1] + cells[:, 1]
    row, col = int(start_cell[0]), int(start_cell[1])
    weight = float(cost_weight)
    if weight <= 0:  # no bound from the path cost: the whole search
        cost, parent = _dijkstra_kernel(grid.cost, row, col, -1, -1, grid.resolution)
        return DistanceField(cost=cost, parent=parent, start=(row, col), grid=grid)
    cost, parent = _best_goal_kernel(
        grid.cost,
        row,
        col,
        grid.resolution,
        items,
        values,
        weight,
        float(min_cost),
        # Scores are m² of the order of 1-100: the stop keeps a margin far above the
        # rounding of the caller's own sums.
        1e-6,
    )
    return DistanceField(cost=cost, parent=parent, start=(row, col), grid=grid)


@numba.njit(cache=True)
def _trace_kernel(parent: IntArray, goal_row: int, goal_col: int) -> IntArray:
    rows, cols = parent.shape
    flat = parent.ravel()
    item = goal_row * cols + goal_col
    count = 1
    while flat[item] >= 0:
        item = flat[item]
        count += 1
        if count > rows * cols:  # a cycle would be a bug; never loop forever
            return np.empty((0, 2), dtype=np.int64)
    path = np.empty((count, 2), dtype=np.int64)
    item = goal_row * cols + goal_col
    for k in range(count - 1, -1, -1):
        path[k, 0] = item // cols
        path[k, 1] = item - (item // cols) * cols
        item = flat[item]
    return path


def trace_path(parent: IntArray, goal_cell: IntArray, start_cell: tuple[int, int]) -> IntArray:
    """Follow a search tree's parents from ``goal_cell`` back to ``start_cell``.

    Returns
    -------
    ndarray of int64, shape (P, 2)
        Cells ``(row, col)`` from start to goal; empty (0, 2) when the goal was not
        reached (or is outside the grid).
    """
    rows, cols = parent.shape
    goal_row, goal_col = int(goal_cell[0]), int(goal_cell[1])
    if not (0 <= goal_row < rows and 0 <= goal_col < cols):
        return np.empty((0, 2), dtype=np.int64)
    if (goal_row, goal_col) != tuple(start_cell) and parent[goal_row, goal_col] < 0:
        return np.empty((0, 2), dtype=np.int64)
    path = _trace_kernel(parent, goal_row, goal_col)
    if len(path) == 0 or tuple(path[0]) != tuple(start_cell):
        return np.empty((0, 2), dtype=np.int64)
    return path


def plan_path(
    grid: CostGrid,
    start: ArrayLike,
    goal: ArrayLike,
    *,
    snap_distance: float = 0.5,
    shorten: bool = True,
) -> FloatArray:
    """A least-cost path between two map-frame points, in metres.

    The search stops as soon as the goal cell is settled. Start and goal snap to the
    nearest passable cell within ``snap_distance``.

    Parameters
    ----------
    grid : CostGrid
    start, goal : array_like, shape (2,) or (3,)
        Map-frame points, m.
    snap_distance : float
        m.
    shorten : bool
        Prune the path by line of sight (:func:`shorten_path`).

    Returns
    -------
    ndarray of float64, shape (P, 2)
        Waypoints (cell centres) from start to goal; empty (0, 2) when the goal is
        unreachable.

    Raises
    ------
    ValueError
        If the start has no passable cell within ``snap_distance``.
    """
    row, col = _start_cell(grid, start, snap_distance)
    goal_cell = nearest_passable_cell(grid, goal, snap_distance)
    if goal_cell is None:
        return np.empty((0, 2))
    _, parent = _dijkstra_kernel(grid.cost, row, col, goal_cell[0], goal_cell[1], grid.resolution)
    cells = trace_path(parent, np.array(goal_cell), (row, col))
    if len(cells) == 0:
        return np.empty((0, 2))
    if shorten:
        cells = shorten_path(grid, cells)
    return grid.cell_to_world(cells)


@numba.njit(cache=True)
def _line_max_cost(cost: FloatArray, r0: int, c0: int, r1: int, c1: int) -> float:
    """Largest cell cost on the straight segment between two cell centres.

    An exact grid traversal in integer arithmetic: the segment crosses a row boundary at
    ``t = (i + 1/2) / |dr|`` and a column boundary at ``t = (j + 1/2) / |dc|``; where
    it passes exactly through a cell corner, both cells beside the corner count too (a
    closed supercover). Blocked cells give ``inf``.
    """
    rows_to_cross = abs(r1 - r0)
    cols_to_cross = abs(c1 - c0)
    step_r = 1 if r1 > r0 else -1
    step_c = 1 if c1 > c0 else -1
    r, c = r0, c0
    worst = cost[r, c]
    i = 0
    j = 0
    while i < rows_to_cross or j < cols_to_cross:
        # Compare the next crossings (i + 1/2) / rows and (j + 1/2) / cols exactly.
        row_key = (2 * i + 1) * cols_to_cross
        col_key = (2 * j + 1) * rows_to_cross
        if j >= cols_to_cross or (i < rows_to_cross and row_key < col_key):
            r += step_r
            i += 1
        elif i >= rows_to_cross or col_key < row_key:
            c += step_c
            j += 1
        else:
            worst = max(worst, cost[r + step_r, c], cost[r, c + step_c])
            r += step_r
            c += step_c
            i += 1
            j += 1
        worst = max(worst, cost[r, c])
        if not math.isfinite(worst):
            return worst
    return worst


def line_is_clear(grid: CostGrid, cell_a: ArrayLike, cell_b: ArrayLike) -> bool:
    """Whether the segment between two cell centres crosses only passable cells."""
    a = np.asarray(cell_a, dtype=np.int64)
    b = np.asarray(cell_b, dtype=np.int64)
    return bool(
        math.isfinite(_line_max_cost(grid.cost, int(a[0]), int(a[1]), int(b[0]), int(b[1])))
    )


@numba.njit(cache=True)
def _shorten_kernel(cost: FloatArray, cells: IntArray, tolerance: float) -> IntArray:
    count = len(cells)
    keep = np.zeros(count, dtype=np.bool_)
    keep[0] = True
    keep[count - 1] = True
    anchor = 0
    while anchor < count - 1:
        best = anchor + 1
        worst_on_path = cost[cells[anchor, 0], cells[anchor, 1]]
        for j in range(anchor + 1, count):
            on_path = cost[cells[j, 0], cells[j, 1]]
            if on_path > worst_on_path:
                worst_on_path = on_path
            line = _line_max_cost(
                cost, cells[anchor, 0], cells[anchor, 1], cells[j, 0], cells[j, 1]
            )
            if line <= worst_on_path * tolerance:
                best = j
            else:
                break
        keep[best] = True
        anchor = best
    return cells[keep]


def shorten_path(grid: CostGrid, cells: ArrayLike, *, tolerance: float = 1.05) -> IntArray:
    """Line-of-sight pruning of a cell path ("string pulling").

    From each kept cell, jump to the farthest later cell of the path reachable in a
    straight line whose cells are all passable and no costlier than ``tolerance`` times
    the costliest path cell it replaces: shortcuts never run closer to walls than the
    original path did.

    Parameters
    ----------
    grid : CostGrid
    cells : array_like of int, shape (P, 2)
        A connected cell path ``(row, col)``, e.g. from :meth:`DistanceField.path_to`.
    tolerance : float
        Allowed cost ratio of a shortcut's worst cell to the replaced path's worst cell.

    Returns
    -------
    ndarray of int64, shape (Q, 2)
        A subsequence of ``cells`` with the same first and last cell (Q <= P).
    """
    cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 2)
    if len(cells) <= 2:
        return cells.copy()
    return _shorten_kernel(grid.cost, cells, float(tolerance))
