"""When the frontier explorer replans, and how (docs/design.md §6).

:class:`Replanning` is a part of :class:`agents.explorer.ExplorerPolicy` (its base class;
the state it reads and sets is the policy's, made in :meth:`ExplorerPolicy.reset`):

* *when* (:meth:`~Replanning._replan_reason`): on request, when the follower is stuck, when
  the goal makes no progress (a watchdog), when the plan is gone or its goal reached, when
  the target frontier is explored, when the path ahead is blocked by a newly mapped wall or
  a robot in the way, and every ``replan_interval`` steps; goals that failed or led
  nowhere are blacklisted for a while;
* *how* (:meth:`~Replanning._replan`): the planning grid (the map with the remembered close
  returns and the robots in the way marked OCCUPIED) inflated, then a path to the given
  goal, or the frontier choice (:meth:`~agents.explorer_choice.FrontierChoice._plan_to_frontier`);
  when that finds no target (and is not waiting on the teammates), the fallback: the
  choice again on the robot's bare footprint, without the safety margin, the known
  teammates and the close returns (only the map ends exploration).
"""

from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import replace
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from agents.explorer_config import ExplorerConfig, ExplorerStatus
from agents.follower import PathFollower
from agents.planning import (
    CostGrid,
    DistanceField,
    distance_field,
    inflate,
    reachable_cells,
    shorten_path,
)
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap

__all__ = [
    "NO_PROGRESS_DISTANCE",
    "NO_PROGRESS_STEPS",
    "PEER_MARGIN",
    "ROUTE_HYSTERESIS",
    "Replanning",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


PEER_MARGIN = 0.15
"""Scan returns within the robot radius plus this (m) of a sighted robot are that robot."""
ROUTE_HYSTERESIS = 1.0
"""A routine replan to the same goal switches route only if the new one is this much
shorter (m)."""
NO_PROGRESS_DISTANCE = 0.3
"""Getting this much closer (m) to the goal counts as progress ..."""
NO_PROGRESS_STEPS = 150
"""... and without it for this many steps the goal is given up and the robot replans."""


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


class Replanning:
    """When and how :class:`~agents.explorer.ExplorerPolicy` replans (module notes)."""

    # The policy's state this part reads and sets (made in ExplorerPolicy.reset).
    config: ExplorerConfig
    follower: PathFollower
    status: ExplorerStatus
    replans: int
    last_replan_reason: str
    _step: int
    _last_replan_step: int
    _given_goal: FloatArray | None
    _target: FloatArray | None
    _target_cells: FloatArray
    _blacklist: list[tuple[float, float, int]]
    _teammates: FloatArray
    _sighted_in_map: FloatArray
    _replan_now: bool
    _empty_replans: int
    _stuck_seen: int
    _close_returns: deque[tuple[int, FloatArray]]
    _best_distance: float
    _best_step: int
    _path_arcs: tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None

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

    def _plan_to_frontier(self, *args: Any, **kwargs: Any) -> None:
        """Choose a frontier and plan there
        (:meth:`agents.explorer_choice.FrontierChoice._plan_to_frontier`)."""
        raise NotImplementedError


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
