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

Two robots (``robot_0`` holds the team frame: the merged map is in robot 0's map frame).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.explorer import ExplorerConfig, ExplorerPolicy
from agents.planning import distance_field, inflate
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
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.fuse import fuse_maps, resample_map
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
    "Decision",
    "MergeAttempt",
    "TeamConfig",
    "TeamCoordinator",
    "TeamState",
    "distinct_hypotheses",
    "in_plain_sight",
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
    peer_range: float = DEFAULT_ENV.peer.detect_range
    """The peer sensor's detection range, m: the env's ``PeerSensorConfig.detect_range``
    (:meth:`for_env`)."""
    sight_margin: float = 1.0
    """A hypothesis that puts the robots closer than ``peer_range - sight_margin``
    (:attr:`in_sight_range`, m) is verified where they stand, without a rendezvous drive;
    the margin keeps the prediction's error inside the sensor's range (m, >= 0)."""
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
    consistent with both maps (``ScoredHypothesis.confident``: acceptance index, no
    conflicts, enough overlap) are worth the drive; several of them is exactly the
    ambiguity (repeated rooms, mirrored wings) that only a rendezvous can settle."""
    max_meeting_cost: float = 25.0
    """Skip a hypothesis whose meeting point is further than this (m of weighted path)
    for the later robot: the detour would cost more exploration than the merge saves."""
    merged_map_every: int = 5
    """Steps between refreshes of the merged map while coordinating."""
    refine_every: int = 0
    """Steps between re-refinements of the transform on the grown maps (0: never, the
    default). The relation between the map frames is a constant, best estimated when it
    is verified, from maps that carry little drift yet; maps grown later carry more, and
    re-refining on them trades the frames' relation for local alignment."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            non_negative=("min_map_area", "max_meeting_cost", "sight_margin"),
            positive=("peer_range",),
            counts=("max_rendezvous", "merged_map_every"),
        )
        name = type(self).__name__
        factor = self.regrow_factor
        ok = isinstance(factor, int | float) and math.isfinite(factor) and factor >= 1
        require(name, "regrow_factor", factor, ok, "a finite number >= 1")
        every = self.refine_every
        ok = isinstance(every, int) and not isinstance(every, bool) and every >= 0
        require(name, "refine_every", every, ok, "an int >= 0")
        margin, peer_range = self.sight_margin, self.peer_range
        require(name, "sight_margin", margin, margin < peer_range, f"< peer_range ({peer_range})")

    @property
    def in_sight_range(self) -> float:
        """Closer than this (m) the robots are in the peer sensor's sight, with a margin."""
        return self.peer_range - self.sight_margin

    @staticmethod
    def env_figures(env: EnvConfig) -> EnvFigures:
        """The fields that are the env's figures: the peer sensor's range."""
        return {"peer_range": ("peer.detect_range", env.peer.detect_range)}

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
    matches: int = 0
    motion: float = 0.0
    """Both robots' travel since the first match, m."""
    previous: list[FloatArray] | None = None
    unseen: int = 0
    """Steps in a row the hypothesis put the robots in plain sight, unseen."""
    others_unseen: dict[int, int] = field(default_factory=dict)
    """The same count for each hypothesis still waiting its turn (by index): the drive
    for one hypothesis also tests the others."""


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
    """Drives two :class:`~agents.explorer.ExplorerPolicy` robots through the four kinds of
    interaction.

    Parameters
    ----------
    config : TeamConfig
        Defaults to the default env's robots and sensors; :meth:`for_env` follows a given
        env's.
    rng : numpy.random.Generator
        All randomness (explorers' tie-breaking, merging).

    Use: each step call :meth:`act` with the env observations and a function giving robot
    i's current own map; read :attr:`state`, :attr:`transform`, :attr:`merged_map`,
    :attr:`rendezvous_point` and the explorers for recording; :meth:`pop_decisions`
    returns what was decided since the last call.
    """

    def __init__(self, config: TeamConfig | None = None, *, rng: np.random.Generator) -> None:
        self.config = config if config is not None else TeamConfig()
        self.rng = rng
        self.explorers = [
            ExplorerPolicy(np.random.default_rng(rng.integers(2**63)), self.config.explorer)
            for _ in range(2)
        ]
        self.state = TeamState.NO_INTERACTION
        self.step = 0
        self.transform: FloatArray | None = None
        """``map0_from_map1`` once verified (refined), else None."""
        self.preliminary_transform: FloatArray | None = None
        """The verified hypothesis before refinement."""
        self.hypotheses: list[FloatArray] = []
        self.rejected: list[FloatArray] = []
        """Hypotheses a rendezvous rejected: the maps' frames never move, so they stay
        wrong and are not tried again."""
        self.hypotheses_tested = 0
        self.step_verified: int | None = None
        self.views: list[GridMap | None] = [None, None]
        """Per robot, the merged map it explores, in map 0's frame: its own map, current,
        fused with the other robot's as it last received it. The two are one map while
        the link is up; while it is down, each robot still sees all of its own mapping
        (a robot exploring on a stale copy of its own map drives to frontiers it has
        already explored)."""
        self.rendezvous: _Rendezvous | None = None
        self._decisions: list[Decision] = []
        self._merge_attempts: list[MergeAttempt] = []
        self._merges_tried = 0
        self._received: list[GridMap | None] = [None, None]
        """Per robot, the other robot's map as it last received it (while the link was
        up)."""
        self._last_merge_step = -(10**9)
        self._last_refine_step = 0
        self._retry_area = 0.0
        self._last_poses = [np.zeros(3), np.zeros(3)]
        self._last_observations: list[dict[str, Any]] = []
        self._link = False
        self._verified_at = np.zeros(2)
        """Robot 1's position (map 1) when the hypothesis was accepted."""
        self._shared: list[tuple[FloatArray | None, FloatArray | None]] = [(None, None)] * 2
        """Per robot, its position and target in map 0's frame as last shared over the
        link (coordinated exploration)."""

    @classmethod
    def for_env(
        cls, env: EnvConfig, *, rng: np.random.Generator, config: TeamConfig | None = None
    ) -> TeamCoordinator:
        """A team for the env's robots and sensors: ``config`` (checked against the env)
        or :meth:`TeamConfig.for_env`."""
        if config is None:
            config = TeamConfig.for_env(env)
        config.check_env(env)
        return cls(config, rng=rng)

    # --- what recording reads -----------------------------------------------------------

    @property
    def merged_map(self) -> GridMap | None:
        """Robot 0's view of the merged map (its own map and robot 1's as last received),
        in map 0's frame, or None before a merge; robot 1 explores :attr:`views` ``[1]``."""
        return self.views[0]

    @property
    def rendezvous_point(self) -> FloatArray | None:
        """The meeting point in map 0's frame while verifying, else None."""
        return None if self.rendezvous is None else self.rendezvous.meeting_point.copy()

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
        """Actions for both robots (normalised ``(v, omega)``).

        Parameters
        ----------
        observations : list of dict
            The env observations of robot 0 and robot 1 (``pose``, ``scan``, ``peer``,
            ``comm``).
        maps : callable
            ``maps(i)`` is robot i's current own map (called only when needed).
        """
        self.step += 1
        link = bool(observations[0]["comm"][0]) and bool(observations[1]["comm"][0])
        self._last_poses = [np.asarray(o["pose"], dtype=np.float64) for o in observations]
        self._last_observations = observations
        self._link = link
        if self.config.interaction:
            if self.state is TeamState.NO_INTERACTION and link:
                self._maybe_generate(maps)
            if self.state is TeamState.HYPOTHESIS_VERIFICATION:
                self._verify(observations, maps, link)
            if self.state is TeamState.COORDINATED_EXPLORATION:
                self._keep_merged_map(maps, link)
        if self.state is TeamState.COORDINATED_EXPLORATION and self.merged_map is not None:
            return self._act_coordinated(observations)
        return [self.explorers[i].act(observations[i], maps(i)) for i in range(2)]

    # --- 1 -> 2: hypothesis generation ------------------------------------------------------

    def _maybe_generate(self, maps: MapSource) -> None:
        m0, m1 = maps(0), maps(1)
        areas = [np.count_nonzero(~m.unknown) * m.resolution**2 for m in (m0, m1)]
        if min(areas) < self.config.min_map_area or sum(areas) < self._retry_area:
            return
        self.state = TeamState.HYPOTHESIS_GENERATION
        self._decide(
            f"comm up: maps exchanged ({areas[0]:.0f} m² and {areas[1]:.0f} m²), "
            "generating hypotheses by virtual robot motion"
        )
        self._retry_area = sum(areas) * self.config.regrow_factor
        try:
            result = merge_maps(
                m0, m1, self.config.merge, rng=self.rng, trace=self.config.keep_merges
            )
        except MergeInputError as error:
            self._decide(f"no hypotheses: {error}")
            self.state = TeamState.NO_INTERACTION
            return
        self._merges_tried += 1
        if self.config.keep_merges:
            self._merge_attempts.append(
                MergeAttempt(
                    number=self._merges_tried, step=self.step, result=result, map0=m0, map1=m1
                )
            )
        pivot = m1.cell_to_world(np.argwhere(~m1.unknown).mean(axis=0)[None, :])[0]
        fresh = distinct_hypotheses(
            [h.map1_from_map2 for h in result.hypotheses if h.confident],
            self.rejected,
            pivot,
            self.config.merge,
        )
        self.hypotheses = fresh[: self.config.max_rendezvous]
        if not self.hypotheses:
            self._decide("no hypothesis worth a rendezvous; exploring on, retry when maps grow")
            self.state = TeamState.NO_INTERACTION
            return
        self._decide(f"{len(self.hypotheses)} hypotheses to verify by rendezvous")
        self._start_rendezvous(0, maps)

    # --- 3: hypothesis verification -----------------------------------------------------------

    def _start_rendezvous(self, index: int, maps: MapSource) -> None:
        while index < len(self.hypotheses):
            hypothesis = self.hypotheses[index]
            if any(hypothesis is rejected for rejected in self.rejected):
                index += 1  # rejected on the way to an earlier one's meeting point
                continue
            verdict = self._verify_in_place(hypothesis, maps(0))
            if verdict is not None:
                self.hypotheses_tested += 1
                rendezvous = _Rendezvous(
                    hypothesis=hypothesis,
                    index=index,
                    meeting_point=self._last_poses[0][:2].copy(),
                    started=self.step,
                )
                if verdict:
                    # Seen where predicted: confirm while both keep exploring (they move).
                    rendezvous.in_place = True
                    self.rendezvous = rendezvous
                    self.state = TeamState.HYPOTHESIS_VERIFICATION
                    self._decide(
                        f"hypothesis #{index}: robot_0 sees robot_1 where predicted from here; "
                        "confirming while they move"
                    )
                    return
                self._decide(
                    f"hypothesis #{index} rejected where the robots stand: it puts robot_1 "
                    "in plain sight of robot_0, and robot_0 does not see it"
                )
                self.rejected.append(hypothesis)
                index += 1
                continue
            meeting = self._meeting_point(hypothesis, maps)
            if meeting is not None and meeting[1] > self.config.max_meeting_cost:
                self._decide(
                    f"hypothesis #{index}: the meeting point is {meeting[1]:.0f} m away; "
                    "skipped for now"
                )
            elif meeting is not None:
                point0, cost = meeting
                point1 = transform_points(inverse(hypothesis), point0[None, :])[0]
                self.rendezvous = _Rendezvous(
                    hypothesis=hypothesis,
                    index=index,
                    meeting_point=point0,
                    started=self.step,
                )
                for explorer, goal in zip(self.explorers, (point0, point1), strict=True):
                    explorer.set_goal(goal)
                self.state = TeamState.HYPOTHESIS_VERIFICATION
                self.hypotheses_tested += 1
                x, y, theta = hypothesis
                self._decide(
                    f"rendezvous for hypothesis #{index} (x {x:.2f}, y {y:.2f}, "
                    f"theta {theta:.3f}): meet at ({point0[0]:.2f}, {point0[1]:.2f}) in "
                    f"robot_0's map, later arrival after ~{cost:.1f} m"
                )
                return
            else:
                self._decide(f"hypothesis #{index}: no meeting point reachable by both; skipped")
            index += 1
        self._give_up()

    def _verify_in_place(self, hypothesis: FloatArray, map0: GridMap) -> bool | None:
        """A rendezvous of length zero: if the hypothesis puts robot 1 well within the peer
        sensor's range of robot 0, across space robot 0's map knows to be free, the sensor
        settles it where they stand (True: seen where predicted; False: not seen). None
        when the robots have to meet first."""
        if not (self._link and self._last_observations):
            return None  # robot 1's pose is only known over the link
        predicted = predicted_relative_pose(self._last_poses[0], self._last_poses[1], hypothesis)
        distance = float(np.hypot(predicted[0], predicted[1]))
        if not 0.5 < distance < self.config.in_sight_range:
            return None
        peer = self._last_observations[0]["peer"][0]
        if peer[0] > 0.5:
            seen = sighting_pose(peer[1], peer[2], peer[3])
            return judge_sighting(seen, predicted, self.config.rendezvous).matches
        # Not seen: only a rejection if the line of sight is known free in robot 0's map.
        sight_range = self.config.in_sight_range
        seen_free = in_plain_sight(self._last_poses[0], predicted, map0, sight_range=sight_range)
        return False if seen_free else None

    def _meeting_point(
        self, hypothesis: FloatArray, maps: MapSource
    ) -> tuple[FloatArray, float] | None:
        m0, m1 = maps(0), maps(1)
        planner = self.config.explorer.planner
        costs = []
        for i, grid in enumerate((m0, m1)):
            explorer_pose = self._last_poses[i]
            try:
                costs.append(distance_field(inflate(grid, planner), explorer_pose).cost)
            except ValueError:
                return None
        cost1_on_0 = field_on_lattice(costs[1], m1, m0, hypothesis)
        return choose_meeting_point(costs[0], cost1_on_0, m0)

    def _verify(self, observations: list[dict[str, Any]], maps: MapSource, link: bool) -> None:
        rendezvous = self.rendezvous
        assert rendezvous is not None
        config = self.config.rendezvous
        poses = [np.asarray(o["pose"], dtype=np.float64) for o in observations]
        if link:
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
                who = f"robot_{observer} sees robot_{1 - observer}"
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
        if rendezvous.first_match is not None:
            if self.step - rendezvous.first_match >= config.confirm_steps:
                self._set_aside(rendezvous, maps, "seen where predicted, but not confirmed")
                return
            # Seen where predicted: if both robots stand still at the meeting point,
            # robot 1 drives on so that the sightings test the hypothesis on a motion.
            if self.explorers[1].status == "arrived":
                self.explorers[1].clear_goal()
            return
        if rendezvous.in_place:
            if self.step - rendezvous.started >= config.wait_steps:
                self._set_aside(rendezvous, maps, "lost sight of each other")
            return
        arrived = all(e.status in ("arrived", "goal_unreachable") for e in self.explorers)
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

    def _within_verified(self, transform: FloatArray) -> bool:
        """Whether ``transform`` stays within the rendezvous tolerances of the verified
        hypothesis where the robots met: the sighting verified no more than that, and a
        refinement that wanders further (in a building with repeated parts the maps can
        fit another placement better) is not trusted."""
        assert self.preliminary_transform is not None
        config = self.config.rendezvous
        point = self._verified_at[None, :]
        verified = self.preliminary_transform
        moved = float(
            np.hypot(*(transform_points(transform, point) - transform_points(verified, point))[0])
        )
        turned = abs(math.remainder(float(transform[2] - verified[2]), 2 * math.pi))
        return moved <= config.position_tolerance and turned <= config.heading_tolerance

    def _set_aside(self, rendezvous: _Rendezvous, maps: MapSource, why: str) -> None:
        """Neither accepted nor rejected: the hypothesis may be proposed again later."""
        self._decide(f"hypothesis #{rendezvous.index} set aside: {why}")
        self.rendezvous = None
        for explorer in self.explorers:
            explorer.clear_goal()
        self._start_rendezvous(rendezvous.index + 1, maps)

    def _accept(self, rendezvous: _Rendezvous, maps: MapSource, how: str, error: float) -> None:
        self.preliminary_transform = rendezvous.hypothesis.copy()
        self._decide(
            f"hypothesis #{rendezvous.index} accepted: {how} (last sighting {error:.2f} m off)"
        )
        m0, m1 = maps(0), maps(1)
        self._verified_at = self._last_poses[1][:2].copy()
        transform, psi, agreement = refine_transform(
            m0, m1, rendezvous.hypothesis, self.config.merge, rng=self.rng
        )
        if not self._within_verified(transform):
            self._decide("the refinement left what the sighting verified; kept the hypothesis")
            transform = rendezvous.hypothesis.copy()
        self.transform = transform
        self.step_verified = self.step
        self._last_refine_step = self.step
        self._decide(
            f"refined by random walk: psi {psi:.3f}, acceptance index {agreement.index:.3f}; "
            "coordinated exploration on the merged map"
        )
        self.rendezvous = None
        for explorer in self.explorers:
            explorer.clear_goal()
        # Robot 1 now explores the merged map, in robot 0's frame.
        self.explorers[1].change_frame(transform)
        self.state = TeamState.COORDINATED_EXPLORATION
        self._received = [m1, m0]
        self._fuse(maps, shared=True)

    def start_coordinated(self, transform: FloatArray, maps: MapSource) -> None:
        """Skip merging and verification: coordinate from now on with a known
        ``map0_from_map1`` (the benchmark's oracle, given the true relative pose).

        What follows is the coordination that follows a verified merge; the robots'
        current maps count as exchanged (at the start, one scan each).
        """
        transform = np.asarray(transform, dtype=np.float64).copy()
        self.preliminary_transform = transform.copy()
        self.transform = transform
        self.step_verified = self.step
        self._last_refine_step = self.step
        self._verified_at = self._last_poses[1][:2].copy()
        self.hypotheses = []
        self.rendezvous = None
        self._decide("relative pose given (oracle): coordinated exploration on the merged map")
        for explorer in self.explorers:
            explorer.clear_goal()
        self.explorers[1].change_frame(transform)
        self.state = TeamState.COORDINATED_EXPLORATION
        self._received = [maps(1), maps(0)]
        self._fuse(maps, shared=True)

    def _reject(self, rendezvous: _Rendezvous, maps: MapSource, why: str) -> None:
        self._decide(f"hypothesis #{rendezvous.index} rejected: {why}")
        self.rejected.append(rendezvous.hypothesis)
        self.rendezvous = None
        for explorer in self.explorers:
            explorer.clear_goal()
        self._start_rendezvous(rendezvous.index + 1, maps)

    def _give_up(self) -> None:
        self._decide("all hypotheses rejected: independent exploration until the maps grow")
        self.hypotheses = []
        self.rendezvous = None
        self.state = TeamState.NO_INTERACTION

    # --- 4: coordinated exploration -------------------------------------------------------

    def _keep_merged_map(self, maps: MapSource, link: bool) -> None:
        assert self.transform is not None
        if self.step - self._last_merge_step < self.config.merged_map_every:
            return
        if link:
            self._received = [maps(1), maps(0)]
            if (
                self.config.refine_every
                and self.step - self._last_refine_step >= self.config.refine_every
            ):
                refined, _, _ = refine_transform(
                    maps(0), maps(1), self.transform, self.config.merge, rng=self.rng
                )
                if self._within_verified(refined):
                    self.explorers[1].change_frame(compose(refined, inverse(self.transform)))
                    self.transform = refined
                self._last_refine_step = self.step
        self._fuse(maps, shared=link)

    def _fuse(self, maps: MapSource, *, shared: bool) -> None:
        """Refresh both robots' views; ``shared``: each has the other's current map (the
        link is up), so the two views are one fusion."""
        assert self.transform is not None
        own = [maps(0), maps(1)]
        views: list[GridMap] = []
        for i in range(2 if not shared else 1):
            other = self._received[i]
            assert other is not None
            m0, m1 = (own[0], other) if i == 0 else (other, own[1])
            if not math.isclose(m1.resolution, m0.resolution):
                m1 = resample_map(m1, m0.resolution)
            views.append(fuse_maps(m0, m1, self.transform))
        self.views = [views[0], views[-1]]
        self._last_merge_step = self.step

    def _act_coordinated(self, observations: list[dict[str, Any]]) -> list[NDArray[np.float32]]:
        assert self.transform is not None and self.merged_map is not None
        poses0 = [
            np.asarray(observations[0]["pose"], dtype=np.float64),
            compose(self.transform, np.asarray(observations[1]["pose"], dtype=np.float64)),
        ]
        actions = []
        for i, explorer in enumerate(self.explorers):
            # In turn, so that robot 1 sees the target robot 0 picks on this very step;
            # a teammate's pose and target are known only as last received over the link.
            other = 1 - i
            if self._link:
                target = self.explorers[other].target
                self._shared[other] = (poses0[other][:2].copy(), target)
            position, target = self._shared[other]
            explorer.set_teammates(np.empty((0, 2)) if position is None else position[None])
            explorer.set_teammate_targets(np.empty((0, 2)) if target is None else target[None])
            mine = explorer.target
            if (
                i == 1
                and target is not None
                and mine is not None
                and np.hypot(*(mine - target)) < explorer.shared_target_radius
            ):
                explorer.request_replan()  # both heading for one frontier: robot 1 yields
            view = self.views[i]
            assert view is not None
            actions.append(explorer.act(observations[i], view, pose_in_map=poses0[i]))
        return actions
