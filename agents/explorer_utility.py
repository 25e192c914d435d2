"""What a frontier is worth to a robot, and the frontier split for a team (docs/design.md §6).

:func:`frontier_utility` is the utility both the single robot's choice and the team's split
rank frontiers by: information gain minus weighted path cost. :func:`team_discount` is
Burgard et al.'s (IEEE T-RO 2005) utility reduction for the view a teammate's target
shares. :func:`assign_frontiers` and :func:`team_frontier_goals` split frontiers between
robots that share a map frame (coordinated exploration, the paper's fourth kind of
interaction): greedy, each robot in turn takes the best remaining frontier, and the gains of
frontiers near a taken one are discounted so that two robots do not explore the same place.

Pure functions on arrays; :mod:`agents.explorer` re-exports them.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.explorer_config import ExplorerConfig
from agents.frontiers import Frontiers, extract_frontiers
from agents.planning import DistanceField, distance_field, inflate
from mrslam_env.gridmap import OCCUPIED, GridMap

__all__ = ["assign_frontiers", "frontier_utility", "team_discount", "team_frontier_goals"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def frontier_utility(
    gains: ArrayLike,
    path_costs: ArrayLike,
    cost_weight: float,
    *,
    min_gain: float = 0.0,
) -> FloatArray:
    """Utility of visiting each frontier: information gain minus weighted path cost.

    Parameters
    ----------
    gains : array_like, shape (..., F)
        m².
    path_costs : array_like, shape (..., F)
        Path cost from the robot to each goal, m; ``inf`` = unreachable.
    cost_weight : float
        m² per m.
    min_gain : float
        Frontiers with a smaller gain get ``-inf``, m².

    Returns
    -------
    ndarray of float64, shape (..., F)
        m²; ``-inf`` for unreachable or worthless frontiers.
    """
    gains = np.asarray(gains, dtype=np.float64)
    path_costs = np.asarray(path_costs, dtype=np.float64)
    utility = gains - cost_weight * np.where(np.isfinite(path_costs), path_costs, 0.0)
    return np.where(np.isfinite(path_costs) & (gains >= min_gain), utility, -np.inf)


def _separation_discount(goals: FloatArray, taken: ArrayLike, separation: float) -> FloatArray:
    """Per goal, the factor ``min(1, d / separation)`` for its distance d to ``taken``."""
    taken = np.asarray(taken, dtype=np.float64).reshape(-1, 2)
    if len(taken) == 0 or len(goals) == 0:
        return np.ones(len(goals))
    distance = np.hypot(*(goals[:, None, :] - taken[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    return np.minimum(distance / separation, 1.0)


def team_discount(
    goals: ArrayLike,
    taken: ArrayLike,
    view_range: float,
    grid: GridMap | None = None,
) -> FloatArray:
    """Per frontier goal, the share of its information gain left to a robot once
    teammates head for ``taken``: the utility reduction of Burgard et al. (IEEE T-RO 2005)
    by the expected overlap of what the robots will see.

    A robot at a goal sees what the gain counts: the square of half-width ``view_range``
    around it. Two such squares whose centres are ``(dx, dy)`` apart share the fraction
    ``max(0, 1 - |dx| / 2r) * max(0, 1 - |dy| / 2r)`` of one (r = ``view_range``); the
    share left is one minus that, and against several taken targets the shares left
    multiply. With ``grid``, a target hidden from the goal by a mapped wall (an OCCUPIED
    cell on the segment between them) shares none of its view.

    Parameters
    ----------
    goals : array_like, shape (F, 2)
        Frontier goals, m.
    taken : array_like, shape (K, 2)
        Teammates' targets in the same frame, m.
    view_range : float
        Half-width of the viewed square, m (> 0).
    grid : GridMap, optional
        The map the goals are in, for the walls.

    Returns
    -------
    ndarray of float64, shape (F,)
        In [0, 1]; 1 where no target shares the view.
    """
    goals = np.asarray(goals, dtype=np.float64).reshape(-1, 2)
    taken = np.asarray(taken, dtype=np.float64).reshape(-1, 2)
    if not view_range > 0:
        raise ValueError(f"view_range must be > 0 m, got {view_range!r}")
    if len(taken) == 0 or len(goals) == 0:
        return np.ones(len(goals))
    offsets = np.abs(goals[:, None, :] - taken[None, :, :])  # (F, K, 2)
    overlap = np.clip(1.0 - offsets / (2.0 * view_range), 0.0, 1.0).prod(axis=2)
    if grid is not None:
        hidden = _walls_between(grid.cells, grid.world_to_cell(goals), grid.world_to_cell(taken))
        overlap[hidden] = 0.0
    return np.asarray((1.0 - overlap).prod(axis=1), dtype=np.float64)


@numba.njit(cache=True)
def _walls_between(cells: NDArray[np.int8], starts: IntArray, ends: IntArray) -> NDArray[np.bool_]:
    """(S, E) bool: whether an OCCUPIED cell lies on the segment from cell ``starts[i]`` to
    cell ``ends[j]`` (sampled once per cell along its longer axis, ends excluded; cells
    beyond the grid are no wall)."""
    rows, cols = cells.shape
    out = np.zeros((len(starts), len(ends)), dtype=np.bool_)
    for i in range(len(starts)):
        r0, c0 = starts[i, 0], starts[i, 1]
        for j in range(len(ends)):
            dr, dc = ends[j, 0] - r0, ends[j, 1] - c0
            n = max(abs(dr), abs(dc))
            for k in range(1, n):
                r = r0 + (2 * k * dr + n) // (2 * n)  # k dr / n, rounded
                c = c0 + (2 * k * dc + n) // (2 * n)
                if 0 <= r < rows and 0 <= c < cols and cells[r, c] == OCCUPIED:
                    out[i, j] = True
                    break
    return out


def assign_frontiers(
    goals: ArrayLike,
    gains: ArrayLike,
    path_costs: ArrayLike,
    *,
    cost_weight: float = 2.0,
    separation: float = 4.0,
    min_gain: float = 0.0,
    view_range: float | None = None,
    grid: GridMap | None = None,
    bonus: ArrayLike | None = None,
) -> IntArray:
    """Split frontiers between robots greedily, keeping the robots apart (Burgard et
    al., IEEE T-RO 2005).

    Repeatedly take the (robot, frontier) pair of highest utility
    (:func:`frontier_utility`) among the robots still without a frontier; then scale the
    gain of every frontier by the share of its view the taken goal's view does not cover
    (:func:`team_discount` with ``view_range`` and ``grid``), or, without ``view_range``,
    by ``min(1, d / separation)``, d its distance to the taken goal, so the next robot
    prefers places the first will not see. A frontier is worth a trip while what is left
    of its gain is at least ``min_gain`` (with ``min_gain = 0`` a robot may share a
    frontier when nothing else is worth its while).

    Parameters
    ----------
    goals : array_like, shape (F, 2)
        Frontier goals in the robots' common frame, m.
    gains : array_like, shape (F,)
        Information gains, m².
    path_costs : array_like, shape (R, F)
        Path cost from each robot to each goal, m; ``inf`` = unreachable.
    cost_weight : float
        m² per m.
    separation : float
        m (> 0).
    min_gain : float
        m².
    view_range : float, optional
        Half-width of a robot's view, m (> 0): the overlap discount instead of the
        distance one.
    grid : GridMap, optional
        The map of ``goals``: no overlap across its walls.
    bonus : array_like, shape (R, F), optional
        Added to each (robot, frontier) utility, m² (e.g. for the frontier a robot is
        already heading to); ``-inf`` rules a pair out.

    Returns
    -------
    ndarray of int64, shape (R,)
        Frontier index per robot, ``-1`` for a robot with no reachable worthwhile frontier.
    """
    goals = np.asarray(goals, dtype=np.float64).reshape(-1, 2)
    gains_left = np.asarray(gains, dtype=np.float64).reshape(-1).copy()
    costs = np.asarray(path_costs, dtype=np.float64)
    if costs.ndim != 2 or costs.shape[1] != len(goals) or len(gains_left) != len(goals):
        raise ValueError(
            f"path_costs must have shape (robots, {len(goals)}) to match goals {goals.shape} "
            f"and gains {gains_left.shape}, got {costs.shape}"
        )
    if not separation > 0:
        raise ValueError(f"separation must be > 0 m, got {separation!r}")
    robots = costs.shape[0]
    extra = np.zeros(costs.shape) if bonus is None else np.asarray(bonus, dtype=np.float64)
    if extra.shape != costs.shape:
        raise ValueError(
            f"bonus must have the shape of path_costs {costs.shape}, got {extra.shape}"
        )
    assignment = np.full(robots, -1, dtype=np.int64)
    for _ in range(robots):
        # Worth a trip on what is left of its gain once the taken goals' views are off.
        utility = frontier_utility(gains_left, costs, cost_weight, min_gain=min_gain) + extra
        utility[assignment >= 0] = -np.inf
        if not np.isfinite(utility).any():
            break
        robot, frontier = np.unravel_index(int(np.argmax(utility)), utility.shape)
        assignment[robot] = frontier
        if view_range is None:
            gains_left *= _separation_discount(goals, goals[frontier], separation)
        else:
            gains_left *= team_discount(goals, goals[frontier], view_range, grid)
    return assignment


def team_frontier_goals(
    grid: GridMap,
    positions: ArrayLike,
    config: ExplorerConfig | None = None,
) -> tuple[FloatArray, Frontiers]:
    """Frontier goals for several robots on one shared map (coordinated exploration).

    Parameters
    ----------
    grid : GridMap
        The merged map, in the frame of ``positions``.
    positions : array_like, shape (R, 2) or (R, 3)
        The robots' poses in that frame, m.
    config : ExplorerConfig, optional
        Planner, frontier and utility settings.

    Returns
    -------
    goals : ndarray of float64, shape (R, 2)
        Goal per robot (give it to :meth:`ExplorerPolicy.set_goal`); NaN rows for robots
        with nothing worth exploring or no passable start.
    frontiers : Frontiers
        The frontiers reachable by at least one robot.
    """
    config = config if config is not None else ExplorerConfig()
    robots = np.asarray(positions, dtype=np.float64)
    robots = robots.reshape(len(robots), -1)
    cost_grid = inflate(grid, config.planner)
    fields: list[DistanceField | None] = []
    for position in robots:
        try:
            fields.append(distance_field(cost_grid, position[:2], snap_distance=config.start_snap))
        except ValueError:
            fields.append(None)
    reachable = np.zeros(grid.shape, dtype=bool)
    for distances in fields:
        if distances is not None:
            reachable |= distances.reachable
    frontiers = extract_frontiers(grid, config.frontiers, reachable=reachable)
    rows, cols = frontiers.goal_cells.T
    path_costs = np.array(
        [
            distances.cost[rows, cols] if distances is not None else np.full(len(frontiers), np.inf)
            for distances in fields
        ]
    ).reshape(len(robots), len(frontiers))
    assignment = assign_frontiers(
        frontiers.goals,
        frontiers.gains,
        path_costs,
        cost_weight=config.cost_weight,
        separation=config.separation,
        min_gain=config.min_gain,
        view_range=config.frontiers.sensor_range if config.team_discount == "overlap" else None,
        grid=grid,
    )
    goals = np.full((len(robots), 2), np.nan)
    assigned = assignment >= 0
    goals[assigned] = frontiers.goals[assignment[assigned]]
    return goals, frontiers
