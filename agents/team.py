"""The team coordinator: the paper's four interaction kinds as a state machine (design §6).

==========================  ==================================================================
state                       what the robots do
==========================  ==================================================================
``no_interaction``          each explores its own frontiers on its own map
``hypothesis_generation``   (comm up, relative pose unknown) the maps are exchanged and
                            merged by virtual robot motion; the ranked hypotheses are kept
``hypothesis_verification`` both drive to a rendezvous planned for the best untested
                            hypothesis; the peer sensor accepts or rejects it
``coordinated_exploration`` the transform is known: refined, the maps fused, both robots
                            explore the merged map and split the frontiers
==========================  ==================================================================

The coordinator uses the other robot's data only while the comm link is up: maps, poses
and sightings are exchanged then; a map received earlier stays usable (it is the robot's
copy), but is not refreshed while the link is down.

``robot_0`` holds the team frame: the merged map is in robot 0's map frame.

**N robots** (2 to 8). Each robot belongs to a group, the robots that verified transforms
connect it to, held in the frame of the group's lowest robot (its root); the common frame
is robot 0's group. Any two robots of different groups that can talk may merge their
groups' maps; the states above are then those of that pair (one merge or rendezvous at a
time, pairs that bring a robot into robot 0's frame first), told as two robots: each
robot's pose in its root's frame, the partner's peer row. An accepted (refined) transform
joins the second group to the first, its robots' transforms composed with it: a robot
joins robot 0's frame when any verified edge reaches its group. Each join is refined
against the merged map of the group it joins; once a group holds three robots or more,
all its transforms are then refined jointly (:func:`mrslam_env.merge.graph.refine_jointly`:
the overlapping pairs of own maps and the verified joins as edges of one pose graph),
not only chained. Maps are relayed through teammates (the link graph's
components). The robots in robot 0's frame explore the merged map and share frontiers;
the others explore alone. With two robots this is, step for step, the two-robot team.

**Policies.** Each robot explores with an exploration policy
(:class:`agents.policy.ExplorationPolicy`, built per robot by a factory; the frontier
explorer by default): whenever the team does not drive the robot itself it asks
``policy.act(observation, context)``. The team drives the legs to a given goal (a
rendezvous meeting point) itself, with a frontier explorer of its own used only for given
goals (:attr:`TeamCoordinator.explorers`; for the frontier explorer that is the policy
itself), so verification works whatever the policy does. What the team shares while
coordinating uses the policy's optional capabilities when it has them (module notes of
:mod:`agents.policy`): its ``target`` is shared with the teammates, ``request_replan()``
makes the later robot yield a target two chose, ``change_frame()`` carries its memory into the
common frame. A policy without a ``target`` is assigned a frontier of the merged map as
its context's ``goal`` instead (:func:`agents.explorer.team_frontier_goals`, every
``ExplorerConfig.replan_interval`` steps), which it may follow or ignore.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.explorer import ExplorerConfig, ExplorerPolicy, team_frontier_goals
from agents.planning import distance_field, inflate
from agents.policy import ExplorationPolicy, PolicyContext, PolicyFactory, build_policy
from agents.rendezvous import (
    RendezvousConfig,
    choose_meeting_point,
    field_on_lattice,
    judge_sighting,
    predicted_relative_pose,
    sighting_pose,
)
from agents.robot import DEFAULT_ENV, EnvFigures, build_for_env, check_against_env
from mrslam_env.config import EnvConfig
from mrslam_env.geometry import compose, inverse, mean_pose, transform_points
from mrslam_env.gridmap import UNKNOWN, GridMap
from mrslam_env.merge.decide import check_conflict_fraction
from mrslam_env.merge.dissimilarity import acceptance_index
from mrslam_env.merge.fuse import at_resolution, fuse_all, fuse_maps, resample_map, warp_map
from mrslam_env.merge.graph import GraphEdge, JointRefineConfig, alignment_edge, refine_jointly
from mrslam_env.merge.pipeline import (
    MergeConfig,
    MergeInputError,
    MergeResult,
    merge_maps,
    refine_transform,
    same_answer,
)
from mrslam_env.validation import check_fields, require

__all__ = [
    "Acceptance",
    "Decision",
    "MergeAttempt",
    "TeamConfig",
    "TeamCoordinator",
    "TeamState",
    "distinct_hypotheses",
    "heading_allowance",
    "in_plain_sight",
    "radio_contradiction",
    "window",
]

FloatArray = NDArray[np.float64]


class TeamState(StrEnum):
    NO_INTERACTION = "no_interaction"
    HYPOTHESIS_GENERATION = "hypothesis_generation"
    HYPOTHESIS_VERIFICATION = "hypothesis_verification"
    COORDINATED_EXPLORATION = "coordinated_exploration"


@dataclass(frozen=True, slots=True, kw_only=True)
class TeamConfig:
    """How the team decides. The robot's and the peer sensor's figures are in
    ``explorer`` and ``peer_range``: :meth:`for_env` sets them from the env."""

    explorer: ExplorerConfig = field(default_factory=ExplorerConfig)
    merge: MergeConfig = field(default_factory=lambda: MergeConfig(correlation_candidates=0))
    """The merge of the exchanged maps. Live, the wall correlation's proposals are left
    out (``correlation_candidates=0``): in a building with repeated parts they add
    confident aliased placements, and live each one costs a rendezvous drive."""
    rendezvous: RendezvousConfig = field(default_factory=RendezvousConfig)
    joint: JointRefineConfig | None = field(default_factory=JointRefineConfig)
    """With three robots or more in a group: the joint refinement of their transforms
    (design §6, teams of N robots); None: the transforms are only chained."""
    peer_range: float = DEFAULT_ENV.peer.detect_range
    """The peer sensor's detection range, m: the env's ``PeerSensorConfig.detect_range``
    (:meth:`for_env`)."""
    sight_margin: float = 1.0
    """A hypothesis that puts the robots closer than ``peer_range - sight_margin``
    (:attr:`in_sight_range`, m) is verified where they stand, without a rendezvous drive;
    the margin keeps the prediction's error inside the sensor's range (m, >= 0)."""
    comm_range: float = DEFAULT_ENV.comm.comm_range
    """The radio's range, m: the env's ``CommConfig.comm_range`` (:meth:`for_env`)."""
    comm_exact: bool = DEFAULT_ENV.comm.exact
    """Whether the link is up exactly when the robots are within ``comm_range`` (the env's
    ``CommConfig``: not blocked by walls, no packet loss; :meth:`for_env`). Then a link
    down says the robots are further apart than ``comm_range``; a link up always says
    they are within it."""
    radio_margin: float | None = 1.0
    """The radio as a range sensor (design §6): a hypothesis that puts the robots more
    than ``comm_range`` plus this margin (m) apart on a step the link was up, or (with
    ``comm_exact``) closer than ``comm_range`` less the margin on a step it was down, is
    rejected without a rendezvous, on the robots' whole tracks when it is formed and
    on every step while it is tested. The margin covers a true hypothesis' position
    error and the SLAM poses' (None: the radio is not used); its heading error is
    ``radio_heading_tolerance``'s."""
    radio_heading_tolerance: float = math.radians(1.0)
    """The heading error (rad) a true hypothesis may have in the radio check: it moves the
    partner's predicted place by up to its tangent times the partner's distance from the
    place the hypothesis is pinned (where the maps overlap: within the partner's track,
    taken at its bounding box's farthest corner). Where that reach exceeds
    ``radio_margin`` it is the margin instead. 1°: the final-error bound (a hypothesis
    further off is wrong); with the margin alone a true hypothesis 1° off would be
    rejected for good once the partner is 57 m from the pivot."""
    interaction: bool = True
    """False: the robots never interact (the independent-exploration baseline)."""
    keep_merges: bool = False
    """Keep every merge attempt, with its stages (``merge_maps(..., trace=True)``), for
    :meth:`TeamCoordinator.pop_merge_attempts` (the recorder draws them)."""
    min_map_area: float = 15.0
    """Each map must know at least this much (m²) before a merge is tried."""
    regrow_factor: float = 1.3
    """After an attempt, the next waits until the maps together know this many times as
    much as then."""
    max_rendezvous: int = 3
    """Hypotheses verified per attempt, best first. Only hypotheses the merge found
    consistent with both maps (``ScoredHypothesis.confident``: enough overlap, few
    conflicts, not refuted) are worth the drive; several of them is exactly the
    ambiguity (repeated rooms, mirrored wings) that only a rendezvous can settle."""
    max_meeting_cost: float = 25.0
    """Skip a hypothesis whose meeting point is further than this (m of weighted path)
    for the later robot: the detour would cost more exploration than the merge saves."""
    merged_map_every: int = 5
    """Steps between refreshes of the merged map while coordinating."""
    seek_contact_after: int = 600
    """Contact seeking (design §6): a robot that had a link to a robot outside its group
    and has been without one for this many steps (0: never seek) drives back to where
    it had it (``seek_contact_back``), and waits there; its partner, which lost the same
    link on the same step, does the same, so the two are back in range without knowing
    where the other is. A robot that never had such a link explores on (the starts'
    places say nothing about where the others are)."""
    seek_contact_back: int = 100
    """The place a contact-seeking robot goes back to is where it was this many steps
    before the link was lost (or where the link came up, if later): the robots lose the
    link at the edge of the radio's range, and the places they held together a little
    earlier are well inside it."""
    seek_contact_wait: int = 200
    """Steps a contact-seeking robot waits at the place of its last link before it
    explores again (and seeks again after another ``seek_contact_after`` steps); at
    least until ``seek_contact_after`` steps after it began seeking, as long as its
    partner may need to come back. A robot not back at the place by then gives up."""
    sighting_count: int = 10
    """Hypotheses from a chance meeting (design §6): when two robots of different groups
    with the link up see each other on this many steps (0: never), all within twice as
    many steps, the relative poses those sightings give (``T = p0 · s · p1⁻¹``, both
    robots' sightings) are averaged into a hypothesis. Averaged over 10 steps (up to 20
    sightings) the peer sensor's heading noise (0.05 rad a sighting) falls to about
    0.7°; the maps' refinement does the rest."""
    sighting_verify_distance: float = 2.0
    """A hypothesis from sightings is verified only by sightings made after both robots
    moved at least this far (m, straight line, each) from where they were when it
    formed, so that the check tests the maps (and the SLAM drift) between two places,
    never the sightings that made it."""
    sighting_wait: int = 300
    """Steps a hypothesis from sightings waits for such a later meeting while the robots
    explore on; then both drive to meet at a place at least
    ``sighting_verify_distance`` from where it formed (the usual rendezvous)."""
    undecided_wait: int | None = None
    """Rivals wait (design §6): when the merge leaves two or more distinct confident
    answers open, each of them but the merge's own answer (when its verdict was
    ``merged``) is not driven to: it waits while the robots explore on, tested by every
    sighting and rejected when it keeps the robots in plain sight unseen, as a
    hypothesis from sightings is, until both robots have nothing left to explore, or for
    at most this many steps (None: no limit; 0: driven to at once, as any other); then
    both drive to meet. Meanwhile the maps are merged again as they grow, and a newer
    merge's hypotheses take its place unless they give the same answer."""
    departure_share: float = 0.0
    """On a rendezvous drive, the robot with the shorter way to the meeting point explores
    on for this share of the difference of the two ways (as time at the cruise speed)
    before it leaves for it, instead of waiting there for the other (0, the default: both
    leave at once). 0.5 (exploring, it may move away from the point as far as it went)
    was measured no better (docs/decisions.md)."""
    teammate_memory: int = 50
    """While coordinating, a teammate's position and target as last received over the
    link are used for at most this many steps without the link (0: for ever); older,
    they are dropped (they mislead the split of the frontiers more than they help)."""
    refine_every: int = 400
    """Steps between re-refinements of the transform on the grown maps while the link is
    up (0: never); one that falls due with the link down runs as soon as it is back. The
    maps at verification can overlap too little to fix the heading well; the grown maps
    overlap more. A re-refinement that leaves the rendezvous
    tolerances of the verified hypothesis is not kept; given transforms
    (:meth:`TeamCoordinator.start_coordinated`) are never re-refined
    (docs/decisions.md)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            non_negative=(
                "min_map_area",
                "max_meeting_cost",
                "sight_margin",
                "sighting_verify_distance",
                "departure_share",
            ),
            positive=("peer_range", "comm_range"),
            counts=(
                "max_rendezvous",
                "merged_map_every",
                "seek_contact_back",
                "seek_contact_wait",
            ),
            whole=(
                "refine_every",
                "seek_contact_after",
                "sighting_count",
                "sighting_wait",
                "teammate_memory",
            ),
        )
        name = type(self).__name__
        factor = self.regrow_factor
        ok = isinstance(factor, int | float) and math.isfinite(factor) and factor >= 1
        require(name, "regrow_factor", factor, ok, "a finite number >= 1")
        if self.undecided_wait is not None:
            check_fields(self, whole=("undecided_wait",))
        if self.radio_margin is not None:
            check_fields(self, non_negative=("radio_margin", "radio_heading_tolerance"))
            tolerance = self.radio_heading_tolerance
            ok = tolerance < math.pi / 2  # its tangent sets the reach
            require(name, "radio_heading_tolerance", tolerance, ok, "< pi/2 (radians)")
        margin, peer_range = self.sight_margin, self.peer_range
        require(name, "sight_margin", margin, margin < peer_range, f"< peer_range ({peer_range})")

    @property
    def in_sight_range(self) -> float:
        """Closer than this (m) the robots are in the peer sensor's sight, with a margin."""
        return self.peer_range - self.sight_margin

    @staticmethod
    def env_figures(env: EnvConfig) -> EnvFigures:
        """The fields that are the env's figures: the peer sensor's range, the radio's
        range and whether the link is up exactly within it."""
        return {
            "peer_range": ("peer.detect_range", env.peer.detect_range),
            "comm_range": ("comm.comm_range", env.comm.comm_range),
            "comm_exact": ("comm.exact", env.comm.exact),
        }

    @classmethod
    def for_env(cls, env: EnvConfig, **overrides: Any) -> TeamConfig:
        """The team for the env's robots and sensors: ``explorer`` from
        :meth:`ExplorerConfig.for_env` unless given (then checked against the env),
        ``peer_range`` from the env; ``overrides`` set the tuning fields."""
        overrides.setdefault("explorer", ExplorerConfig.for_env(env))
        config = build_for_env(cls, cls.env_figures(env), overrides)
        config.check_env(env)
        return config

    def check_env(self, env: EnvConfig) -> None:
        """Raise a ``ValueError`` if this config contradicts the env's robot or sensors."""
        check_against_env(self, self.env_figures(env))
        self.explorer.check_env(env)


