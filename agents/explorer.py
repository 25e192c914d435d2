"""Frontier exploration for one robot, and the frontier split for a team (docs/design.md §6).

:class:`ExplorerPolicy` is the thin stateful shell around the pure steps in
:mod:`agents.frontiers`, :mod:`agents.planning` and :mod:`agents.follower`:

* on a **replan** (no plan yet, goal reached, path blocked by a newly mapped wall, target
  no longer a frontier, stuck, or every ``replan_interval`` steps) it inflates the map,
  runs one Dijkstra search from the robot, extracts the frontiers reachable from it, picks
  the one of highest utility ``gain - cost_weight * path_cost`` (:func:`frontier_utility`)
  and plans the path there;
* on every other step it only follows the path and runs two cheap checks (is the path
  ahead still clear, is the target still a frontier).

A *given goal* (:meth:`ExplorerPolicy.set_goal`) replaces frontier choice: the team
coordinator uses it to send a robot to a rendezvous point or to an assigned frontier.

:func:`assign_frontiers` and :func:`team_frontier_goals` split frontiers between robots that
share a map frame (coordinated exploration, the paper's fourth kind of interaction):
greedy, each robot in turn takes the best remaining frontier, and the gains of frontiers
near a taken one are discounted so that two robots do not explore the same place.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.follower import (
    FollowerConfig,
    PathFollower,
    escape_command,
    lane_clearance,
    teammate_clearance,
)
from agents.frontiers import FrontierConfig, Frontiers, extract_frontiers
from agents.planning import (
    CostGrid,
    DistanceField,
    PlannerConfig,
    best_goal_field,
    distance_field,
    inflate,
    reachable_cells,
    shorten_path,
)
from agents.policy import PolicyContext
from mrslam_env.config import EnvConfig
from mrslam_env.geometry import compose, transform_points, world_to_cell
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.slam.scan import mask_returns_near, sighted_positions
from mrslam_env.validation import check_fields, require

__all__ = [
    "ExplorerConfig",
    "ExplorerPolicy",
    "ExplorerStatus",
    "assign_frontiers",
    "frontier_policy",
    "frontier_utility",
    "team_discount",
    "team_frontier_goals",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

TeamDiscount = Literal["overlap", "distance"]
TeamAllocation = Literal["targets", "greedy", "minpos"]

ExplorerStatus = Literal[
    "idle", "exploring", "waiting", "to_goal", "arrived", "goal_unreachable", "blocked", "done"
]


@dataclass(frozen=True, slots=True, kw_only=True)
class ExplorerConfig:
    """Tuning of :class:`ExplorerPolicy`. The robot's figures are in ``planner`` (radius)
    and ``follower`` (speeds, period): :meth:`for_env` sets both from the env."""

    planner: PlannerConfig = field(default_factory=PlannerConfig)
    frontiers: FrontierConfig = field(default_factory=FrontierConfig)
    follower: FollowerConfig = field(default_factory=FollowerConfig)
    cost_weight: float = 1.0
    """Information gain (m²) one metre of path cost is worth, m²/m (>= 0)."""
    min_gain: float = 0.5
    """Frontiers whose information gain is below this are not worth a trip, m² (>= 0)."""
    target_bonus: float = 8.0
    """Utility bonus (m²) of the frontier being driven to (the one that overlaps the
    current target's cells), so that the choice does not flip between two similar
    frontiers on every replan (>= 0)."""
    separation: float = 4.0
    """Frontier goals within a quarter of this of a teammate's target are the teammate's
    (:attr:`ExplorerPolicy.shared_target_radius`); with ``team_discount="distance"``,
    frontiers closer than this to a teammate's target have their gain scaled by
    ``distance / separation``, m (> 0)."""
    team_discount: TeamDiscount = "distance"
    """How a teammate's target lowers the gain of a frontier: ``"distance"`` scales it by
    ``min(1, distance / separation)``; ``"overlap"`` (Burgard et al. 2005's utility
    reduction, :func:`team_discount`; measured no better, docs/decisions.md) by the
    share of the frontier's view the target's view does not cover (both views the
    square of half-width ``frontiers.sensor_range`` the gain is counted in; no overlap
    across a mapped wall)."""
    team_allocation: TeamAllocation = "targets"
    """How a robot that knows its teammates' positions (in a common frame) chooses its
    frontier. ``"targets"``: the best for itself, the teammates' targets taken and
    frontiers near them discounted (``team_discount``). ``"greedy"``: its part of a
    joint assignment of frontiers to itself and its teammates (:func:`assign_frontiers`,
    Burgard et al. 2005's greedy cost-utility assignment: each teammate's path costs
    from a search from its last known position, its current target kept with
    ``target_bonus``). ``"minpos"``: among the frontiers worth a trip, one for which the
    fewest teammates have a shorter path (Bautin et al. 2012, MinPos), the best utility
    among those. Either falls back on ``"targets"`` when it leaves the robot nothing."""
    contest_targets: bool = True
    """A teammate's target is left to it only while the teammate is as near to it as
    this robot: when this robot's path cost to the target's frontier is below the
    straight-line distance from the teammate's last known position to its target, the
    target is not the teammate's (neither taken nor discounted) for this robot's choice.
    Off while a teammate has no target (whose target is whose is then not known; teams
    of three or more). False: a teammate's target is always its own."""
    replan_interval: int = 25
    """Steps between routine replans."""
    min_replan_interval: int = 5
    """Steps after a replan before an explored target triggers the next one (the robot
    keeps driving meanwhile; blocked paths and stuck robots replan at once)."""
    blocked_lookahead: float = 2.5
    """How far ahead along the path (m) each step checks for newly mapped walls."""
    blacklist_radius: float = 0.6
    """Frontier goals within this distance of a failed or fruitless goal are skipped, m."""
    blacklist_steps: int = 400
    """How long a goal stays blacklisted, steps."""
    target_gone_fraction: float = 0.25
    """The target counts as explored when fewer than this fraction of its frontier cells
    are still frontier cells."""
    done_after: int = 3
    """Consecutive replans without a worthwhile frontier before reporting ``done``."""
    goal_snap: float = 1.0
    """A given goal in a blocked or unknown cell is moved to the nearest reachable cell
    within this distance, m."""
    start_snap: float = 0.6
    """A robot inside a wall's inflation plans from the nearest passable cell within this
    distance, m."""
    tie_jitter: float = 1e-3
    """Scale of the random tie-breaking noise added to utilities, m²."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            non_negative=("cost_weight", "min_gain", "target_bonus", "tie_jitter"),
            positive=(
                "separation",
                "blocked_lookahead",
                "blacklist_radius",
                "goal_snap",
                "start_snap",
            ),
            counts=("replan_interval", "min_replan_interval", "blacklist_steps", "done_after"),
        )
        fraction = self.target_gone_fraction
        ok = 0 <= fraction <= 1
        require(type(self).__name__, "target_gone_fraction", fraction, ok, "in [0, 1]")
        discount = self.team_discount
        ok = discount in ("overlap", "distance")
        require(type(self).__name__, "team_discount", discount, ok, "'overlap' or 'distance'")
        allocation = self.team_allocation
        ok = allocation in ("targets", "greedy", "minpos")
        expected = "'targets', 'greedy' or 'minpos'"
        require(type(self).__name__, "team_allocation", allocation, ok, expected)

    @classmethod
    def for_env(cls, env: EnvConfig, **overrides: Any) -> ExplorerConfig:
        """The explorer for the env's robot: ``planner`` and ``follower`` from their
        ``for_env`` unless given (then checked against the env); ``overrides`` set the
        tuning fields."""
        overrides.setdefault("planner", PlannerConfig.for_env(env))
        overrides.setdefault("follower", FollowerConfig.for_env(env))
        config = cls(**overrides)
        config.check_env(env)
        return config

    def check_env(self, env: EnvConfig) -> None:
        """Raise a ``ValueError`` if the planner or follower contradicts the env's robot."""
        self.planner.check_env(env)
        self.follower.check_env(env)


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


@functools.lru_cache(maxsize=16)
def _disk_offsets(radius_cells: float) -> IntArray:
    """Cell offsets (K, 2) within ``radius_cells`` of the centre; read-only and cached (the
    robot's footprint, asked for on every step)."""
    reach = math.ceil(radius_cells)
    rows, cols = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    inside = rows**2 + cols**2 <= radius_cells**2
    offsets = np.stack([rows[inside], cols[inside]], axis=1).astype(np.int64)
    offsets.flags.writeable = False
    return offsets


ESCAPE_AFTER_STEPS = 25
"""Steps without real motion (< 5 cm, < 0.3 rad) while following a path before the
reactive escape."""
CLOSE_RETURN_RANGE = 0.5
"""Scan returns closer than this (m) are remembered as obstacles for planning."""
CLOSE_RETURN_EVERY = 5
"""Steps between remembered scans."""
CLOSE_RETURN_MEMORY = 600
"""Steps a remembered return is kept."""
ESCAPE_STEPS = 20
"""Steps of reactive escape before replanning."""
PEER_MARGIN = 0.15
"""Scan returns within the robot radius plus this (m) of a sighted robot are that robot."""
ROUTE_HYSTERESIS = 1.0
"""A routine replan to the same goal switches route only if the new one is this much
shorter (m)."""
NO_PROGRESS_DISTANCE = 0.3
"""Getting this much closer (m) to the goal counts as progress ..."""
NO_PROGRESS_STEPS = 150
"""... and without it for this many steps the goal is given up and the robot replans."""


class ExplorerPolicy:
    """Frontier exploration for one robot: ``act(observation, robot_map) -> (v, omega)``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Breaks ties between frontiers of equal utility.
    config : ExplorerConfig, optional
        Defaults to the default env's robot; :meth:`for_env` follows a given env's.

    Attributes
    ----------
    status : str
        ``"exploring"`` (driving to a frontier), ``"waiting"`` (the frontiers worth a
        trip are left to teammates for now: not done), ``"to_goal"`` / ``"arrived"`` /
        ``"goal_unreachable"`` (a given goal), ``"blocked"`` (no passable cell near the
        robot), ``"done"`` (no frontier worth visiting is left), ``"idle"`` (before the
        first step).
    replans : int
        Number of replans so far; ``last_replan_reason`` says why the last one happened.
    """

    def __init__(self, rng: np.random.Generator, config: ExplorerConfig | None = None) -> None:
        self.config = config if config is not None else ExplorerConfig()
        self.rng = rng
        self.follower = PathFollower(self.config.follower)
        self.reset()

    @classmethod
    def for_env(
        cls, env: EnvConfig, rng: np.random.Generator, config: ExplorerConfig | None = None
    ) -> ExplorerPolicy:
        """An explorer for the env's robot: ``config`` (checked against the env) or
        :meth:`ExplorerConfig.for_env`."""
        if config is None:
            config = ExplorerConfig.for_env(env)
        config.check_env(env)
        return cls(rng, config)

    def reset(self) -> None:
        """Forget plans, goals, frontiers and blacklists (a new episode)."""
        self.follower.clear()
        self.status: ExplorerStatus = "idle"
        self.replans = 0
        self.last_replan_reason = ""
        self._step = 0
        self._last_replan_step = -(10**9)
        self._given_goal: FloatArray | None = None
        self._target: FloatArray | None = None
        self._target_cells = np.empty((0, 2))
        self._frontiers = np.empty((0, 2))
        self._frontier_set: Frontiers | None = None
        self._blacklist: list[tuple[float, float, int]] = []
        self._teammate_targets = np.empty((0, 2))
        self._teammates = np.empty((0, 2))
        self._sighted_body = np.empty((0, 2))
        self._sighted_in_map = np.empty((0, 2))
        self._replan_now = False
        self._empty_replans = 0
        self._stuck_seen = 0
        self._angles: FloatArray | None = None
        self._held_steps = 0
        self._escape_until = 0
        self._still_pose = np.zeros(3)
        self._close_returns: deque[tuple[int, FloatArray]] = deque()
        self._best_distance = math.inf
        self._best_step = 0
        self._grid_origin: tuple[float, float] = (0.0, 0.0)
        self._grid_resolution = 1.0
        self._path_arcs: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None = None

    # --- what the coordinator and the recorder read and set -------------------------------

    @property
    def plan(self) -> FloatArray:
        """The path being followed, (P, 2) map-frame m (empty when none)."""
        return self.follower.path

    @property
    def frontiers(self) -> FloatArray:
        """Centroids of the frontiers found at the last replan, (F, 2) map-frame m."""
        return self._frontiers.copy()

    @property
    def frontier_set(self) -> Frontiers | None:
        """All of the last replan's frontier data (goals, gains, sizes), or None."""
        return self._frontier_set

    @property
    def target(self) -> FloatArray | None:
        """The current goal (frontier goal or given goal), (2,) map-frame m, or None."""
        return None if self._target is None else self._target.copy()

    @property
    def shared_target_radius(self) -> float:
        """Frontier goals this close (m) to a teammate's target are the teammate's."""
        return self.config.separation / 4

    @property
    def done(self) -> bool:
        """True when no frontier worth visiting is left (exploration finished)."""
        return self.status == "done"

    def set_goal(self, point: ArrayLike) -> None:
        """Drive to ``point`` (2,) in the map frame instead of exploring; replans now."""
        goal = np.asarray(point, dtype=np.float64).reshape(-1)[:2]
        if goal.shape != (2,) or not np.all(np.isfinite(goal)):
            raise ValueError(f"set_goal needs a finite (x, y), got {point!r}")
        self._given_goal = goal.copy()
        self._set_target(goal)
        self._target_cells = np.empty((0, 2))
        self.follower.clear()
        self.status = "to_goal"
        self._last_replan_step = -(10**9)

    def clear_goal(self) -> None:
        """Go back to exploring frontiers; replans on the next step."""
        self._given_goal = None
        self._target = None
        self.follower.clear()
        self.status = "exploring"
        self._empty_replans = 0
        self._last_replan_step = -(10**9)

    def change_frame(self, new_from_old: ArrayLike) -> None:
        """The map frame changes (the robot now explores a merged map in a teammate's
        frame): carry what the policy remembers in map coordinates (remembered
        obstacles, blacklisted goals, the current target) over with the SE(2) transform
        ``new_from_old`` (3,), and drop the path, which is replanned on the next step."""
        transform = np.asarray(new_from_old, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(transform)):
            raise ValueError(f"change_frame needs a finite (x, y, theta), got {new_from_old!r}")
        self._close_returns = deque(
            (step, transform_points(transform, points)) for step, points in self._close_returns
        )
        if self._blacklist:
            points = transform_points(transform, np.array([(x, y) for x, y, _ in self._blacklist]))
            self._blacklist = [
                (float(x), float(y), until)
                for (x, y), (_, _, until) in zip(points, self._blacklist, strict=True)
            ]
        if self._target is not None:
            self._target = transform_points(transform, self._target[None, :2])[0]
        if self._given_goal is not None:
            self._given_goal = transform_points(transform, self._given_goal[None, :])[0]
        if len(self._target_cells):
            self._target_cells = transform_points(transform, self._target_cells)
        self._still_pose = compose(transform, self._still_pose)
        self._best_distance, self._best_step = math.inf, self._step
        self.follower.clear()
        self._last_replan_step = -(10**9)

    def set_teammate_targets(self, points: ArrayLike) -> None:
        """Teammates' targets (K, 2) in this robot's map frame: frontiers near them are
        discounted (``separation``). An empty array clears them."""
        targets = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        self._teammate_targets = targets[np.all(np.isfinite(targets), axis=1)]

    def set_teammates(self, positions: ArrayLike) -> None:
        """Teammates' positions (K, 2) in this robot's map frame: planning treats each as
        an obstacle of the robot's footprint, so that paths pass round a teammate
        instead of through it (SLAM leaves robots out of the maps). Empty clears them."""
        points = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        self._teammates = points[np.all(np.isfinite(points), axis=1)]

    def request_replan(self) -> None:
        """Replan on the next step (the coordinator saw two robots heading for one
        target)."""
        self._replan_now = True

    # --- the policy ------------------------------------------------------------------------

    def act(
        self,
        observation: dict[str, Any],
        robot_map: GridMap | PolicyContext,
        *,
        pose_in_map: ArrayLike | None = None,
    ) -> NDArray[np.float32]:
        """One normalised action ``(v, omega)`` in [-1, 1], float32 (2,).

        Parameters
        ----------
        observation : dict
            The env observation of this robot; uses ``pose`` (unless ``pose_in_map`` is
            given) and ``scan`` (a guard against obstacles the map misses).
        robot_map : GridMap or PolicyContext
            The map to explore (the robot's own, or a merged one), in the frame of the
            pose; or the team's context (the exploration-policy protocol,
            :meth:`act_in_context`).
        pose_in_map : array_like, shape (3,), optional
            The robot's pose in ``robot_map``'s frame, when that is not its own map frame.
        """
        if isinstance(robot_map, PolicyContext):
            return self.act_in_context(observation, robot_map)
        self._step += 1
        pose = np.asarray(
            observation["pose"] if pose_in_map is None else pose_in_map, dtype=np.float64
        )[:3]
        peer = observation.get("peer")
        self._sighted_body = np.empty((0, 2)) if peer is None else sighted_positions(peer)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        self._sighted_in_map = pose[:2] + self._sighted_body @ np.array([[c, s], [-s, c]])
        self._remember_close_returns(observation.get("scan"), pose)
        reason = self._replan_reason(robot_map, pose)
        if reason:
            self._replan(self._planning_grid(robot_map), pose, reason, robot_map)
        if self.status in ("done", "waiting", "blocked", "goal_unreachable", "idle"):
            self.follower.clear()
        scan = observation.get("scan")
        clearance = self._clearance(scan)
        if scan is not None and (self.status == "blocked" or self._step < self._escape_until):
            # No passable cell near the robot, or the scan keeps stopping it where the map
            # shows no wall: the planner cannot help; get out reactively, then replan.
            assert self._angles is not None
            if self._step + 1 == self._escape_until:
                self._last_replan_step = -(10**9)
            return escape_command(
                scan, self._angles, self.config.planner.robot_radius, config=self.config.follower
            )
        teammates = teammate_clearance(self._sighted_body, self.config.planner.robot_radius)
        action = self.follower.step(pose, clearance=clearance, teammates=teammates)
        moved = float(np.hypot(*(pose[:2] - self._still_pose[:2])))
        turned = abs(math.remainder(float(pose[2] - self._still_pose[2]), 2 * math.pi))
        if self.follower.status == "following" and moved < 0.05 and turned < 0.3:
            self._held_steps += 1
            if self._held_steps >= ESCAPE_AFTER_STEPS:
                self._held_steps = 0
                self._escape_until = self._step + ESCAPE_STEPS
                if self._target is not None and self._given_goal is None:
                    self._blacklist_point(self._target, self.config.blacklist_steps * 5)
                    self._blacklist_point(pose, self.config.blacklist_steps * 5)
        else:
            self._held_steps = 0
            self._still_pose = pose.copy()
        if self._given_goal is not None and self.follower.status == "reached":
            self.status = "arrived"
        return action

    def act_in_context(
        self, observation: dict[str, Any], context: PolicyContext
    ) -> NDArray[np.float32]:
        """The exploration-policy protocol's ``act`` (:mod:`agents.policy`): explore
        ``context.map`` from ``context.pose``, passing round the teammates and leaving
        their targets to them; a ``context.goal`` is driven to as a given goal
        (:meth:`set_goal`) until another one comes or :meth:`clear_goal`."""
        self.set_teammates(context.teammates)
        self.set_teammate_targets(context.teammate_targets)
        if context.goal is not None:
            goal = np.asarray(context.goal, dtype=np.float64).reshape(-1)[:2]
            given = self._given_goal
            if given is None or float(np.hypot(*(goal - given))) > self.config.goal_snap / 2:
                self.set_goal(goal)
        return self.act(observation, context.map, pose_in_map=context.pose)

    def _remember_close_returns(self, scan: Any, pose: FloatArray) -> None:
        """Keep the scan's close returns (map frame) for a while: obstacles the map
        misses (a desk corner seen only edge-on) that stop the robot must also stop the
        planner from sending it there again, as a costmap's obstacle layer does."""
        if scan is None or self._step % CLOSE_RETURN_EVERY:
            return
        ranges = np.asarray(scan, dtype=np.float64)
        if self._angles is None or len(self._angles) != len(ranges):
            self._clearance(ranges)
        assert self._angles is not None
        if len(self._sighted_body):
            # A robot is no obstacle to remember: it moves on (and a phantom wall where
            # it stood would close a corridor for minutes).
            ranges = mask_returns_near(
                ranges, self._sighted_body, self.config.planner.robot_radius + PEER_MARGIN, np.inf
            )
        close = ranges < CLOSE_RETURN_RANGE
        if not close.any():
            return
        angles = pose[2] + self._angles[close]
        points = pose[:2] + ranges[close, None] * np.column_stack([np.cos(angles), np.sin(angles)])
        self._close_returns.append((self._step, points))
        horizon = self._step - CLOSE_RETURN_MEMORY
        while self._close_returns and self._close_returns[0][0] < horizon:
            self._close_returns.popleft()

    def _planning_grid(
        self, grid: GridMap, robots_too: bool = True, returns_too: bool = True
    ) -> GridMap:
        """The map with (``returns_too``) remembered close returns and (``robots_too``)
        the robots in the way (:meth:`_robots_in_the_way`) marked OCCUPIED (what the
        planner plans on)."""
        parts = [p for _, p in self._close_returns] if returns_too else []
        robots = self._robots_in_the_way() if robots_too else np.empty((0, 2))
        if len(robots):
            radius_cells = self.config.planner.robot_radius / grid.resolution
            footprint = _disk_offsets(radius_cells) * grid.resolution
            parts.extend(centre + footprint[:, ::-1] for centre in robots)
        if not parts:
            return grid
        points = np.concatenate(parts)
        cells = grid.world_to_cell(points)
        cells = cells[grid.contains(cells)]
        if len(cells) == 0:
            return grid
        marked = grid.cells.copy()
        marked[cells[:, 0], cells[:, 1]] = OCCUPIED
        return GridMap(cells=marked, resolution=grid.resolution, origin=grid.origin)

    def _clearance(self, scan: Any) -> tuple[float, float] | None:
        if scan is None:
            return None
        ranges = np.asarray(scan, dtype=np.float64)
        if self._angles is None or len(self._angles) != len(ranges):
            self._angles = np.asarray(
                -np.pi + np.arange(len(ranges)) * (2.0 * np.pi / len(ranges)), dtype=np.float64
            )
        return lane_clearance(ranges, self._angles, self.config.planner.robot_radius)

    # --- when to replan --------------------------------------------------------------------

    def _replan_reason(self, grid: GridMap, pose: FloatArray) -> str:
        config = self.config
        since = self._step - self._last_replan_step
        if self._replan_now:
            self._replan_now = False
            return "requested"
        if self.follower.stuck_events != self._stuck_seen:
            self._stuck_seen = self.follower.stuck_events
            if self._target is not None and self._given_goal is None:
                self._blacklist_point(self._target)
                # Where the robot got stuck is a trap (a gap the planner's margin calls
                # passable in places, a desk corner): no frontier there for long.
                self._blacklist_point(pose, config.blacklist_steps * 5)
            return "stuck"
        if self.follower.status == "recovering":
            return ""
        if self._target is not None and self.status in ("exploring", "to_goal"):
            # A watchdog on the goal itself: orbiting a path point (pure pursuit that
            # cannot make the turn) moves the robot but never brings it closer.
            distance = float(np.hypot(*(pose[:2] - self._target[:2])))
            if distance < self._best_distance - NO_PROGRESS_DISTANCE:
                self._best_distance, self._best_step = distance, self._step
            elif self._step - self._best_step > NO_PROGRESS_STEPS:
                self._best_distance, self._best_step = math.inf, self._step
                if self._given_goal is None:
                    self._blacklist_point(self._target)
                return "no_progress"
        if self.status in ("done", "waiting", "blocked", "goal_unreachable"):
            # Blocked: retry soon (the escape manoeuvre is moving the robot out); waiting:
            # soon too (a teammate's target may be given up on any step).
            soon = self.status in ("blocked", "waiting")
            wait = config.min_replan_interval if soon else config.replan_interval
            return "retry" if since >= wait else ""
        if self._given_goal is not None:
            if self.status == "arrived":
                return ""
            if len(self.follower.path) == 0:
                return "no_plan"
        else:
            if len(self.follower.path) == 0:
                return "no_plan"
            if self.follower.status == "reached":
                if self._target is not None:
                    self._blacklist_point(self._target)
                return "goal_reached"
            if since >= config.min_replan_interval and self._target_explored(grid):
                return "target_explored"
        if self._path_blocked(grid):
            return "path_blocked"
        if since >= config.replan_interval:
            return "periodic"
        return ""

    def _robots_in_the_way(self) -> FloatArray:
        """The robots planning passes round: the teammates whose positions are known
        (after a merge); before that, while exploring, the robots the peer sensor sees
        (two robots unaware of each other would otherwise meet head-on in a doorway and
        push). Driving to a given goal (a rendezvous) plans through them."""
        if len(self._teammates) or self._given_goal is not None:
            return self._teammates
        return self._sighted_in_map

    def _path_blocked(self, grid: GridMap) -> bool:
        """Whether an OCCUPIED cell, or a robot in the way, now lies within the blocked
        radius of the path ahead."""
        path = self.follower.path
        if len(path) < 2:
            return False
        start = self.follower.progress
        # The path's segments and arc lengths, once per path (the path changes on replans).
        cached = self._path_arcs
        if cached is None or not np.array_equal(cached[0], path):
            segments = np.diff(path, axis=0)
            lengths = np.hypot(segments[:, 0], segments[:, 1])
            cached = (path, segments, lengths, np.concatenate(([0.0], np.cumsum(lengths))))
            self._path_arcs = cached
        _, segments, lengths, arc = cached
        step = grid.resolution
        along = np.arange(start, min(start + self.config.blocked_lookahead, arc[-1]), step)
        if len(along) == 0:
            return False
        index = np.clip(np.searchsorted(arc, along, side="right") - 1, 0, len(lengths) - 1)
        fraction = (along - arc[index]) / np.maximum(lengths[index], 1e-12)
        points = path[index] + fraction[:, None] * segments[index]
        radius_cells = self.config.planner.robot_radius / grid.resolution
        footprint = _disk_offsets(radius_cells)
        if _footprint_meets(grid.cells, grid.world_to_cell(points), footprint, OCCUPIED):
            return True
        # Known teammates are already in the grid planning sees; sighted robots are not.
        robots = self._robots_in_the_way()
        if len(robots) == 0 or len(self._teammates):
            return False
        gaps = np.hypot(*(points[:, None, :] - robots[None, :, :]).transpose(2, 0, 1))
        return bool(gaps.min() < 2.0 * self.config.planner.robot_radius + PEER_MARGIN)

    def _target_explored(self, grid: GridMap) -> bool:
        """Whether too few of the target frontier's cells are still FREE next to UNKNOWN."""
        if len(self._target_cells) == 0:
            return False
        inside, still = _still_frontier_cells(grid.cells, grid.world_to_cell(self._target_cells))
        if inside == 0:
            return False
        return bool(still < self.config.target_gone_fraction * len(self._target_cells))

    def _set_target(self, point: FloatArray) -> None:
        """A new goal restarts the progress watchdog; keeping the same one does not."""
        if self._target is None or np.hypot(*(point[:2] - self._target[:2])) > 0.5:
            self._best_distance, self._best_step = math.inf, self._step
        self._target = np.asarray(point, dtype=np.float64).copy()

    def _blacklist_point(self, point: FloatArray, steps: int | None = None) -> None:
        duration = self.config.blacklist_steps if steps is None else steps
        self._blacklist.append((float(point[0]), float(point[1]), self._step + duration))

    # --- replanning ------------------------------------------------------------------------

    def _replan(
        self, grid: GridMap, pose: FloatArray, reason: str, plain: GridMap | None = None
    ) -> None:
        config = self.config
        self.replans += 1
        self.last_replan_reason = reason
        self._last_replan_step = self._step
        self._blacklist = [entry for entry in self._blacklist if entry[2] > self._step]
        try:
            cost_grid = inflate(grid, config.planner)
            if self._given_goal is not None:
                distances = distance_field(cost_grid, pose, snap_distance=config.start_snap)
            else:
                start, reachable = reachable_cells(cost_grid, pose, snap_distance=config.start_snap)
        except ValueError:
            self.status = "blocked"
            self.follower.clear()
            return
        if self._given_goal is not None:
            self._plan_to_given_goal(cost_grid, distances)
            return
        empty_replans = self._empty_replans
        self._plan_to_frontier(grid, cost_grid, start, reachable, pose, plain)
        if self._target is not None or self.status == "waiting" or plain is None:
            return
        # Only the map ends exploration: known teammates, remembered close returns and the
        # planner's safety margin shape the paths, but a frontier they cut off (a teammate
        # in the doorway, a jamb's close returns closing a narrow door, a ragged wall's
        # margin leaving the robot on an island of the cost grid) is still to be explored:
        # plan without them, on the robot's bare footprint, the follower's scan guard
        # keeping the robot off walls and teammates. Robots only sighted (before a merge)
        # stay in the way: :meth:`_path_blocked` refuses a path through them.
        lenient = self._planning_grid(plain, robots_too=not len(self._teammates), returns_too=False)
        self._empty_replans = empty_replans
        bare = replace(config.planner, safety_margin=0.0)
        cost_grid = inflate(lenient, bare)  # fewer obstacles: cannot raise here
        start, reachable = reachable_cells(cost_grid, pose, snap_distance=config.start_snap)
        self._plan_to_frontier(lenient, cost_grid, start, reachable, pose, plain)

    def _follow(self, cost_grid: CostGrid, cells: IntArray, same_goal: bool = False) -> None:
        path = cost_grid.cell_to_world(shorten_path(cost_grid, cells))
        if same_goal and self.last_replan_reason == "periodic" and len(self.follower.path):
            # Hysteresis: a routine replan to the same goal keeps the current route unless
            # the new one is clearly shorter; otherwise two routes of about equal length
            # around a loop make the robot turn back and forth for ever.
            length = float(np.hypot(*np.diff(path, axis=0).T).sum()) if len(path) > 1 else 0.0
            if length > self.follower.remaining - ROUTE_HYSTERESIS:
                return
        self.follower.set_path(path)

    def _plan_to_given_goal(self, cost_grid: CostGrid, distances: DistanceField) -> None:
        assert self._given_goal is not None
        goal_cell = _nearest_reachable(distances, self._given_goal, self.config.goal_snap)
        if goal_cell is None:
            self.status = "goal_unreachable"
            self.follower.clear()
            return
        self._follow(cost_grid, distances.path_to(goal_cell))
        self.status = "to_goal"

    def _plan_to_frontier(
        self,
        grid: GridMap,
        cost_grid: CostGrid,
        start: tuple[int, int],
        reachable: NDArray[np.bool_],
        pose: FloatArray,
        plain: GridMap | None,
    ) -> None:
        """Choose a frontier and plan there. ``grid`` is what the robot plans on (with
        the teammates' footprints); ``plain``, when given, the map it was made from,
        where the teammates' own paths are searched (``team_allocation``)."""
        config = self.config
        frontiers = extract_frontiers(grid, config.frontiers, reachable=reachable)
        self._grid_origin, self._grid_resolution = grid.origin, grid.resolution
        self._frontier_set = frontiers
        self._frontiers = frontiers.centroids
        choice = -1
        if len(frontiers):
            # The search stops once no frontier left can beat the best one reached: the
            # choice, its path cost and its path are those of the whole search.
            claims = self._claims(frontiers, cost_grid, start)
            gains, excluded, current = self._utility_parts(frontiers, grid, claims)
            if config.team_allocation != "targets" and len(self._teammates):
                # The whole search: the joint choice needs every goal's path cost.
                distances = distance_field(cost_grid, pose, snap_distance=config.start_snap)
                # The teammates' searches run on the map without their own footprints.
                plain = grid if plain is None else self._planning_grid(plain, robots_too=False)
                teammate_grid = inflate(plain, config.planner)
                choice = self._joint_choice(frontiers, teammate_grid, distances, excluded, current)
            else:
                bound = gains + config.tie_jitter
                if current >= 0:
                    bound[current] += config.target_bonus
                bound[excluded | (gains < config.min_gain)] = -np.inf
                distances = best_goal_field(
                    cost_grid,
                    start,
                    frontiers.goal_cells,
                    bound,
                    cost_weight=config.cost_weight,
                    min_cost=config.follower.goal_tolerance,
                )
                choice = -1
            if choice < 0:
                choice = self._choose_frontier(frontiers, distances, (gains, excluded, current))
        if choice < 0:
            self._target = None
            self._target_cells = np.empty((0, 2))
            self.follower.clear()
            if len(frontiers) and self._left_to_teammates(frontiers, gains, excluded, claims):
                # Not done: what is left is the teammates' for now, and may come back to
                # this robot (a teammate that gives its target up, or is done).
                self._empty_replans = 0
                self.status = "waiting"
                return
            self._empty_replans += 1
            self.status = "done" if self._empty_replans >= config.done_after else "exploring"
            return
        self._empty_replans = 0
        goal = frontiers.goals[choice]
        same_goal = self._target is not None and bool(np.hypot(*(goal - self._target[:2])) < 0.3)
        self._set_target(goal)
        self._target_cells = grid.cell_to_world(frontiers.cells_of(choice))
        self._follow(cost_grid, distances.path_to(frontiers.goal_cells[choice]), same_goal)
        self.status = "exploring"

    def _left_to_teammates(
        self,
        frontiers: Frontiers,
        gains: FloatArray,
        excluded: NDArray[np.bool_],
        claims: FloatArray,
    ) -> bool:
        """Whether a frontier worth a trip on its own (gain >= ``min_gain``, not
        blacklisted) was passed over only because of the teammates' targets: taken by one,
        or discounted (:meth:`_utility_parts`' ``gains``) below ``min_gain``."""
        if len(claims) == 0:
            return False
        worthwhile = (frontiers.gains >= self.config.min_gain) & ~self._blacklisted(frontiers)
        passed_over = excluded | (gains < self.config.min_gain)
        return bool((worthwhile & passed_over).any())

    def _blacklisted(self, frontiers: Frontiers) -> NDArray[np.bool_]:
        """Per frontier, whether its goal is within ``blacklist_radius`` of a blacklisted
        point."""
        if not self._blacklist:
            return np.zeros(len(frontiers), dtype=bool)
        points = np.array([(x, y) for x, y, _ in self._blacklist])
        radius = self.config.blacklist_radius
        return _separation_discount(frontiers.goals, points, radius) < 1.0

    def _current_frontier(self, frontiers: Frontiers) -> int:
        """The new frontier that continues the current target's frontier, or -1."""
        if self._target is None or len(self._target_cells) == 0 or len(frontiers) == 0:
            return -1
        cells = world_to_cell(self._target_cells, self._grid_origin, self._grid_resolution)
        return _most_overlapping(frontiers.labels, cells)

    def _claims(
        self, frontiers: Frontiers, cost_grid: CostGrid, start: tuple[int, int]
    ) -> FloatArray:
        """The teammates' targets this robot leaves to them, (K, 2): all of them, or with
        ``contest_targets`` those the teammate is as near to as this robot (its path cost
        to the nearest frontier goal within ``shared_target_radius`` of the target, against
        the teammate's straight-line distance from its last known position). Contesting
        needs to know whose each target is, so it is off while a teammate has no target
        (teams of three or more)."""
        targets = self._teammate_targets
        config = self.config
        if not config.contest_targets or len(targets) == 0 or len(frontiers) == 0:
            return targets
        if len(self._teammates) != len(targets):
            return targets  # which target is whose is not known
        radius = self.shared_target_radius
        keep = np.ones(len(targets), dtype=bool)
        for k, (target, teammate) in enumerate(zip(targets, self._teammates, strict=True)):
            near = np.hypot(*(frontiers.goals - target).T) < radius
            if not near.any():
                continue
            # The search stops at the nearest of these goals: its cost is exact.
            cells = frontiers.goal_cells[near]
            field = best_goal_field(cost_grid, start, cells, np.zeros(len(cells)), cost_weight=1.0)
            if field.cost[cells[:, 0], cells[:, 1]].min() < float(np.hypot(*(target - teammate))):
                keep[k] = False
        return targets[keep]

    def _utility_parts(
        self, frontiers: Frontiers, grid: GridMap, targets: FloatArray
    ) -> tuple[FloatArray, NDArray[np.bool_], int]:
        """Per frontier, the path-cost-free parts of its utility: the gain after the
        teammates' discount (``team_discount``), whether it is excluded (a teammate's
        target, blacklisted), and the index of the current target's frontier (-1 if
        none). ``targets``: the teammates' targets left to them (:meth:`_claims`)."""
        config = self.config
        if config.team_discount == "overlap":
            view_range = config.frontiers.sensor_range
            discount = team_discount(frontiers.goals, targets, view_range, grid)
        else:
            discount = _separation_discount(frontiers.goals, targets, config.separation)
        gains = frontiers.gains * discount
        excluded = np.zeros(len(frontiers), dtype=bool)
        if len(targets):
            # A teammate's own target is taken, however big its gain.
            radius = self.shared_target_radius
            excluded |= _separation_discount(frontiers.goals, targets, radius) < 1.0
        excluded |= self._blacklisted(frontiers)
        return gains, excluded, self._current_frontier(frontiers)

    def _joint_choice(
        self,
        frontiers: Frontiers,
        cost_grid: CostGrid,
        distances: DistanceField,
        excluded: NDArray[np.bool_],
        current: int,
    ) -> int:
        """This robot's frontier by ``team_allocation`` (``"greedy"`` or ``"minpos"``)
        with its teammates at their last known positions, or -1 when it leaves none.

        Row 0 of the path costs is this robot's (``distances``), the others a search from
        each teammate's position on ``cost_grid`` (the straight-line distance when no
        passable cell lies near it). Undiscounted gains: the assignment itself keeps the
        robots apart."""
        config = self.config
        rows, cols = frontiers.goal_cells.T
        teammates = self._teammates
        costs = np.empty((1 + len(teammates), len(frontiers)))
        costs[0] = distances.cost[rows, cols]
        for k, position in enumerate(teammates):
            try:
                field = distance_field(cost_grid, position, snap_distance=config.start_snap)
                costs[1 + k] = field.cost[rows, cols]
            except ValueError:
                costs[1 + k] = np.hypot(*(frontiers.goals - position).T)
        own = np.zeros(len(frontiers))
        own[excluded | (costs[0] < config.follower.goal_tolerance)] = -np.inf
        if current >= 0:
            own[current] += config.target_bonus
        own += config.tie_jitter * self.rng.random(len(frontiers))
        if config.team_allocation == "minpos":
            utility = frontier_utility(
                frontiers.gains, costs[0], config.cost_weight, min_gain=config.min_gain
            )
            utility += own
            ok = np.isfinite(utility)
            if not ok.any():
                return -1
            # Rank: how many teammates have a shorter path to the frontier.
            rank = (costs[1:] < costs[0][None, :]).sum(axis=0)
            best_rank = rank[ok].min()
            utility[rank > best_rank] = -np.inf
            return int(np.argmax(utility))
        bonus = np.zeros(costs.shape)
        bonus[0] = own
        targets = self._teammate_targets
        if len(targets) == len(teammates):
            # A teammate keeps its target (the bonus this robot gives its own).
            radius = self.shared_target_radius
            for k, target in enumerate(targets):
                near = np.hypot(*(frontiers.goals - target).T)
                if near.min() < radius:
                    bonus[1 + k, int(np.argmin(near))] += config.target_bonus
        assignment = assign_frontiers(
            frontiers.goals,
            frontiers.gains,
            costs,
            cost_weight=config.cost_weight,
            separation=config.separation,
            min_gain=config.min_gain,
            bonus=bonus,
        )
        return int(assignment[0])

    def _choose_frontier(
        self,
        frontiers: Frontiers,
        distances: DistanceField,
        parts: tuple[FloatArray, NDArray[np.bool_], int],
    ) -> int:
        """Index of the frontier of highest utility, or -1 when none is worth it.

        ``distances`` needs exact path costs only at the goals that could be the best
        (:func:`~agents.planning.best_goal_field`); elsewhere upper bounds do. ``parts``
        are :meth:`_utility_parts` of ``frontiers``, as the search's bound used them."""
        config = self.config
        rows, cols = frontiers.goal_cells.T
        path_costs = distances.cost[rows, cols]
        gains, excluded, current = parts
        utility = frontier_utility(gains, path_costs, config.cost_weight, min_gain=config.min_gain)
        utility[excluded] = -np.inf
        # A goal next to the robot reveals nothing new: its frontier is what the robot
        # cannot see from here.
        utility[path_costs < config.follower.goal_tolerance] = -np.inf
        if current >= 0 and np.isfinite(utility[current]):
            utility[current] += config.target_bonus
        utility += config.tie_jitter * self.rng.random(len(utility))
        best = int(np.argmax(utility))
        return best if np.isfinite(utility[best]) else -1


@numba.njit(cache=True)
def _footprint_meets(
    cells: NDArray[np.int8], centres: IntArray, offsets: IntArray, value: np.int8
) -> bool:
    """Whether a cell of ``cells`` within the grid, at ``offsets`` (K, 2) from one of
    ``centres`` (N, 2), holds ``value``."""
    rows, cols = cells.shape
    for i in range(len(centres)):
        for k in range(len(offsets)):
            row = centres[i, 0] + offsets[k, 0]
            col = centres[i, 1] + offsets[k, 1]
            if 0 <= row < rows and 0 <= col < cols and cells[row, col] == value:
                return True
    return False


@numba.njit(cache=True)
def _still_frontier_cells(cells: NDArray[np.int8], targets: IntArray) -> tuple[int, int]:
    """Of the cells ``targets`` (K, 2): how many lie within the grid, and how many of those
    are FREE with an UNKNOWN 4-neighbour (a neighbour beyond the grid counts as one)."""
    rows, cols = cells.shape
    inside = still = 0
    for i in range(len(targets)):
        row, col = targets[i, 0], targets[i, 1]
        if not (0 <= row < rows and 0 <= col < cols):
            continue
        inside += 1
        if cells[row, col] != FREE:
            continue
        for d_row, d_col in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            r, c = row + d_row, col + d_col
            if not (0 <= r < rows and 0 <= c < cols) or cells[r, c] == UNKNOWN:
                still += 1
                break
    return inside, still


def _most_overlapping(labels: NDArray[np.int32], cells: IntArray) -> int:
    """Index of the frontier whose cells overlap ``cells`` (K, 2) most, or -1."""
    rows, cols = labels.shape
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < rows) & (cells[:, 1] >= 0) & (cells[:, 1] < cols)
    hits = labels[cells[inside, 0], cells[inside, 1]]
    hits = hits[hits > 0]
    if len(hits) == 0:
        return -1
    return int(np.bincount(hits).argmax()) - 1


