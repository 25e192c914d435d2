"""The team's configuration and the vocabulary its parts share (design §6).

:class:`TeamConfig` (how the team decides), :class:`TeamState` (the four kinds of
interaction, the states of :class:`agents.team.TeamCoordinator`), :class:`Decision` (one
line of the ``events`` log) and :data:`MapSource`. The coordinator and each of its roles
(:mod:`agents.team_contact`, :mod:`agents.team_proposals`,
:mod:`agents.team_verification`, :mod:`agents.team_groups`,
:mod:`agents.team_allocation`) import them from here; :mod:`agents.team` re-exports them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.explorer import ExplorerConfig
from agents.rendezvous import RendezvousConfig
from agents.robot import DEFAULT_ENV, EnvFigures, build_for_env, check_against_env
from mrslam_env.config import EnvConfig
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.graph import JointRefineConfig
from mrslam_env.merge.pipeline import MergeConfig
from mrslam_env.validation import check_fields, require

__all__ = ["Decision", "FloatArray", "MapSource", "TeamConfig", "TeamState"]

FloatArray = NDArray[np.float64]

MapSource = Callable[[int], GridMap]
"""``maps(i)``: robot i's map (its own, or in a role, the pair's side i's group map)."""


class TeamState(StrEnum):
    """The team's state: the kind of interaction under way (the table of
    :mod:`agents.team`; with N robots, that of the pair being merged)."""

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
