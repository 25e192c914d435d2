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

Step 2 lives here; step 1 in :mod:`agents.planning_costs`, step 3 in
:mod:`agents.planning_shortcuts`. Every name is importable from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.planning_costs import (
    CostGrid,
    PlannerConfig,
    UnknownPolicy,
    inflate,
    nearest_passable_cell,
)
from agents.planning_shortcuts import line_is_clear, shorten_path

__all__ = [
    "CostGrid",
    "DistanceField",
    "PlannerConfig",
    "UnknownPolicy",
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