def _nearest_reachable(
    distances: DistanceField, point: FloatArray, max_distance: float
) -> IntArray | None:
    """The reachable cell nearest to ``point`` within ``max_distance`` m, or None."""
    grid = distances.grid
    cell = grid.world_to_cell(point)
    radius = math.ceil(max_distance / grid.resolution)
    rows, cols = grid.shape
    r0, r1 = max(int(cell[0]) - radius, 0), min(int(cell[0]) + radius + 1, rows)
    c0, c1 = max(int(cell[1]) - radius, 0), min(int(cell[1]) + radius + 1, cols)
    if r0 >= r1 or c0 >= c1:
        return None
    candidates = np.argwhere(distances.reachable[r0:r1, c0:c1]) + np.array([r0, c0])
    if len(candidates) == 0:
        return None
    squared = ((candidates - cell) ** 2).sum(axis=1)
    best = int(np.argmin(squared))
    if squared[best] > radius**2:
        return None
    return np.asarray(candidates[best], dtype=np.int64)


def frontier_policy(env: EnvConfig, rng: np.random.Generator) -> ExplorerPolicy:
    """The exploration-policy factory (:data:`agents.policy.PolicyFactory`) of the frontier
    explorer, the team's default: ``mrslam run --policy agents.explorer:frontier_policy``."""
    return ExplorerPolicy.for_env(env, rng)
