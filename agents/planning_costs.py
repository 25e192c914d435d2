"""Step 1 of path planning: the cost grid of a map (docs/design.md §6, building blocks).

:func:`inflate` turns a trinary :class:`~mrslam_env.gridmap.GridMap` into a
:class:`CostGrid`: cells closer to an OCCUPIED cell than the robot radius plus a safety
margin are blocked (``inf``); the others cost ``1`` plus a soft penalty that decays with the
distance to the nearest wall, so that shortest paths keep clearance; UNKNOWN cells are
either blocked or cost a configurable multiple (:class:`PlannerConfig`). The wall
distances come from one numba pass (an exact Euclidean distance transform) over the known
part of the map. :func:`nearest_passable_cell` finds where a robot inside a wall's
inflation starts planning from.

The search (:mod:`agents.planning`) and the path shortening
(:mod:`agents.planning_shortcuts`) work on the :class:`CostGrid`; :mod:`agents.planning`
re-exports every name.
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

__all__ = ["CostGrid", "PlannerConfig", "UnknownPolicy", "inflate", "nearest_passable_cell"]

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
