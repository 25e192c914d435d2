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

One concern per module; the public names of all of them are importable from here. The
policy is one object built in layers, each adding to the one below (``ExplorerPolicy``,
then ``FrontierChoice``, then ``Replanning``), its state made in
:meth:`ExplorerPolicy.reset`:

* this module: the policy's shell (the act loop, what the coordinator and the recorder read
  and set, the scan's close returns, the reactive escape), :func:`frontier_policy`;
* :mod:`agents.explorer_choice`: which frontier, with the teammate-aware target rules
  (:class:`~agents.explorer_choice.FrontierChoice`);
* :mod:`agents.explorer_replan`: when to replan and how, and the fallback when the planning
  grid cuts off the frontiers left (:class:`~agents.explorer_replan.Replanning`);
* :mod:`agents.explorer_utility`: frontier utility and the frontier split for a team;
* :mod:`agents.explorer_config`: :class:`ExplorerConfig`.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.explorer_choice import FrontierChoice
from agents.explorer_config import ExplorerConfig, ExplorerStatus, TeamAllocation, TeamDiscount
from agents.explorer_replan import (
    NO_PROGRESS_DISTANCE,
    NO_PROGRESS_STEPS,
    PEER_MARGIN,
    ROUTE_HYSTERESIS,
)
from agents.explorer_utility import (
    assign_frontiers,
    frontier_utility,
    team_discount,
    team_frontier_goals,
)
from agents.follower import PathFollower, escape_command, lane_clearance, teammate_clearance
from agents.frontiers import Frontiers
from agents.policy import PolicyContext
from mrslam_env.config import EnvConfig
from mrslam_env.geometry import compose, transform_points
from mrslam_env.gridmap import GridMap
from mrslam_env.slam.scan import mask_returns_near, sighted_positions

__all__ = [
    "CLOSE_RETURN_EVERY",
    "CLOSE_RETURN_MEMORY",
    "CLOSE_RETURN_RANGE",
    "ESCAPE_AFTER_STEPS",
    "ESCAPE_STEPS",
    "NO_PROGRESS_DISTANCE",
    "NO_PROGRESS_STEPS",
    "PEER_MARGIN",
    "ROUTE_HYSTERESIS",
    "ExplorerConfig",
    "ExplorerPolicy",
    "ExplorerStatus",
    "TeamAllocation",
    "TeamDiscount",
    "assign_frontiers",
    "frontier_policy",
    "frontier_utility",
    "team_discount",
    "team_frontier_goals",
]

FloatArray = NDArray[np.float64]


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


class ExplorerPolicy(FrontierChoice):
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

    def _clearance(self, scan: Any) -> tuple[float, float] | None:
        if scan is None:
            return None
        ranges = np.asarray(scan, dtype=np.float64)
        if self._angles is None or len(self._angles) != len(ranges):
            self._angles = np.asarray(
                -np.pi + np.arange(len(ranges)) * (2.0 * np.pi / len(ranges)), dtype=np.float64
            )
        return lane_clearance(ranges, self._angles, self.config.planner.robot_radius)


def frontier_policy(env: EnvConfig, rng: np.random.Generator) -> ExplorerPolicy:
    """The exploration-policy factory (:data:`agents.policy.PolicyFactory`) of the frontier
    explorer, the team's default: ``mrslam run --policy agents.explorer:frontier_policy``."""
    return ExplorerPolicy.for_env(env, rng)