@dataclass(frozen=True, slots=True)
class Decision:
    """One thing the team decided (for the ``events`` log)."""

    step: int
    text: str


@dataclass(frozen=True, slots=True, eq=False)
class MergeAttempt:
    """One merge of the exchanged maps (kept with ``TeamConfig.keep_merges``)."""

    number: int
    """Counts the attempts from 1."""
    step: int
    result: MergeResult
    """With its trace: ``merge_maps(map0, map1, ..., trace=True)``."""
    map0: GridMap
    map1: GridMap
    robots: tuple[int, int] = (0, 1)
    """The robots whose maps (their groups' maps, in the groups' root frames) were merged."""


@dataclass(frozen=True, slots=True)
class Acceptance:
    """A hypothesis the team accepted (for the recording's story of a merge)."""

    step: int
    index: int
    """Its number among the hypotheses to verify (``#index``), from 0."""
    count: int
    """How many hypotheses were to verify beside it."""
    proposed_by: str
    """Where it came from: a merge source (:attr:`ScoredHypothesis.proposed_by`:
    ``"virtual robot"``, ``"correlation"``, ``"hough"``...) or ``"sighting"``."""
    attempt: int | None
    """The merge attempt that proposed it (None: from sightings)."""
    how: str
    """How it was verified (the acceptance's words)."""
    verified: FloatArray
    """The hypothesis as verified, before refinement (side 0's from side 1's frame)."""
    refined: FloatArray
    """The transform kept after refinement."""


@dataclass(slots=True)
class _Rendezvous:
    hypothesis: FloatArray
    index: int
    meeting_point: FloatArray
    """In map 0's frame."""
    started: int
    arrived_at: int | None = None
    in_place: bool = False
    """Verified where the robots stand (no meeting point to drive to)."""
    first_match: int | None = None
    """Step of the first sighting that matched the prediction."""
    last_match: int | None = None
    """Step of the last sighting that matched (for a match where the robots stood: the
    step of that match)."""
    matches: int = 0
    motion: float = 0.0
    """Both robots' travel since the first match, m."""
    previous: list[FloatArray] | None = None
    unseen: int = 0
    """Steps in a row the hypothesis put the robots in plain sight, unseen."""
    others_unseen: dict[int, int] = field(default_factory=dict)
    """The same count for each hypothesis still waiting its turn (by index): the drive
    for one hypothesis also tests the others."""
    waits: bool = False
    """Waits, the robots exploring on, for a later chance meeting before anyone is
    driven for it: a hypothesis from sightings, or one the merge did not decide
    (:attr:`TeamConfig.undecided_wait`)."""
    hold: tuple[int, int] | None = None
    """On a drive: the side that explores on before it leaves for the meeting point, and
    the step it leaves (:attr:`TeamConfig.departure_share`)."""
    formed_at: list[FloatArray] | None = None
    """A hypothesis from sightings (:attr:`TeamConfig.sighting_count`): where the two
    robots were (side 0, side 1; their group roots' frames) when it formed; sightings
    count only once both are ``sighting_verify_distance`` away. None: from the merge."""


MapSource = Callable[[int], GridMap]


SIGHT_BAND = (-0.25, 0.0, 0.25)
"""Offsets (m) of the lines of sight checked side by side."""
UNSEEN_STEPS = 10
"""On the way to a meeting point, a hypothesis that keeps the other robot in plain sight
(:func:`in_plain_sight`) for this many steps in a row while the peer sensor sees nothing
is rejected there and then."""


def in_plain_sight(
    pose: FloatArray, predicted: FloatArray, grid: GridMap, *, sight_range: float
) -> bool:
    """Whether a robot at ``predicted`` (its pose in the observer's body frame) would be
    in the peer sensor's sight from ``pose`` (the observer's pose in ``grid``): closer than
    ``sight_range`` (m, :attr:`TeamConfig.in_sight_range`) and further than 0.5 m, across
    cells ``grid`` knows to be free all the way, in a band :data:`SIGHT_BAND` wide."""
    distance = float(np.hypot(predicted[0], predicted[1]))
    if not 0.5 < distance < sight_range:
        return False
    start = pose[:2]
    end = transform_points(pose, predicted[None, :2])[0]
    # A band, not a line: the prediction is only good to a few decimetres, and a wall
    # corner just beside the line would hide the robot.
    normal = np.array([start[1] - end[1], end[0] - start[0]]) / distance
    line = start + np.linspace(0.0, 1.0, 50)[:, None] * (end - start)
    samples = np.concatenate([line + offset * normal for offset in SIGHT_BAND])
    cells = grid.world_to_cell(samples)
    if not grid.contains(cells).all():
        return False
    return bool(grid.free[cells[:, 0], cells[:, 1]].all())


def distinct_hypotheses(
    ranked: list[FloatArray], rejected: list[FloatArray], pivot: FloatArray, config: MergeConfig
) -> list[FloatArray]:
    """The hypotheses worth a rendezvous each, best first: ``ranked`` without those that
    are one answer (:func:`~mrslam_env.merge.pipeline.same_answer` at ``pivot``, a point of
    map 1) with a better-ranked one or with a ``rejected`` one. Refined from different
    starts, two candidates can end as one answer, and one rendezvous settles both."""
    kept: list[FloatArray] = []
    for transform in ranked:
        if not any(same_answer(transform, known, pivot, config) for known in rejected + kept):
            kept.append(transform)
    return kept


def radio_contradiction(
    hypothesis: FloatArray,
    track0: FloatArray,
    track1: FloatArray,
    link: NDArray[np.bool_],
    *,
    comm_range: float,
    exact: bool,
    allowance: ArrayLike = 0.0,
) -> float:
    """How far (m) ``hypothesis`` (``side0_from_side1``) puts two robots outside what
    their radio link said, at worst over the steps given: on a step the link was up, the
    amount by which the robots' distance under the hypothesis exceeds ``comm_range``; on
    one it was down (only if the link is up ``exact``-ly within ``comm_range``), the
    amount by which it falls short of it; less the step's ``allowance`` (m, scalar or
    (T,): the error a true hypothesis may have there). ``track0`` (T, 2) and ``track1``
    (T, 2) are the robots' positions in their side's frame on those steps, ``link`` (T,)
    whether the link was up. Negative (or -inf for no step) when the hypothesis agrees
    with the radio."""
    if len(link) == 0:
        return -math.inf
    predicted = transform_points(hypothesis, np.asarray(track1, dtype=np.float64))
    distance = np.hypot(*(predicted - np.asarray(track0, dtype=np.float64)).T)
    down = comm_range - distance if exact else np.full_like(distance, -math.inf)
    return float((np.where(link, distance - comm_range, down) - allowance).max())


def heading_allowance(track: FloatArray, known: FloatArray, tolerance: float) -> FloatArray:
    """(T,) m: how far a heading error of ``tolerance`` (rad) moves each place of
    ``track`` (T, 2) about a pivot anywhere in the box bounding ``known`` (K, 2; the
    robot's whole track, where the maps that pin the hypothesis were made): the tangent
    times the distance to the box's farthest corner."""
    track = np.asarray(track, dtype=np.float64).reshape(-1, 2)
    known = np.asarray(known, dtype=np.float64).reshape(-1, 2)
    if len(known) == 0 or len(track) == 0:
        return np.zeros(len(track))
    low, high = known.min(axis=0), known.max(axis=0)
    reach = np.maximum(np.abs(track - low), np.abs(track - high))
    return math.tan(tolerance) * np.hypot(*reach.T)


def _either_in_sight(
    poses: list[FloatArray], predicted: FloatArray, maps: MapSource, sight_range: float
) -> bool:
    """Whether either robot would have the other in plain sight (closer than
    ``sight_range``, m), each judged on its own map, given robot 1's ``predicted`` pose in
    robot 0's body frame."""
    return in_plain_sight(poses[0], predicted, maps(0), sight_range=sight_range) or (
        in_plain_sight(poses[1], inverse(predicted), maps(1), sight_range=sight_range)
    )


