"""Which frontier the frontier explorer drives to (docs/design.md §6).

:class:`FrontierChoice` is a part of :class:`agents.explorer.ExplorerPolicy` (a base class,
on :class:`~agents.explorer_replan.Replanning`; the state it reads and sets is the
policy's): on a replan, the frontiers reachable from the robot are extracted and the one
of highest utility ``gain - cost_weight * path_cost`` chosen
(:func:`~agents.explorer_utility.frontier_utility`), the current target's frontier kept
with ``target_bonus``, blacklisted goals skipped. The teammate-aware rules live here too:
which of the teammates' targets are theirs (:meth:`~FrontierChoice._claims`, with
``contest_targets``), how the gains near them are discounted and their own goals taken
(:meth:`~FrontierChoice._utility_parts`), the joint choice with the teammates
(``team_allocation``, :meth:`~FrontierChoice._joint_choice`), and whether what is left is
the teammates' for now (``waiting``, not ``done``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from agents.explorer_replan import Replanning
from agents.explorer_utility import (
    _separation_discount,
    assign_frontiers,
    frontier_utility,
    team_discount,
)
from agents.frontiers import Frontiers, extract_frontiers
from agents.planning import CostGrid, DistanceField, best_goal_field, distance_field, inflate
from mrslam_env.geometry import world_to_cell
from mrslam_env.gridmap import GridMap

__all__ = ["FrontierChoice"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class FrontierChoice(Replanning):
    """Which frontier :class:`~agents.explorer.ExplorerPolicy` drives to (module notes)."""

    # The policy's state this part reads besides Replanning's (made in ExplorerPolicy.reset).
    rng: np.random.Generator
    _teammate_targets: FloatArray
    _frontiers: FloatArray
    _frontier_set: Frontiers | None
    _grid_origin: tuple[float, float]
    _grid_resolution: float

    @property
    def shared_target_radius(self) -> float:
        """Frontier goals this close (m) to a teammate's target are the teammate's."""
        return self.config.separation / 4

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


def _most_overlapping(labels: NDArray[np.int32], cells: IntArray) -> int:
    """Index of the frontier whose cells overlap ``cells`` (K, 2) most, or -1."""
    rows, cols = labels.shape
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < rows) & (cells[:, 1] >= 0) & (cells[:, 1] < cols)
    hits = labels[cells[inside, 0], cells[inside, 1]]
    hits = hits[hits > 0]
    if len(hits) == 0:
        return -1
    return int(np.bincount(hits).argmax()) - 1
