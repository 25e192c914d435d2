"""The frontier explorer's tuning (docs/design.md §6): :class:`ExplorerConfig`, and the names
of its choices and of the explorer's states.

The explorer (:mod:`agents.explorer`), its parts (:mod:`agents.explorer_replan`,
:mod:`agents.explorer_choice`) and the frontier split (:mod:`agents.explorer_utility`)
import them from here; :mod:`agents.explorer` re-exports them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from agents.follower import FollowerConfig
from agents.frontiers import FrontierConfig
from agents.planning import PlannerConfig
from mrslam_env.config import EnvConfig
from mrslam_env.validation import check_fields, require

__all__ = ["ExplorerConfig", "ExplorerStatus", "TeamAllocation", "TeamDiscount"]

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