class TeamCoordinator:
    """Drives a team of N robots through the four kinds of interaction (module notes).

    Parameters
    ----------
    config : TeamConfig
        Defaults to the default env's robots and sensors; :meth:`for_env` follows a given
        env's.
    rng : numpy.random.Generator
        All randomness (policies' and explorers' tie-breaking, merging).
    n_robots : int
        Team size (>= 2; the env's ``n_robots``).
    policy_factory : PolicyFactory, optional
        Builds each robot's exploration policy (``factory(env, rng)``, the robot's own
        generator drawn from ``rng``); None: the frontier explorer with ``config.explorer``.
    env : EnvConfig, optional
        What ``policy_factory`` is given (default: the default env).

    Attributes
    ----------
    policies : list of ExplorationPolicy
        Each robot's policy.
    explorers : list of ExplorerPolicy
        What drives each robot's legs to a given goal: the policy itself when it is a
        frontier explorer, else one of the team's own.
    roots : list of int
        Per robot, the lowest robot of its group (the robots its verified transforms
        connect it to); the common frame is the group of robot 0.
    frames : list of ndarray (3,)
        Per robot, ``root_from_map``: its map frame in its group root's map frame (robot
        0's, the common frame, once it joined).
    pair : tuple of int
        The two robots whose groups are being merged (side 0, side 1; the lower root
        first), or were last.

    Use: each step call :meth:`act` with the env observations and a function giving robot
    i's current own map; read :attr:`state`, :meth:`common_transform`, :attr:`merged_map`,
    :attr:`rendezvous_point`, :meth:`plan_of` and :meth:`frontiers_of` for recording;
    :meth:`pop_decisions` returns what was decided since the last call.
    """

    def __init__(
        self,
        config: TeamConfig | None = None,
        *,
        rng: np.random.Generator,
        n_robots: int = 2,
        policy_factory: PolicyFactory | None = None,
        env: EnvConfig | None = None,
    ) -> None:
        if not isinstance(n_robots, int) or isinstance(n_robots, bool) or n_robots < 2:
            raise ValueError(f"a team needs n_robots >= 2, got {n_robots!r}")
        self.config = config if config is not None else TeamConfig()
        self.rng = rng
        # Sighting hypotheses are refined with a generator of their own, so that one formed
        # (and perhaps set aside) does not shift the draws of the merges and explorers.
        self._sighting_rng = rng.spawn(1)[0]
        self.n_robots = n_robots
        self.policies: list[ExplorationPolicy] = []
        self.explorers: list[ExplorerPolicy] = []
        for _ in range(n_robots):
            seed = rng.integers(2**63)
            policy: ExplorationPolicy
            if policy_factory is None:
                explorer = ExplorerPolicy(np.random.default_rng(seed), self.config.explorer)
                policy = explorer
            else:
                env_config = env if env is not None else DEFAULT_ENV
                policy = build_policy(policy_factory, env_config, np.random.default_rng(seed))
                if isinstance(policy, ExplorerPolicy):
                    explorer = policy
                else:  # the team's own explorer drives the legs to a given goal
                    goal_rng = np.random.default_rng([int(seed), 1])
                    explorer = ExplorerPolicy(goal_rng, self.config.explorer)
            self.policies.append(policy)
            self.explorers.append(explorer)
        n = n_robots
        self.state = TeamState.NO_INTERACTION
        self.step = 0
        self.roots = list(range(n))
        self.frames: list[FloatArray] = [np.zeros(3) for _ in range(n)]
        self.verified: list[FloatArray | None] = [None] * n
        """Per robot, ``common_from_map`` as verified (the hypotheses before refinement,
        composed), once it joined the common frame; None before."""
        self.step_joined: list[int | None] = [0] + [None] * (n - 1)
        self.pair: tuple[int, int] = (0, 1)
        self.hypotheses: list[FloatArray] = []
        """The current pair's hypotheses (``side0_from_side1``: group frame from group
        frame), best first."""
        self._rejected: dict[tuple[int, int], list[FloatArray]] = {}
        """Per pair of group roots, the hypotheses a rendezvous rejected: the maps' frames
        never move, so they stay wrong and are not tried again."""
        self.hypotheses_tested = 0
        self._undecided: list[FloatArray] = []
        """The last merge's hypotheses that wait (:attr:`TeamConfig.undecided_wait`): its
        confident answers other than its own ``merged`` one, when it left a rival open."""
        self.rendezvous_steps = 0
        """Robot-steps spent driving to a meeting point or waiting there."""
        self._meeting_costs: tuple[float, float] | None = None
        """Each side's way (m) to the last meeting point chosen."""
        self.first_hypothesis_step: int | None = None
        """The step the first hypothesis was put to verification (any kind)."""
        self.first_rendezvous_step: int | None = None
        """The step robots were first driven to a meeting point."""
        self.views: list[GridMap | None] = [None] * n
        """Per robot in the common frame, the merged map it explores, in robot 0's frame:
        its own map, current, fused with the others' as it last received them. One map
        while every link among them is up; while one is down, each robot still sees all
        of its own mapping (a robot exploring on a stale copy of its own map drives to
        frontiers it has already explored)."""
        self.rendezvous: _Rendezvous | None = None
        self.hypothesis_sources: list[str] = []
        """Per entry of :attr:`hypotheses`, where it came from (:class:`Acceptance`'s
        ``proposed_by``); for the recording only."""
        self.hypotheses_attempt: int | None = None
        """The merge attempt that gave :attr:`hypotheses` (None: from sightings)."""
        self.acceptances: list[Acceptance] = []
        """Every hypothesis accepted, in order; for the recording only."""
        self._decisions: list[Decision] = []
        self._merge_attempts: list[MergeAttempt] = []
        self._merges_tried = 0
        self._received: dict[tuple[int, int], GridMap] = {}
        """``(i, j)``: robot j's map as robot i last received it (while they could talk,
        directly or through teammates)."""
        self._last_merge_step = -(10**9)
        self._last_refine_step = 0
        self._retry_area: dict[tuple[int, int], float] = {}
        """Per pair of group roots: the area the maps must know before the next attempt."""
        self._poses = [np.zeros(3) for _ in range(n)]
        self._last_poses = [np.zeros(3), np.zeros(3)]
        """The current pair's poses, each in its group root's frame."""
        self._last_observations: list[dict[str, Any]] = []
        """The current pair's observations, as two robots see each other (``peer`` and
        ``comm`` of the partner only)."""
        self._links = np.zeros((n, n), dtype=bool)
        self._reach = np.eye(n, dtype=bool)
        self._link = False
        """The current pair's link."""
        self._verified_at: list[FloatArray] = [np.zeros(2) for _ in range(n)]
        """Per robot, its position (own map) when the hypothesis that joined it was
        accepted."""
        self._given = False
        """The transforms were given (:meth:`start_coordinated`): known, never
        re-refined."""
        self._shared: dict[tuple[int, int], tuple[FloatArray, FloatArray | None, int]] = {}
        """``(i, j)``: robot j's position and target in the common frame as robot i last
        received them (coordinated exploration), and the step it received them; dropped
        after ``teammate_memory`` steps."""
        self._on_goal = [False] * n
        """Per robot, whether the team drives it to a given goal (else its policy acts)."""
        self._assigned: list[FloatArray | None] = [None] * n
        """Per robot whose policy has no ``target``: the frontier the team assigned it
        while coordinating (its context's ``goal``)."""
        self._last_assignment = -(10**9)
        self._group_maps: dict[int, tuple[tuple[int, ...], int, GridMap]] = {}
        """Per group root (groups outside the common frame): its members, the step and
        the fusion of their maps in its frame."""
        self._join_edges: list[GraphEdge] = []
        """The alignments that joined two groups (nodes: the groups' roots then), each
        refined on the two groups' maps: edges of the joint refinement."""
        self._maps: MapSource = _no_map
        """The robots' own maps (the last ``maps`` given to :meth:`act`)."""
        self._contact_step: list[int | None] = [None] * n
        """Per robot, the last step it had a link to a robot outside its group (None:
        never)."""
        self._contact_track: list[deque[FloatArray]] = [
            deque(maxlen=self.config.seek_contact_back + 1) for _ in range(n)
        ]
        """Per robot, where it was (own map frame) on the last steps of its last link,
        at most ``seek_contact_back + 1`` of them: the first is the place it seeks."""
        self._seek_from = [0] * n
        """Per robot, the step its time without a link counts from for the next search
        (the end of the last one)."""
        self._seeking: list[tuple[int, int | None] | None] = [None] * n
        """Per robot seeking contact: the step it began and the step it arrived at the
        place (None while on its way); None when not seeking."""
        self.seeking_steps = [0] * n
        """Per robot, the steps it spent seeking contact (driving back and waiting)."""
        self._sightings: dict[tuple[int, int], deque[tuple[int, FloatArray]]] = {}
        """Per pair of robots (side 0, side 1), the recent steps on which they saw each
        other, each with the relative pose of their groups' frames it gives."""
        self.sighting_hypotheses = 0
        """Hypotheses formed from sightings (:attr:`TeamConfig.sighting_count`)."""
        self._tracks: list[list[FloatArray]] = [[] for _ in range(n)]
        """Per robot, its position (own map frame) on every step so far."""
        self._link_track: list[NDArray[np.bool_]] = []
        """The links between the robots (n, n) on every step so far."""
        self._radio_since = 0
        """The first track step the next per-step radio check judges (:meth:`_verify`)."""
        self.radio_rejections = 0
        """Hypotheses rejected by the radio (:attr:`TeamConfig.radio_margin`)."""

    @classmethod
    def for_env(
        cls,
        env: EnvConfig,
        *,
        rng: np.random.Generator,
        config: TeamConfig | None = None,
        n_robots: int = 2,
        policy_factory: PolicyFactory | None = None,
    ) -> TeamCoordinator:
        """A team for the env's robots and sensors: ``config`` (checked against the env)
        or :meth:`TeamConfig.for_env`; ``policy_factory`` builds the policies for ``env``."""
        if config is None:
            config = TeamConfig.for_env(env)
        config.check_env(env)
        return cls(config, rng=rng, n_robots=n_robots, policy_factory=policy_factory, env=env)

    # --- what recording reads -----------------------------------------------------------

    @property
    def members(self) -> list[int]:
        """The robots in the common frame (robot 0's group), in index order."""
        return [i for i in range(self.n_robots) if self.roots[i] == 0]

    def common_transform(self, robot: int) -> FloatArray | None:
        """``map0_from_map<robot>`` once ``robot`` joined the common frame, else None."""
        return self.frames[robot].copy() if self.roots[robot] == 0 else None

    @property
    def transform(self) -> FloatArray | None:
        """``map0_from_map1`` once robot 1 joined (refined), else None (two robots)."""
        return None if self.step_joined[1] is None else self.frames[1]

    @property
    def preliminary_transform(self) -> FloatArray | None:
        """Robot 1's ``map0_from_map1`` as verified, before refinement, or None."""
        return self.verified[1]

    @property
    def step_verified(self) -> int | None:
        """The step of the first verified merge, or None."""
        steps = [s for s in self.step_joined[1:] if s is not None]
        return min(steps) if steps else None

    @property
    def rejected(self) -> list[FloatArray]:
        """The current pair's rejected hypotheses."""
        return self._rejected.setdefault(self._pair_roots(), [])

    @property
    def merged_map(self) -> GridMap | None:
        """Robot 0's view of the merged map (its own map and the others' as last
        received), in map 0's frame, or None before a merge; robot i explores
        :attr:`views` ``[i]``."""
        return self.views[0]

    @property
    def rendezvous_point(self) -> FloatArray | None:
        """The meeting point in the frame of side 0's group root while verifying."""
        return None if self.rendezvous is None else self.rendezvous.meeting_point.copy()

    def plan_of(self, robot: int) -> FloatArray:
        """The path ``robot`` follows, (P, 2) in the frame of the map it explores: the
        team's on a leg to a given goal, else its policy's ``plan`` (empty if it has none)."""
        source: Any = self.explorers[robot] if self._on_goal[robot] else self.policies[robot]
        return _points(getattr(source, "plan", None))

    def frontiers_of(self, robot: int) -> FloatArray:
        """The frontiers ``robot``'s policy found (its ``frontiers``, (F, 2)), or empty."""
        return _points(getattr(self.policies[robot], "frontiers", None))

    def done(self, robot: int) -> bool:
        """Whether ``robot``'s policy reports that nothing is left to explore (its
        ``done``; a policy without one never is)."""
        return bool(getattr(self.policies[robot], "done", False))

    def coordinated(self, robot: int) -> bool:
        """Whether ``robot`` explores the merged map in the common frame."""
        return self.roots[robot] == 0 and self.views[robot] is not None

    def explored_frame(self, robot: int) -> FloatArray | None:
        """``root_from_explored``: from the frame of the map ``robot`` explores (the
        common frame while coordinated, else its own) to its group root's frame; None
        when they are one frame."""
        if self.coordinated(robot) or self.roots[robot] == robot:
            return None
        return self.frames[robot]

    def pose_in_root(self, robot: int, pose: ArrayLike) -> FloatArray:
        """``robot``'s SLAM ``pose`` (own map frame) in its group root's frame."""
        pose = np.asarray(pose, dtype=np.float64)
        return pose if self.roots[robot] == robot else compose(self.frames[robot], pose)

    @property
    def merge_pending(self) -> bool:
        """Whether a merge is under way or may come soon without the maps growing: maps
        being merged, a hypothesis under verification, sightings being gathered into
        one, or a robot seeking contact (``mrslam run``'s ``until_merged`` waits on it)."""
        if self.state in (TeamState.HYPOTHESIS_GENERATION, TeamState.HYPOTHESIS_VERIFICATION):
            return True
        window = 2 * self.config.sighting_count
        recent = any(t and self.step - t[-1][0] < window for t in self._sightings.values())
        return recent or any(seeking is not None for seeking in self._seeking)

    def source_of(self, rendezvous: _Rendezvous) -> str:
        """Where the hypothesis of ``rendezvous`` came from (:class:`Acceptance`'s
        ``proposed_by``)."""
        if rendezvous.formed_at is not None:
            return "sighting"
        sources = self.hypothesis_sources
        return sources[rendezvous.index] if rendezvous.index < len(sources) else "virtual robot"

    def pop_decisions(self) -> list[Decision]:
        decisions, self._decisions = self._decisions, []
        return decisions

    def pop_merge_attempts(self) -> list[MergeAttempt]:
        """The merge attempts since the last call (empty unless ``config.keep_merges``)."""
        attempts, self._merge_attempts = self._merge_attempts, []
        return attempts

    def _decide(self, text: str) -> None:
        self._decisions.append(Decision(self.step, text))

    # --- the step -----------------------------------------------------------------------

    def act(self, observations: list[dict[str, Any]], maps: MapSource) -> list[NDArray[np.float32]]:
        """Actions for all robots (normalised ``(v, omega)``).

        Parameters
        ----------
        observations : list of dict
            The env observations of robot 0, 1, ... (``pose``, ``scan``, ``peer``,
            ``comm``).
        maps : callable
            ``maps(i)`` is robot i's current own map (called only when needed).
        """
        self.step += 1
        n = self.n_robots
        self._maps = maps
        self._poses = [np.asarray(o["pose"], dtype=np.float64) for o in observations]
        links = np.zeros((n, n), dtype=bool)
        for i in range(n):
            for j in range(i + 1, n):
                up = bool(observations[i]["comm"][_row(i, j)])
                up = up and bool(observations[j]["comm"][_row(j, i)])
                links[i, j] = links[j, i] = up
        self._links, self._reach = links, _reachable(links)
        if self.config.interaction and self.config.radio_margin is not None:
            for i in range(n):
                self._tracks[i].append(self._poses[i][:2].copy())
            self._link_track.append(links)
        self._observe_pair(observations)
        if self.config.interaction:
            self._seek_contact()
            if self.state in (
                TeamState.NO_INTERACTION,
                TeamState.COORDINATED_EXPLORATION,
            ) and not self._maybe_sighting(observations, maps):
                self._maybe_generate(observations, maps)
            elif self._waiting_on_sightings():
                self._generate_beside_sightings(maps)
            if self.state is TeamState.HYPOTHESIS_VERIFICATION:
                self._verify(self._last_observations, self._side_maps(maps), self._link)
            rendezvous = self.rendezvous
            if rendezvous is not None and not rendezvous.in_place:
                self.rendezvous_steps += sum(self._on_goal[r] for r in self.pair)
            if len(self.members) > 1:
                self._keep_merged_map(maps)
        if len(self.members) > 1 and self.merged_map is not None:
            return self._act_coordinated(observations, maps)
        return [self.act_alone(i, observations[i], maps(i)) for i in range(n)]

    def act_alone(
        self, robot: int, observation: dict[str, Any], own_map: GridMap
    ) -> NDArray[np.float32]:
        """``robot``'s action on its own map, in its own frame, knowing no teammate (the
        team's step outside the common frame; the one-robot baseline calls it directly)."""
        if self._on_goal[robot]:
            return self.explorers[robot].act(observation, own_map)
        pose = np.asarray(observation["pose"], dtype=np.float64)
        context = PolicyContext(
            robot=robot, step=self.step, map=own_map, pose=pose, own_map=own_map
        )
        return self.policies[robot].act(observation, context)

    # --- contact seeking -----------------------------------------------------------------

    def _seek_contact(self) -> None:
        """The contact-seeking rule (:attr:`TeamConfig.seek_contact_after`): a robot that
        lost its link to the robots outside its group goes back to where it was
        ``seek_contact_back`` steps before it lost it and waits there; any such link ends
        the seeking."""
        config = self.config
        after = config.seek_contact_after
        if not after:  # switched off
            return
        for i in range(self.n_robots):
            outside = [j for j in range(self.n_robots) if self.roots[j] != self.roots[i]]
            if any(self._links[i, j] for j in outside):
                if self._contact_step[i] != self.step - 1:
                    self._contact_track[i].clear()  # a new link: where it came up first
                self._contact_step[i] = self.step
                self._contact_track[i].append(self._poses[i][:2].copy())
                if self._seeking[i] is not None:
                    self._stop_seeking(i, f"link up again after {self.seeking_steps[i]} steps")
                continue
            seeking = self._seeking[i]
            if seeking is not None:
                self.seeking_steps[i] += 1
                started, arrived = seeking
                if arrived is None:
                    status = self.explorers[i].status
                    if status == "arrived":
                        self._seeking[i] = (started, self.step)
                    elif status == "goal_unreachable":
                        self._stop_seeking(i, "the place is out of reach on its map")
                    elif self.step - started >= after:
                        self._stop_seeking(i, f"not back at the place in {after} steps")
                # The partner, gone as long, may take up to ``after`` steps to come back.
                elif self.step >= max(arrived + config.seek_contact_wait, started + after):
                    self._stop_seeking(i, "no link at the place of the last one")
                continue
            last = self._contact_step[i]
            if not outside or last is None or self._on_goal[i]:
                continue
            if self.step - max(last, self._seek_from[i]) < after:
                continue
            place = self._contact_track[i][0]
            goal = transform_points(self.frames[i], place[None, :])[0]
            self.explorers[i].set_goal(goal if self.coordinated(i) else place)
            self._on_goal[i] = True
            self._seeking[i] = (self.step, None)
            back = len(self._contact_track[i]) - 1
            self._decide(
                f"robot_{i}: no link for {self.step - last} steps; back to where it was "
                f"{back} steps before losing it ({place[0]:.1f}, {place[1]:.1f} in its map) "
                "to seek contact"
            )

    def _stop_seeking(self, robot: int, why: str) -> None:
        self._seeking[robot] = None
        self._release(robot)
        self._seek_from[robot] = self.step  # the next search a full interval from now
        self._decide(f"robot_{robot}: contact seeking ends ({why})")

    # --- the pair being merged ------------------------------------------------------------

    def _pair_roots(self) -> tuple[int, int]:
        return self.roots[self.pair[0]], self.roots[self.pair[1]]

    def _set_pair(self, a: int, b: int) -> None:
        """Merge the groups of robots ``a`` and ``b`` next: side 0 is the lower root's."""
        self.pair = (a, b) if self.roots[a] < self.roots[b] else (b, a)

    def _observe_pair(self, observations: list[dict[str, Any]]) -> None:
        """The current pair as two robots: poses in their group roots' frames, each one's
        peer row and link of the other."""
        a, b = self.pair
        pair_view = []
        for me, other in ((a, b), (b, a)):
            observation = observations[me]
            row = _row(me, other)
            pose = self.pose_in_root(me, self._poses[me])
            pair_view.append(
                {
                    **observation,
                    "pose": pose,
                    "peer": np.asarray(observation["peer"])[row : row + 1],
                    "comm": np.asarray(observation["comm"])[row : row + 1],
                }
            )
        self._last_observations = pair_view
        self._last_poses = [o["pose"] for o in pair_view]
        self._link = bool(self._links[a, b])

    def _group_map(self, robot: int, maps: MapSource) -> GridMap:
        """The map of ``robot``'s group in its root's frame: the merged map it explores in
        the common frame; its own map when alone; else its group's maps fused."""
        view = self.views[robot]
        if self.roots[robot] == 0 and view is not None:
            return view
        root = self.roots[robot]
        group = [k for k in range(self.n_robots) if k != root and self.roots[k] == root]
        if not group:
            return maps(root)
        # A group's fusion is remade every ``merged_map_every`` steps, as the views are.
        made = self._group_maps.get(root)
        fresh = made is not None and self.step - made[1] < self.config.merged_map_every
        if made is not None and fresh and made[0] == tuple(group):
            return made[2]
        grid = fuse_all(maps(root), ((maps(k), self.frames[k]) for k in group))
        self._group_maps[root] = (tuple(group), self.step, grid)
        return grid

    def _side_maps(self, maps: MapSource) -> MapSource:
        """``sides(k)``: the map of the current pair's side k (its group's, in its root's
        frame)."""
        cache: dict[int, GridMap] = {}

        def sides(k: int) -> GridMap:
            if k not in cache:
                cache[k] = self._group_map(self.pair[k], maps)
            return cache[k]

        return sides

    def _send(self, side: int, goal: FloatArray) -> None:
        """Drive the pair's side-``side`` robot to ``goal`` (its group root's frame) with
        the team's explorer, in the frame of the map it explores."""
        robot = self.pair[side]
        if not self.coordinated(robot) and self.roots[robot] != robot:
            goal = transform_points(inverse(self.frames[robot]), goal[None, :2])[0]
        self.explorers[robot].set_goal(goal)
        self._on_goal[robot] = True

    def _release(self, robot: int) -> None:
        """End ``robot``'s leg to a given goal: its policy explores again."""
        self.explorers[robot].clear_goal()
        self._on_goal[robot] = False

    def _release_pair(self) -> None:
        for robot in self.pair:
            self._release(robot)

    def _change_frame(self, robot: int, new_from_old: FloatArray) -> None:
        """``robot`` now explores in another frame: its policy (when it can) and the
        team's explorer carry what they remember over."""
        change = getattr(self.policies[robot], "change_frame", None)
        if change is not None:
            change(new_from_old)
        if self.explorers[robot] is not self.policies[robot]:
            self.explorers[robot].change_frame(new_from_old)

    def _rest(self) -> None:
        """No merge under way: coordinated if robot 0 has a teammate in its frame."""
        self.hypotheses = []
        self.hypothesis_sources = []
        self.rendezvous = None
        coordinated = len(self.members) > 1
        self.state = TeamState.COORDINATED_EXPLORATION if coordinated else TeamState.NO_INTERACTION

    # --- 1 -> 2: hypothesis generation ------------------------------------------------------

    def _candidate_pairs(self) -> list[tuple[int, int]]:
        """Pairs of robots of two groups that can talk now, those that bring a robot into
        the common frame first."""
        n = self.n_robots
        pairs = [
            (a, b)
            for a in range(n)
            for b in range(a + 1, n)
            if self._links[a, b] and self.roots[a] != self.roots[b]
        ]
        return sorted(pairs, key=lambda p: (min(self.roots[p[0]], self.roots[p[1]]) != 0, p))

    def _maybe_generate(self, observations: list[dict[str, Any]], maps: MapSource) -> None:
        for a, b in self._candidate_pairs():
            self._set_pair(a, b)
            self._observe_pair(observations)
            if self._generate(self._side_maps(maps)):
                return

    def _generate(self, sides: MapSource) -> bool:
        """Merge the current pair's maps; False when they are not ripe for it."""
        m0, m1 = sides(0), sides(1)
        areas = [np.count_nonzero(~m.unknown) * m.resolution**2 for m in (m0, m1)]
        key = self._pair_roots()
        if min(areas) < self.config.min_map_area or sum(areas) < self._retry_area.get(key, 0.0):
            return False
        a, b = self.pair
        self.state = TeamState.HYPOTHESIS_GENERATION
        names = "" if self.n_robots == 2 else f" (robot_{a} and robot_{b})"
        self._decide(
            f"comm up: maps exchanged{names} ({areas[0]:.0f} m² and {areas[1]:.0f} m²), "
            "generating hypotheses by virtual robot motion"
        )
        self._retry_area[key] = sum(areas) * self.config.regrow_factor
        try:
            result = merge_maps(
                m0, m1, self.config.merge, rng=self.rng, trace=self.config.keep_merges
            )
        except MergeInputError as error:
            self._decide(f"no hypotheses: {error}")
            self._rest()
            return True
        self._merges_tried += 1
        if self.config.keep_merges:
            self._merge_attempts.append(
                MergeAttempt(
                    number=self._merges_tried,
                    step=self.step,
                    result=result,
                    map0=m0,
                    map1=m1,
                    robots=(a, b),
                )
            )
        pivot = m1.cell_to_world(np.argwhere(~m1.unknown).mean(axis=0)[None, :])[0]
        decided = result.transform
        fresh = distinct_hypotheses(
            [h.map1_from_map2 for h in result.hypotheses if h.confident],
            self.rejected,
            pivot,
            self.config.merge,
        )
        fresh = [h for h in fresh if not self._radio_rejects(h, "from the merge")]
        self.hypotheses = fresh[: self.config.max_rendezvous]
        sources = {
            id(h.map1_from_map2): getattr(h, "proposed_by", "virtual robot")
            for h in result.hypotheses
        }
        self.hypothesis_sources = [sources.get(id(h), "virtual robot") for h in self.hypotheses]
        self.hypotheses_attempt = self._merges_tried
        # Rivals: one meeting cannot tell which of two open answers is right, more map
        # may; the merge's own answer (if it gave one) is still driven to at once.
        rivals = len(fresh) > 1
        self._undecided = [
            h
            for h in self.hypotheses
            if rivals and (decided is None or not same_answer(h, decided, pivot, self.config.merge))
        ]
        if not self.hypotheses:
            self._decide("no hypothesis worth a rendezvous; exploring on, retry when maps grow")
            self._rest()
            return True
        self._decide(f"{len(self.hypotheses)} hypotheses to verify by rendezvous")
        self._start_rendezvous(0, sides)
        return True

    def _maybe_sighting(self, observations: list[dict[str, Any]], maps: MapSource) -> bool:
        """A hypothesis from a chance meeting (:attr:`TeamConfig.sighting_count`): two
        robots of different groups with the link up that see each other give the relative
        pose of their groups' frames directly, ``T = p0 · s · p1⁻¹``; averaged over
        ``sighting_count`` steps of sightings it is refined and checked on the maps
        (:meth:`_form_from_sightings`). True when one was put to verification."""
        count = self.config.sighting_count
        if not count:
            return False
        for a, b in self._candidate_pairs():
            self._set_pair(a, b)
            side0, side1 = self.pair
            poses = [self.pose_in_root(r, self._poses[r]) for r in self.pair]
            estimates = []
            for me, other in ((side0, side1), (side1, side0)):
                peer = np.asarray(observations[me]["peer"])[_row(me, other)]
                if peer[0] < 0.5:
                    continue
                seen = sighting_pose(peer[1], peer[2], peer[3])
                side1_in_side0 = seen if me == side0 else inverse(seen)
                estimates.append(compose(compose(poses[0], side1_in_side0), inverse(poses[1])))
            if not estimates:
                continue
            track = self._sightings.setdefault(self.pair, deque(maxlen=count))
            track.append((self.step, np.array(estimates)))
            if len(track) < count or self.step - track[0][0] >= 2 * count:
                continue
            hypothesis = mean_pose(np.concatenate([e for _, e in track]))
            track.clear()
            self._observe_pair(observations)
            if self._form_from_sightings(hypothesis, self._side_maps(maps), poses):
                return True
        return False

    def _form_from_sightings(
        self, hypothesis: FloatArray, sides: MapSource, poses: list[FloatArray]
    ) -> bool:
        """Refine the sightings' ``hypothesis`` on the pair's maps (kept only when the
        refined placement stays within the rendezvous tolerances and the maps do not
        conflict there), check the maps agree at it within the peer sensor's range of
        both robots (the merge's conflict check), and put it to verification: True;
        False when the maps conflict (rejected)."""
        m0, m1 = sides(0), sides(1)
        # Checked where the robots met: the sightings vouch for the maps there; far
        # from it, either map's SLAM drift may make even the true placement conflict.
        near0, near1 = (
            window(m, pose[:2], self.config.peer_range)
            for m, pose in zip((m0, m1), poses, strict=True)
        )
        names = [f"robot_{r}" for r in self.pair]
        x, y, theta = hypothesis
        self.hypotheses_tested += 1
        self.sighting_hypotheses += 1
        self._note_hypothesis()
        try:
            refined, _, _ = refine_transform(
                m0, m1, hypothesis, self.config.merge, rng=self._sighting_rng
            )
        except MergeInputError:
            refined = None
        if (
            refined is not None
            and self._within_verified(refined, hypothesis, poses[1][:2])
            and self._map_check(near0, near1, refined) is None
        ):
            transform, how, conflict = refined, "refined on the maps", None
        else:
            transform, how = hypothesis, "kept as seen"
            conflict = self._map_check(near0, near1, transform)
        seen = (
            f"{names[0]} and {names[1]} saw each other on {self.config.sighting_count} "
            f"steps: hypothesis x {x:.2f}, y {y:.2f}, theta {theta:.3f}"
        )
        if conflict is not None:
            self._decide(f"{seen}; rejected, the maps conflict there ({conflict})")
            return False
        why = self._radio_refutes(transform)
        if why is not None:
            self._decide(f"{seen}; rejected by {why}")
            return False
        self.hypotheses = [transform]
        self.hypothesis_sources, self.hypotheses_attempt = ["sighting"], None
        self.rendezvous = _Rendezvous(
            hypothesis=transform,
            index=0,
            meeting_point=poses[0][:2].copy(),
            started=self.step,
            last_match=self.step,
            in_place=True,
            waits=True,
            formed_at=[pose[:2].copy() for pose in poses],
        )
        self.state = TeamState.HYPOTHESIS_VERIFICATION
        self._decide(
            f"{seen} ({how}); to verify by sightings after both moved "
            f"{self.config.sighting_verify_distance:.1f} m"
        )
        return True

    def _waiting_on_sightings(self) -> bool:
        """Whether a hypothesis (from sightings, or undecided by the merge) waits,
        unmatched, for a chance meeting (nobody is driven for it yet)."""
        rendezvous = self.rendezvous
        return (
            self.state is TeamState.HYPOTHESIS_VERIFICATION
            and rendezvous is not None
            and rendezvous.waits
            and rendezvous.in_place
            and rendezvous.first_match is None
        )

    def _generate_beside_sightings(self, maps: MapSource) -> None:
        """While a hypothesis waits for a chance meeting, the pair's maps are still
        merged as they grow: the new merge's hypotheses take its place (it is set aside),
        unless the merge gave nothing to drive for, or its first hypothesis waits too and
        the waiting one is from sightings or is the same answer (within the rendezvous
        tolerances where robot 1 is): then it waits on, its wait counted from its start."""
        waiting, hypotheses = self.rendezvous, self.hypotheses
        sources, attempt = self.hypothesis_sources, self.hypotheses_attempt
        undecided, tested = self._undecided, self.hypotheses_tested
        assert waiting is not None
        if not self._link or not self._generate(self._side_maps(maps)):
            return
        kind = "from sightings" if waiting.formed_at is not None else f"#{waiting.index}"
        new = self.rendezvous
        keep = new is None or (
            new.waits
            and new.first_match is None
            and (
                waiting.formed_at is not None
                or self._within_verified(
                    new.hypothesis, waiting.hypothesis, self._last_poses[1][:2]
                )
            )
        )
        if keep:
            # The new merge's hypotheses are dropped: its rivals and its count with them.
            self.rendezvous, self.hypotheses = waiting, hypotheses
            self.hypothesis_sources, self.hypotheses_attempt = sources, attempt
            self._undecided, self.hypotheses_tested = undecided, tested
            self.state = TeamState.HYPOTHESIS_VERIFICATION
            self._decide(f"the hypothesis {kind} waits on for a later meeting")
        else:
            self._decide(f"the hypothesis {kind} is set aside for the merge's")

    def _radio_excess(self, hypothesis: FloatArray, since: int = 0) -> float:
        """:func:`radio_contradiction` of ``hypothesis`` (the current pair's) on the pair's
        tracks, each position in its group root's frame, from step ``since`` (an index into
        the tracks) to the last step the pair's link was up: a robot's positions reach its
        partner only over the link, so the steps it was down are judged when it is back.
        Each step is allowed the heading tolerance's reach at the partner
        (:func:`heading_allowance`) where it exceeds ``radio_margin``
        (:attr:`TeamConfig.radio_heading_tolerance`)."""
        a, b = self.pair
        end = len(self._link_track)
        while end > since and not self._link_track[end - 1][a, b]:
            end -= 1
        tracks = []
        for robot in (a, b):
            track = np.asarray(self._tracks[robot][:end], dtype=np.float64).reshape(-1, 2)
            if self.roots[robot] != robot:
                track = transform_points(self.frames[robot], track)
            tracks.append(track)
        link = np.array([links[a, b] for links in self._link_track[since:end]], dtype=bool)
        judged = tracks[1][since:end]
        reach = heading_allowance(judged, tracks[1], self.config.radio_heading_tolerance)
        return radio_contradiction(
            hypothesis,
            tracks[0][since:end],
            judged,
            link,
            comm_range=self.config.comm_range,
            exact=self.config.comm_exact,
            allowance=np.maximum(reach - (self.config.radio_margin or 0.0), 0.0),
        )

    def _radio_refutes(self, hypothesis: FloatArray, *, since: int = 0) -> str | None:
        """Why the radio rejects ``hypothesis`` (:attr:`TeamConfig.radio_margin`), judged
        on the steps from ``since`` (:meth:`_radio_excess`); None when it does not."""
        margin = self.config.radio_margin
        if margin is None:
            return None
        excess = self._radio_excess(hypothesis, since)
        if excess <= margin:
            return None
        self.radio_rejections += 1
        return (
            f"the radio: it puts the robots {excess:.1f} m beyond what the link said, past "
            f"the heading tolerance's reach (> the {margin} m margin)"
        )

    def _radio_rejects(self, hypothesis: FloatArray, kind: str, *, since: int = 0) -> bool:
        """Whether the radio rejects ``hypothesis`` (:meth:`_radio_refutes`); a rejected
        one is logged and kept among the pair's rejected hypotheses."""
        why = self._radio_refutes(hypothesis, since=since)
        if why is None:
            return False
        self.rejected.append(hypothesis)
        x, y, theta = hypothesis
        self._decide(
            f"hypothesis (x {x:.2f}, y {y:.2f}, theta {theta:.3f}) {kind} rejected by {why}"
        )
        return True

    def _map_check(self, m0: GridMap, m1: GridMap, transform: FloatArray) -> str | None:
        """Why the maps conflict at ``transform`` (the merge's conflict check, at its
        working resolution), or None."""
        config = self.config.merge
        resolution = max(m0.resolution, m1.resolution, config.working_resolution)
        w0, w1 = at_resolution(m0, resolution), at_resolution(m1, resolution)
        agreement = acceptance_index(w0, w1, transform)
        return check_conflict_fraction(agreement, resolution, config)

    def _moved_off(self, rendezvous: _Rendezvous, poses: list[FloatArray]) -> bool:
        """Whether sightings now test ``rendezvous``: always for a hypothesis from the
        merge; for one from sightings, once both robots moved
        ``sighting_verify_distance`` from where it formed."""
        formed_at = rendezvous.formed_at
        if formed_at is None:
            return True
        distance = self.config.sighting_verify_distance
        return all(
            float(np.hypot(*(pose[:2] - at))) >= distance
            for pose, at in zip(poses, formed_at, strict=True)
        )

    # --- 3: hypothesis verification -----------------------------------------------------------

    def _start_rendezvous(self, index: int, maps: MapSource) -> None:
        """Put hypothesis ``index`` (or the next one worth it) to a rendezvous; ``maps``
        gives the pair's side maps."""
        names = [f"robot_{r}" for r in self.pair]
        while index < len(self.hypotheses):
            hypothesis = self.hypotheses[index]
            if any(hypothesis is rejected for rejected in self.rejected):
                index += 1  # rejected on the way to an earlier one's meeting point
                continue
            verdict = self._verify_in_place(hypothesis, maps(0))
            if verdict is not None:
                self.hypotheses_tested += 1
                self._note_hypothesis()
                rendezvous = _Rendezvous(
                    hypothesis=hypothesis,
                    index=index,
                    meeting_point=self._last_poses[0][:2].copy(),
                    started=self.step,
                    last_match=self.step,
                )
                if verdict:
                    # Seen where predicted: confirm while both keep exploring (they move);
                    # should they lose sight of each other, they drive to meet (_verify).
                    rendezvous.in_place = True
                    self.rendezvous = rendezvous
                    self.state = TeamState.HYPOTHESIS_VERIFICATION
                    self._decide(
                        f"hypothesis #{index}: {names[0]} sees {names[1]} where predicted "
                        "from here; confirming while they move"
                    )
                    return
                self._decide(
                    f"hypothesis #{index} rejected where the robots stand: it puts "
                    f"{names[1]} in plain sight of {names[0]}, and {names[0]} does not see it"
                )
                self.rejected.append(hypothesis)
                index += 1
                continue
            if self.config.undecided_wait != 0 and not self._is_decided(hypothesis):
                self.hypotheses_tested += 1
                self._note_hypothesis()
                self.rendezvous = _Rendezvous(
                    hypothesis=hypothesis,
                    index=index,
                    meeting_point=self._last_poses[0][:2].copy(),
                    started=self.step,
                    last_match=self.step,
                    in_place=True,
                    waits=True,
                )
                self.state = TeamState.HYPOTHESIS_VERIFICATION
                wait = self.config.undecided_wait
                until = "they have nothing left to explore" if wait is None else f"{wait} steps"
                self._decide(
                    f"hypothesis #{index}: a rival is open beside it (the merge's answer is "
                    f"not this one); tested where the robots explore, until {until}, "
                    "before a rendezvous"
                )
                return
            meeting = self._meeting_point(hypothesis, maps)
            if meeting is not None and meeting[1] > self.config.max_meeting_cost:
                self._decide(
                    f"hypothesis #{index}: the meeting point is {meeting[1]:.0f} m away; "
                    "skipped for now"
                )
            elif meeting is not None:
                point0, cost = meeting
                self.rendezvous = _Rendezvous(
                    hypothesis=hypothesis,
                    index=index,
                    meeting_point=point0,
                    started=self.step,
                )
                self._send_to_meet(self.rendezvous)
                self.state = TeamState.HYPOTHESIS_VERIFICATION
                self.hypotheses_tested += 1
                self._note_hypothesis()
                x, y, theta = hypothesis
                self._decide(
                    f"rendezvous for hypothesis #{index} (x {x:.2f}, y {y:.2f}, "
                    f"theta {theta:.3f}): meet at ({point0[0]:.2f}, {point0[1]:.2f}) in "
                    f"robot_{self.roots[self.pair[0]]}'s map, later arrival after ~{cost:.1f} m"
                )
                return
            else:
                self._decide(f"hypothesis #{index}: no meeting point reachable by both; skipped")
            index += 1
        self._give_up()

    def _is_decided(self, hypothesis: FloatArray) -> bool:
        """Whether ``hypothesis`` is not one the last merge left waiting (a confident
        answer other than its own ``merged`` one, beside an open rival)."""
        return not any(hypothesis is undecided for undecided in self._undecided)

    def _note_hypothesis(self) -> None:
        if self.first_hypothesis_step is None:
            self.first_hypothesis_step = self.step

    def _verify_in_place(self, hypothesis: FloatArray, map0: GridMap) -> bool | None:
        """A rendezvous of length zero: if the hypothesis puts side 1's robot well within
        the peer sensor's range of side 0's, across space side 0's map knows to be free,
        the sensor settles it where they stand (True: seen where predicted; False: not
        seen). None when the robots have to meet first."""
        if not (self._link and self._last_observations):
            return None  # the other robot's pose is only known over the link
        predicted = predicted_relative_pose(self._last_poses[0], self._last_poses[1], hypothesis)
        distance = float(np.hypot(predicted[0], predicted[1]))
        if not 0.5 < distance < self.config.in_sight_range:
            return None
        peer = self._last_observations[0]["peer"][0]
        if peer[0] > 0.5:
            seen = sighting_pose(peer[1], peer[2], peer[3])
            return judge_sighting(seen, predicted, self.config.rendezvous).matches
        # Not seen: only a rejection if the line of sight is known free in side 0's map.
        sight_range = self.config.in_sight_range
        seen_free = in_plain_sight(self._last_poses[0], predicted, map0, sight_range=sight_range)
        return False if seen_free else None

    def _meeting_point(
        self, hypothesis: FloatArray, maps: MapSource, *, avoid: FloatArray | None = None
    ) -> tuple[FloatArray, float] | None:
        """The meeting point (side 0's group frame) and the later arrival's cost, each
        robot's travel planned on the map it drives on (:meth:`_driven_map`): a robot
        outside the common frame drives on its own map, which may not know the places
        its group's map (the merge's) does. ``avoid``: points (K, 2, side 0's frame) the
        meeting point keeps ``sighting_verify_distance + sight_margin`` (m) from."""
        m0 = maps(0)
        planner = self.config.explorer.planner
        costs = []
        for side in (0, 1):
            grid, root_from_grid, pose = self._driven_map(side, maps)
            try:
                cost = distance_field(inflate(grid, planner), pose).cost
            except ValueError:
                return None
            side0_from_grid = root_from_grid if side == 0 else compose(hypothesis, root_from_grid)
            if side == 0 and grid is m0:
                costs.append(cost)
            else:
                costs.append(field_on_lattice(cost, grid, m0, side0_from_grid))
        if avoid is not None:
            rows, cols = m0.cells.shape
            centres = m0.cell_to_world(np.indices((rows, cols)).reshape(2, -1).T)
            near = np.zeros(rows * cols, dtype=bool)
            # The robots stop short of the point: a margin, so that both are far enough.
            radius = self.config.sighting_verify_distance + self.config.sight_margin
            for point in avoid:
                near |= np.hypot(*(centres - point).T) < radius
            costs[0] = np.where(near.reshape(rows, cols), np.inf, costs[0])
        chosen = choose_meeting_point(costs[0], costs[1], m0)
        if chosen is not None:
            cell = tuple(m0.world_to_cell(chosen[0][None, :])[0])
            self._meeting_costs = (float(costs[0][cell]), float(costs[1][cell]))
        return chosen

    def _driven_map(self, side: int, maps: MapSource) -> tuple[GridMap, FloatArray, FloatArray]:
        """The map the pair's side-``side`` robot drives on to a given goal, its place in
        the robot's group root's frame (``root_from_map``) and the robot's pose in it."""
        robot = self.pair[side]
        view = self.views[robot]
        if self.coordinated(robot) and view is not None:  # the merged map, common frame
            return view, np.zeros(3), self._last_poses[side]
        alone = all(self.roots[k] != self.roots[robot] for k in range(self.n_robots) if k != robot)
        if alone:  # its group's map is its own
            return maps(side), np.zeros(3), self._last_poses[side]
        # Outside the common frame a robot explores its own map, even in a group.
        frame = self.frames[robot] if self.roots[robot] != robot else np.zeros(3)
        return self._maps(robot), frame, self._poses[robot]

    def _verify(self, observations: list[dict[str, Any]], maps: MapSource, link: bool) -> None:
        """One step of the rendezvous; ``observations`` and ``maps`` are the pair's (side
        0, side 1: poses in the group roots' frames, the partner's peer row)."""
        rendezvous = self.rendezvous
        assert rendezvous is not None
        config = self.config.rendezvous
        robots = self.pair
        hold = rendezvous.hold
        if hold is not None and self.step >= hold[1] and not rendezvous.in_place:
            rendezvous.hold = None
            self._send(hold[0], self._meeting_goal(rendezvous, hold[0]))
        # The radio on the steps since the last check, once the link is up (the partner's
        # positions come over it): for the hypothesis under test (a drive ends as soon as
        # the link says the robots are not where it puts them) and those waiting their turn.
        if link:
            since, self._radio_since = self._radio_since, len(self._link_track)
            for hypothesis in self.hypotheses[rendezvous.index + 1 :]:
                if not any(hypothesis is rejected for rejected in self.rejected):
                    self._radio_rejects(hypothesis, "waiting its turn", since=since)
            why = self._radio_refutes(rendezvous.hypothesis, since=since)
            if why is not None:
                self._reject(rendezvous, maps, why)
                return
        poses = [np.asarray(o["pose"], dtype=np.float64) for o in observations]
        if link and self._moved_off(rendezvous, poses):
            if rendezvous.previous is not None:
                rendezvous.motion += sum(
                    float(np.hypot(*(pose[:2] - before[:2])))
                    for pose, before in zip(poses, rendezvous.previous, strict=True)
                )
                rendezvous.previous = poses
            predicted = predicted_relative_pose(poses[0], poses[1], rendezvous.hypothesis)
            for observer, expected in ((0, predicted), (1, inverse(predicted))):
                peer = observations[observer]["peer"][0]
                if peer[0] < 0.5:
                    continue
                seen = sighting_pose(peer[1], peer[2], peer[3])
                sighting = judge_sighting(seen, expected, config)
                who = f"robot_{robots[observer]} sees robot_{robots[1 - observer]}"
                if not sighting.matches:
                    self._reject(
                        rendezvous,
                        maps,
                        f"{who} {sighting.position_error:.2f} m / "
                        f"{math.degrees(sighting.heading_error):.0f}° from the prediction",
                    )
                    return
                if rendezvous.first_match is None:
                    rendezvous.first_match = self.step
                    rendezvous.previous = poses
                rendezvous.matches += 1
                rendezvous.last_match = self.step
                if (
                    rendezvous.matches >= config.confirm_sightings
                    and rendezvous.motion >= config.confirm_motion
                ):
                    self._accept(
                        rendezvous,
                        maps,
                        f"{who} where predicted in {rendezvous.matches} sightings while the "
                        f"robots moved {rendezvous.motion:.1f} m",
                        sighting.position_error,
                    )
                    return
                break
            else:
                # Nobody seen: does the hypothesis put the other robot in plain sight?
                sight_range = self.config.in_sight_range
                if rendezvous.first_match is None and _either_in_sight(
                    poses, predicted, maps, sight_range
                ):
                    rendezvous.unseen += 1
                    if rendezvous.unseen >= UNSEEN_STEPS:
                        self._reject(
                            rendezvous,
                            maps,
                            f"it kept the robots in plain sight of each other for "
                            f"{rendezvous.unseen} steps, and neither saw the other",
                        )
                        return
                else:
                    rendezvous.unseen = 0
                self._test_waiting(rendezvous, poses, maps)
        # A waiting hypothesis (from sightings, or a rival the merge left open), still
        # unmatched, waits longer for a later meeting by chance.
        waiting = rendezvous.waits and rendezvous.first_match is None
        lost_after: float = UNSEEN_STEPS
        if waiting and rendezvous.formed_at is not None:
            lost_after = self.config.sighting_wait
        elif waiting:
            wait = self.config.undecided_wait
            lost_after = math.inf if wait is None else wait
        # Robots with nothing left to explore would wait for a chance meeting in vain.
        idle = waiting and all(self.done(r) for r in robots)
        if (
            rendezvous.in_place
            and rendezvous.last_match is not None
            and (self.step - rendezvous.last_match >= lost_after or idle)
            and self._drive_to_meet(rendezvous, maps)
        ):
            return
        if rendezvous.first_match is not None:
            if self.step - rendezvous.first_match >= config.confirm_steps:
                self._set_aside(rendezvous, maps, "seen where predicted, but not confirmed")
                return
            # Seen where predicted: if both robots stand still at the meeting point,
            # side 1's robot drives on so that the sightings test the hypothesis on a motion.
            if self.explorers[robots[1]].status == "arrived":
                self._release(robots[1])
            return
        if rendezvous.in_place:
            if self.step - rendezvous.started >= config.wait_steps + (lost_after - UNSEEN_STEPS):
                why = "no meeting point" if waiting else "lost sight of each other"
                self._set_aside(rendezvous, maps, why)
            return
        stuck = [r for r in robots if self.explorers[r].status == "goal_unreachable"]
        if stuck:
            # Not a test of the hypothesis: the robot cannot get there on its map.
            self._set_aside(
                rendezvous, maps, f"robot_{stuck[0]} cannot reach the meeting point on its map"
            )
            return
        arrived = all(self.explorers[r].status == "arrived" for r in robots)
        if arrived and rendezvous.arrived_at is None:
            rendezvous.arrived_at = self.step
            self._decide("both robots at the rendezvous; waiting for a sighting")
        if (
            rendezvous.arrived_at is not None
            and self.step - rendezvous.arrived_at >= config.wait_steps
        ):
            self._reject(rendezvous, maps, "arrived and waited: the other robot was not there")
        elif self.step - rendezvous.started >= config.timeout_steps:
            self._reject(rendezvous, maps, "rendezvous timed out")

    def _send_to_meet(self, rendezvous: _Rendezvous) -> None:
        """Both sides of the pair to the meeting point (side 0's frame; side 1 to where
        the hypothesis puts it in its own frame); the side with the shorter way only
        after it explored on for :attr:`TeamConfig.departure_share` of the difference."""
        if self.first_rendezvous_step is None:
            self.first_rendezvous_step = self.step
        rendezvous.hold = None
        costs, share = self._meeting_costs, self.config.departure_share
        self._meeting_costs = None  # used once: for the point just chosen
        if costs is not None and share > 0:
            follower = self.config.explorer.follower
            early = int(np.argmin(costs))
            steps = int(share * abs(costs[0] - costs[1]) / (follower.cruise_speed * follower.dt))
            if steps > 0:
                rendezvous.hold = (early, self.step + steps)
        for side in (0, 1):
            if rendezvous.hold is None or rendezvous.hold[0] != side:
                self._send(side, self._meeting_goal(rendezvous, side))

    def _meeting_goal(self, rendezvous: _Rendezvous, side: int) -> FloatArray:
        """The meeting point in side ``side``'s group frame."""
        point0 = rendezvous.meeting_point
        if side == 0:
            return point0
        return transform_points(inverse(rendezvous.hypothesis), point0[None, :])[0]

    def _drive_to_meet(self, rendezvous: _Rendezvous, maps: MapSource) -> bool:
        """A hypothesis matched where the robots stood, then they lost sight of each
        other before it was confirmed (exploring on, they part), or a hypothesis from
        sightings that no later meeting tested within ``sighting_wait``: both drive to its
        meeting point, and the confirmation goes on there as at any rendezvous. False
        (nothing changed) when no meeting point is within ``max_meeting_cost``."""
        assert rendezvous.last_match is not None
        unseen = self.step - rendezvous.last_match
        hypothesis = rendezvous.hypothesis
        avoid = None
        if rendezvous.formed_at is not None:  # meet where the sightings test the maps
            at0, at1 = rendezvous.formed_at
            avoid = np.array([at0, transform_points(hypothesis, at1[None, :])[0]])
        meeting = self._meeting_point(hypothesis, maps, avoid=avoid)
        if meeting is None or meeting[1] > self.config.max_meeting_cost:
            return False
        point0, cost = meeting
        rendezvous.in_place = False
        rendezvous.meeting_point = point0
        rendezvous.started = self.step
        self._send_to_meet(rendezvous)
        if rendezvous.first_match is not None:
            rendezvous.first_match = self.step  # a full window to confirm at the meeting
        self._decide(
            f"hypothesis #{rendezvous.index}: no sighting for {unseen} steps before "
            f"it was confirmed; both drive to meet at ({point0[0]:.2f}, {point0[1]:.2f}), "
            f"later arrival after ~{cost:.1f} m"
        )
        return True

    def _test_waiting(
        self, rendezvous: _Rendezvous, poses: list[FloatArray], maps: MapSource
    ) -> None:
        """With nobody seen: reject each hypothesis waiting its turn that has kept the
        robots in plain sight (:func:`in_plain_sight`) for :data:`UNSEEN_STEPS` steps."""
        for index in range(rendezvous.index + 1, len(self.hypotheses)):
            hypothesis = self.hypotheses[index]
            if any(hypothesis is rejected for rejected in self.rejected):
                continue
            predicted = predicted_relative_pose(poses[0], poses[1], hypothesis)
            if not _either_in_sight(poses, predicted, maps, self.config.in_sight_range):
                rendezvous.others_unseen[index] = 0
                continue
            unseen = rendezvous.others_unseen.get(index, 0) + 1
            rendezvous.others_unseen[index] = unseen
            if unseen >= UNSEEN_STEPS:
                self.hypotheses_tested += 1
                self.rejected.append(hypothesis)
                self._decide(
                    f"hypothesis #{index} rejected on the way to #{rendezvous.index}'s "
                    f"meeting point: it kept the robots in plain sight of each other for "
                    f"{unseen} steps, and neither saw the other"
                )

    def _within_verified(
        self, transform: FloatArray, verified: FloatArray, point: FloatArray
    ) -> bool:
        """Whether ``transform`` stays within the rendezvous tolerances of the
        ``verified`` hypothesis at ``point`` (where the robots met, in the frame
        ``transform`` maps from): the sighting verified no more than that, and a
        refinement that wanders further (in a building with repeated parts the maps can
        fit another placement better) is not trusted."""
        config = self.config.rendezvous
        at = np.asarray(point, dtype=np.float64).reshape(1, 2)
        moved = float(
            np.hypot(*(transform_points(transform, at) - transform_points(verified, at))[0])
        )
        turned = abs(math.remainder(float(transform[2] - verified[2]), 2 * math.pi))
        return moved <= config.position_tolerance and turned <= config.heading_tolerance

    def _set_aside(self, rendezvous: _Rendezvous, maps: MapSource, why: str) -> None:
        """Neither accepted nor rejected: the hypothesis may be proposed again later."""
        self._decide(f"hypothesis #{rendezvous.index} set aside: {why}")
        self.rendezvous = None
        self._release_pair()
        self._start_rendezvous(rendezvous.index + 1, maps)

    def _accept(self, rendezvous: _Rendezvous, maps: MapSource, how: str, error: float) -> None:
        radio = ""
        if self.config.radio_margin is not None:
            radio = f"; radio {self._radio_excess(rendezvous.hypothesis):+.2f} m"
        self._decide(
            f"hypothesis #{rendezvous.index} accepted: {how} (last sighting {error:.2f} m "
            f"off{radio})"
        )
        m0, m1 = maps(0), maps(1)
        verified_at = self._last_poses[1][:2].copy()
        transform, psi, agreement = refine_transform(
            m0, m1, rendezvous.hypothesis, self.config.merge, rng=self.rng
        )
        if not self._within_verified(transform, rendezvous.hypothesis, verified_at):
            self._decide("the refinement left what the sighting verified; kept the hypothesis")
            transform = rendezvous.hypothesis.copy()
        self._decide(
            f"refined by random walk: psi {psi:.3f}, acceptance index {agreement.index:.3f}; "
            "coordinated exploration on the merged map"
        )
        self.acceptances.append(
            Acceptance(
                step=self.step,
                index=rendezvous.index,
                count=len(self.hypotheses),
                proposed_by=self.source_of(rendezvous),
                attempt=None if rendezvous.formed_at is not None else self.hypotheses_attempt,
                how=how,
                verified=rendezvous.hypothesis.copy(),
                refined=np.array(transform, dtype=np.float64),
            )
        )
        self.rendezvous = None
        self._release_pair()
        root0, root1 = self._pair_roots()
        joined = alignment_edge(root0, root1, m0, m1, transform)
        if joined is not None:
            self._join_edges.append(joined)
        self._join(transform, rendezvous.hypothesis, verified_at)
        self._last_refine_step = self.step
        self._rest()
        if len(self.members) > 1:
            # Only a join into the common frame makes merged views; a view made for
            # robot 0 alone would be a frozen copy of its map, which its later merges with
            # other groups would then use instead of its current map.
            self._exchange_and_fuse(everyone=False)

    def _join(self, transform: FloatArray, verified: FloatArray, at: FloatArray) -> None:
        """The pair's groups become one: side 1's group, placed by ``transform`` (refined;
        ``verified`` before refinement; ``at``: where side 1's robot was, in its root's
        frame), joins side 0's; robots new in the common frame explore the merged map."""
        root0, root1 = self._pair_roots()
        before = [frame.copy() for frame in self.frames]
        joining = [k for k in range(self.n_robots) if self.roots[k] == root1]
        for k in joining:
            old = self.frames[k]
            self.frames[k] = compose(transform, old) if k != root1 else transform.copy()
            self.verified[k] = compose(verified, old) if k != root1 else verified.copy()
            self._verified_at[k] = transform_points(inverse(old), at[None, :])[0]
            self.roots[k] = root0
        self._refine_group(root0)
        self._group_maps.pop(root0, None)
        self._group_maps.pop(root1, None)
        for k in range(self.n_robots):
            if self.roots[k] != 0:
                continue
            if k in joining:
                self.step_joined[k] = self.step
                # Robot k now explores the merged map, in robot 0's frame.
                self._change_frame(k, self.frames[k])
            elif k != 0 and not np.array_equal(self.frames[k], before[k]):
                self._change_frame(k, compose(self.frames[k], inverse(before[k])))

    def _refine_group(self, root: int) -> None:
        """With three robots or more in ``root``'s group: every member's transform refined
        jointly (:func:`~mrslam_env.merge.graph.refine_jointly` on the members' own maps,
        the root fixed) instead of chained. Kept only when every member stays within the
        rendezvous tolerances of what was verified for it (:meth:`_within_verified`)."""
        group = [k for k in range(self.n_robots) if self.roots[k] == root]
        if len(group) < 3 or self.config.joint is None:
            return
        own = [self._maps(k) for k in group]
        estimate = [self.frames[k] for k in group]
        node = {k: n for n, k in enumerate(group)}
        known = [
            replace(e, i=node[e.i], j=node[e.j])
            for e in self._join_edges
            if e.i in node and e.j in node
        ]
        result = refine_jointly(
            own,
            estimate,
            self.config.joint,
            rng=self.rng,
            fixed=group.index(root),
            known_edges=known,
        )
        pairs = result.edges[: len(result.edges) - len(known)]
        names = ", ".join(f"robot_{group[e.i]}-robot_{group[e.j]}" for e in pairs)
        for k, solved in zip(group, result.transforms, strict=True):
            verified = self.verified[k]
            if (
                k != root
                and verified is not None
                and not self._within_verified(solved, verified, self._verified_at[k])
            ):
                self._decide(
                    f"joint refinement ({names}) left what was verified for robot_{k}; "
                    "kept the chained transforms"
                )
                return
        moved = max(
            float(np.hypot(*(solved[:2] - self.frames[k][:2])))
            for k, solved in zip(group, result.transforms, strict=True)
        )
        for k, solved in zip(group, result.transforms, strict=True):
            if k != root:
                self.frames[k] = solved
        self._decide(
            f"transforms of robot_{root}'s group of {len(group)} refined jointly on "
            f"{len(pairs)} overlapping pairs ({names}) and {len(known)} joins; "
            f"moved up to {moved:.2f} m"
        )

    def start_coordinated(self, transform: ArrayLike, maps: MapSource) -> None:
        """Skip merging and verification: coordinate from now on with known transforms
        (the benchmark's oracle, given the true relative poses): ``map0_from_map1`` (3,),
        or with more robots (N-1, 3), ``map0_from_map_i`` for i = 1 ... N-1.

        What follows is the coordination that follows a verified merge; the robots'
        current maps count as exchanged (at the start, one scan each).
        """
        transforms = np.asarray(transform, dtype=np.float64).reshape(-1, 3)
        if len(transforms) != self.n_robots - 1:
            raise ValueError(
                f"start_coordinated needs {self.n_robots - 1} transforms, got {len(transforms)}"
            )
        self._maps = maps
        self._decide("relative pose given (oracle): coordinated exploration on the merged map")
        for robot in range(self.n_robots):
            self._release(robot)
        for k in range(1, self.n_robots):
            self.frames[k] = transforms[k - 1].copy()
            self.verified[k] = transforms[k - 1].copy()
            self.roots[k] = 0
            self.step_joined[k] = self.step
            self._verified_at[k] = self._poses[k][:2].copy()
            self._change_frame(k, self.frames[k])
        self._given = True
        self._rest()
        self._exchange_and_fuse(everyone=True)

    def _reject(self, rendezvous: _Rendezvous, maps: MapSource, why: str) -> None:
        self._decide(f"hypothesis #{rendezvous.index} rejected: {why}")
        if rendezvous.formed_at is None:
            # One from sightings says nothing about the maps' other placements: it is
            # not kept among the rejected, which would hide a merge's answer close to it.
            self.rejected.append(rendezvous.hypothesis)
        self.rendezvous = None
        self._release_pair()
        self._start_rendezvous(rendezvous.index + 1, maps)

    def _give_up(self) -> None:
        self._decide("all hypotheses rejected: independent exploration until the maps grow")
        self._rest()

    # --- 4: coordinated exploration -------------------------------------------------------

    def _exchange_and_fuse(self, *, everyone: bool) -> None:
        """At a join: the robots of the common frame that can talk (``everyone``: all of
        them) hold each other's current maps, and their merged views are made now."""
        maps = self._maps
        members = self.members
        for i in members:
            for j in members:
                if i != j and (everyone or self._reach[i, j] or {i, j} == set(self.pair)):
                    self._received[(i, j)] = maps(j)
        shared = everyone or bool(self._reach[np.ix_(members, members)].all())
        self._fuse(maps, shared=shared)

    def _keep_merged_map(self, maps: MapSource) -> None:
        """Every ``merged_map_every`` steps: the maps exchanged between the robots of the
        common frame that can talk (directly or through teammates), the views refused."""
        if self.step - self._last_merge_step < self.config.merged_map_every:
            return
        members = self.members
        for i in members:
            for j in members:
                if i != j and self._reach[i, j]:
                    self._received[(i, j)] = maps(j)
        if (
            self.config.refine_every
            and not self._given
            and self.state is TeamState.COORDINATED_EXPLORATION
            and self.step - self._last_refine_step >= self.config.refine_every
            and self._refine_again(maps)
        ):
            self._last_refine_step = self.step
        self._fuse(maps, shared=bool(self._reach[np.ix_(members, members)].all()))

    def _refine_again(self, maps: MapSource) -> bool:
        """The common frame's transforms refined again on the grown maps
        (``TeamConfig.refine_every``), each kept only within the rendezvous tolerances
        of what was verified for it: a group of three or more jointly
        (:meth:`_refine_group`, once every member can reach every other), else each
        member robot 0 can reach against robot 0's map. False when nothing could be
        refined for want of the link: the caller tries again at its next tick instead of
        a whole period later."""
        members = self.members
        if len(members) >= 3 and self.config.joint is not None:
            if not self._reach[np.ix_(members, members)].all():
                return False
            before = {k: self.frames[k] for k in members[1:]}
            self._refine_group(0)
            for k, old in before.items():
                if self.frames[k] is not old:
                    self._change_frame(k, compose(self.frames[k], inverse(old)))
            return True
        refined_any = False
        for k in members[1:]:
            verified = self.verified[k]
            if not self._reach[0, k] or verified is None:
                continue
            refined_any = True
            refined, psi, agreement = refine_transform(
                maps(0), maps(k), self.frames[k], self.config.merge, rng=self.rng
            )
            if not self._within_verified(refined, verified, self._verified_at[k]):
                self._decide(
                    f"re-refinement of robot_{k}'s transform left what the sighting "
                    "verified; kept the transform"
                )
                continue
            at = self._verified_at[k][None, :]
            shift = transform_points(refined, at) - transform_points(self.frames[k], at)
            turn = math.remainder(float(refined[2] - self.frames[k][2]), 2 * math.pi)
            self._decide(
                f"robot_{k}'s transform re-refined on the grown maps: psi {psi:.3f}, "
                f"acceptance index {agreement.index:.3f}; the meeting place moved "
                f"{float(np.hypot(*shift[0])):.3f} m, turned {math.degrees(turn):+.2f}°"
            )
            self._change_frame(k, compose(refined, inverse(self.frames[k])))
            self.frames[k] = refined
        return refined_any

    def _fuse(self, maps: MapSource, *, shared: bool) -> None:
        """Refresh the views of the robots of the common frame: each robot's own map,
        current, fused with the others' as it holds them, in robot 0's frame. ``shared``:
        all of them hold each other's current maps, so the views are one fusion."""
        members = self.members
        owners = members[:1] if shared else members
        views: dict[int, GridMap] = {}
        for i in owners:

            def held(j: int, i: int = i) -> GridMap | None:
                return maps(j) if j == i else self._received.get((i, j))

            # Robot 0's map as held, the others' fused in; a robot that never received
            # robot 0's map starts from the first it holds, brought into the frame.
            view = held(0)
            resolution = maps(i).resolution
            for j in members[1:]:
                other = held(j)
                if other is None:
                    continue
                if not math.isclose(other.resolution, resolution):
                    other = resample_map(other, resolution)
                if view is None:
                    view = warp_map(other, self.frames[j])
                else:
                    view = fuse_maps(view, other, self.frames[j])
            assert view is not None  # robot i holds its own map
            views[i] = view
        self.views = [
            (views[owners[0]] if shared else views[i]) if i in members else None
            for i in range(self.n_robots)
        ]
        self._last_merge_step = self.step

    def _act_coordinated(
        self, observations: list[dict[str, Any]], maps: MapSource
    ) -> list[NDArray[np.float32]]:
        members = self.members
        poses = [
            pose if self.roots[i] != 0 or i == 0 else compose(self.frames[i], pose)
            for i, pose in enumerate(self._poses)
        ]
        self._assign_frontiers(members, poses)
        actions = []
        for i, policy in enumerate(self.policies):
            if self.roots[i] != 0:
                actions.append(self.act_alone(i, observations[i], maps(i)))
                continue
            # In turn, so that a robot sees the targets the robots before it pick on this
            # very step; a teammate's pose and target are known only as last received.
            memory = self.config.teammate_memory
            for j in members:
                if j != i and self._reach[i, j]:
                    self._shared[(i, j)] = (poses[j][:2].copy(), self._target_of(j), self.step)
                elif (
                    memory
                    and (i, j) in self._shared
                    and self.step - self._shared[(i, j)][2] > memory
                ):
                    del self._shared[(i, j)]  # too old to trust
            known = [(j, *self._shared[(i, j)][:2]) for j in members if (i, j) in self._shared]
            mine = self._target_of(i)
            replan = getattr(policy, "request_replan", None)
            radius = getattr(policy, "shared_target_radius", self.config.explorer.separation / 4)
            if (
                replan is not None
                and mine is not None
                and any(
                    j < i and target is not None and np.hypot(*(mine - target)) < radius
                    for j, _, target in known
                )
            ):
                replan()  # two robots heading for one frontier: the later yields
            view = self.views[i]
            assert view is not None
            if self._on_goal[i]:
                actions.append(self.explorers[i].act(observations[i], view, pose_in_map=poses[i]))
                continue
            context = PolicyContext(
                robot=i,
                step=self.step,
                map=view,
                pose=poses[i],
                own_map=maps(i),
                in_common_frame=True,
                teammates=_points([position for _, position, _ in known]),
                teammate_targets=_points([t for _, _, t in known if t is not None]),
                goal=self._assigned[i],
                common_from_own=self.frames[i].copy(),
            )
            actions.append(policy.act(observations[i], context))
        return actions

    def _target_of(self, robot: int) -> FloatArray | None:
        """Where ``robot`` heads in the common frame: its policy's ``target`` when it has
        one, else the frontier the team assigned it."""
        policy = self.policies[robot]
        if hasattr(policy, "target"):
            target = policy.target
            return None if target is None else np.asarray(target, dtype=np.float64)[:2]
        return self._assigned[robot]

    def _assign_frontiers(self, members: list[int], poses: list[FloatArray]) -> None:
        """Every ``replan_interval`` steps, the frontiers of the merged map split between
        the robots of the common frame (:func:`~agents.explorer.team_frontier_goals`), for
        the policies without a ``target`` of their own (their context's ``goal``)."""
        chooses = [hasattr(self.policies[i], "target") for i in members]
        if all(chooses):
            return
        if self.step - self._last_assignment < self.config.explorer.replan_interval:
            return
        self._last_assignment = self.step
        assert self.merged_map is not None
        positions = np.array([poses[i] for i in members])
        goals, _ = team_frontier_goals(self.merged_map, positions, self.config.explorer)
        for i, own_choice, goal in zip(members, chooses, goals, strict=True):
            self._assigned[i] = None if own_choice or not np.all(np.isfinite(goal)) else goal


def _row(robot: int, other: int) -> int:
    """The row of ``other`` in ``robot``'s ``peer`` and ``comm`` observations (index
    order, itself skipped)."""
    return other if other < robot else other - 1


def _reachable(links: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Which robots can exchange data, directly or through teammates (the transitive
    closure of ``links``, (N, N) bool; each robot reaches itself)."""
    reach = links | np.eye(len(links), dtype=bool)
    for k in range(len(links)):
        reach = reach | (reach[:, k : k + 1] & reach[k : k + 1, :])
    return reach


def _points(points: Any) -> FloatArray:
    """``points`` as a (K, 2) float array (None: empty)."""
    if points is None:
        return np.empty((0, 2))
    return np.asarray(points, dtype=np.float64).reshape(-1, 2)


def _no_map(robot: int) -> GridMap:
    raise RuntimeError("the team has not acted yet: no maps")


def window(grid: GridMap, point: ArrayLike, radius: float) -> GridMap:
    """The square of ``grid`` within ``radius`` (m) of ``point`` (its frame), clipped to
    the grid (one unknown cell when the point is outside it)."""
    row, col = grid.world_to_cell(np.asarray(point, dtype=np.float64)[None, :2])[0]
    reach = math.ceil(radius / grid.resolution)
    rows, cols = grid.shape
    r0, r1 = max(row - reach, 0), min(row + reach + 1, rows)
    c0, c1 = max(col - reach, 0), min(col + reach + 1, cols)
    if r0 >= r1 or c0 >= c1:
        return GridMap(cells=np.full((1, 1), UNKNOWN, dtype=np.int8), resolution=grid.resolution)
    origin = (grid.origin[0] + c0 * grid.resolution, grid.origin[1] + r0 * grid.resolution)
    return GridMap(cells=grid.cells[r0:r1, c0:c1].copy(), resolution=grid.resolution, origin=origin)
