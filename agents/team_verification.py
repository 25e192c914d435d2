"""The team's verification role: rendezvous planning, the meeting, the checks.

A role of :class:`agents.team.TeamCoordinator` (design §6; the pure geometry is
:mod:`agents.rendezvous`). It takes the hypotheses the proposals role
(:mod:`agents.team_proposals`) left in :attr:`TeamCoordinator.hypotheses`, best first,
and settles them one at a time; the one under test is :attr:`TeamCoordinator.rendezvous`
(a :class:`_Rendezvous`). Following one hypothesis:

1. :meth:`Verification.start` puts it to a test: **in place** when it puts the robots
   within the peer sensor's sight of each other (seen where predicted: confirmed while
   they explore; not seen across free space: rejected at once), **waiting** for a chance
   meeting when the merge left a rival open (:meth:`Proposals.is_decided
   <agents.team_proposals.Proposals.is_decided>`), else **a drive** of both robots to a
   meeting point (:meth:`Verification.meeting_point`); a sighting's hypothesis arrives
   already waiting.
2. :meth:`Verification.verify`, every step: the radio checks (:meth:`radio_refutes
   <Verification.radio_refutes>`, on the link history of :mod:`agents.team_contact`), the
   peer sensor's sightings judged against the prediction, hypotheses in plain sight but
   unseen (:data:`UNSEEN_STEPS`), waits, arrivals and time-outs.
3. It ends **accepted** (:meth:`Verification.accept`: refined on the maps, recorded as an
   :class:`Acceptance`, the pair's groups joined by :mod:`agents.team_groups`, then
   :meth:`TeamCoordinator._accepted`), **rejected** (kept among the pair's rejected
   hypotheses unless from sightings) or **set aside** (may be proposed again); either
   way the next hypothesis is started, and with none left the team rests.

Interface: :meth:`~Verification.start`, :meth:`~Verification.verify`,
:meth:`~Verification.accept`, :meth:`~Verification.meeting_point`,
:meth:`~Verification.test_waiting` and the checks the other roles use too:
:meth:`~Verification.within_verified` (a refinement stays within the rendezvous
tolerances), :meth:`~Verification.radio_refutes` and :meth:`~Verification.radio_rejects`.
State it owns: the ways to the last meeting point chosen and the first link-history step
the next radio check judges; the tallies it keeps (``hypotheses_tested``,
``first_rendezvous_step``, ``radio_rejections``, ``acceptances``) are the coordinator's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from agents.planning import distance_field, inflate
from agents.rendezvous import (
    choose_meeting_point,
    field_on_lattice,
    heading_allowance,
    in_plain_sight,
    judge_sighting,
    predicted_relative_pose,
    radio_contradiction,
    sighting_pose,
)
from agents.team_config import FloatArray, MapSource
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.pipeline import refine_transform

if TYPE_CHECKING:
    from agents.team import TeamCoordinator

__all__ = ["UNSEEN_STEPS", "Acceptance", "Verification"]

UNSEEN_STEPS = 10
"""On the way to a meeting point, a hypothesis that keeps the other robot in plain sight
(:func:`~agents.rendezvous.in_plain_sight`) for this many steps in a row while the peer
sensor sees nothing is rejected there and then."""


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


class Verification:
    """Settles ``team``'s hypotheses one at a time (module notes)."""

    def __init__(self, team: TeamCoordinator) -> None:
        self.team = team
        self.meeting_costs: tuple[float, float] | None = None
        """Each side's way (m) to the last meeting point chosen."""
        self._radio_since = 0
        """The first track step the next per-step radio check judges (:meth:`verify`)."""

    def start(self, index: int, maps: MapSource) -> None:
        """Put hypothesis ``index`` (or the next one worth it) to a rendezvous; ``maps``
        gives the pair's side maps."""
        team = self.team
        names = [f"robot_{r}" for r in team.pair]
        while index < len(team.hypotheses):
            hypothesis = team.hypotheses[index]
            if any(hypothesis is rejected for rejected in team.rejected):
                index += 1  # rejected on the way to an earlier one's meeting point
                continue
            verdict = self._verify_in_place(hypothesis, maps(0))
            if verdict is not None:
                team.hypotheses_tested += 1
                team._note_hypothesis()
                rendezvous = _Rendezvous(
                    hypothesis=hypothesis,
                    index=index,
                    meeting_point=team._last_poses[0][:2].copy(),
                    started=team.step,
                    last_match=team.step,
                )
                if verdict:
                    # Seen where predicted: confirm while both keep exploring (they move);
                    # should they lose sight of each other, they drive to meet (verify).
                    rendezvous.in_place = True
                    team._verifying(rendezvous)
                    team._decide(
                        f"hypothesis #{index}: {names[0]} sees {names[1]} where predicted "
                        "from here; confirming while they move"
                    )
                    return
                team._decide(
                    f"hypothesis #{index} rejected where the robots stand: it puts "
                    f"{names[1]} in plain sight of {names[0]}, and {names[0]} does not see it"
                )
                team.rejected.append(hypothesis)
                index += 1
                continue
            if team.config.undecided_wait != 0 and not team.proposals.is_decided(hypothesis):
                team.hypotheses_tested += 1
                team._note_hypothesis()
                team._verifying(
                    _Rendezvous(
                        hypothesis=hypothesis,
                        index=index,
                        meeting_point=team._last_poses[0][:2].copy(),
                        started=team.step,
                        last_match=team.step,
                        in_place=True,
                        waits=True,
                    )
                )
                wait = team.config.undecided_wait
                until = "they have nothing left to explore" if wait is None else f"{wait} steps"
                team._decide(
                    f"hypothesis #{index}: a rival is open beside it (the merge's answer is "
                    f"not this one); tested where the robots explore, until {until}, "
                    "before a rendezvous"
                )
                return
            meeting = self.meeting_point(hypothesis, maps)
            if meeting is not None and meeting[1] > team.config.max_meeting_cost:
                team._decide(
                    f"hypothesis #{index}: the meeting point is {meeting[1]:.0f} m away; "
                    "skipped for now"
                )
            elif meeting is not None:
                point0, cost = meeting
                rendezvous = _Rendezvous(
                    hypothesis=hypothesis,
                    index=index,
                    meeting_point=point0,
                    started=team.step,
                )
                self._send_to_meet(rendezvous)
                team._verifying(rendezvous)
                team.hypotheses_tested += 1
                team._note_hypothesis()
                x, y, theta = hypothesis
                team._decide(
                    f"rendezvous for hypothesis #{index} (x {x:.2f}, y {y:.2f}, "
                    f"theta {theta:.3f}): meet at ({point0[0]:.2f}, {point0[1]:.2f}) in "
                    f"robot_{team.roots[team.pair[0]]}'s map, later arrival after ~{cost:.1f} m"
                )
                return
            else:
                team._decide(f"hypothesis #{index}: no meeting point reachable by both; skipped")
            index += 1
        self._give_up()

    def verify(self, observations: list[dict[str, Any]], maps: MapSource, link: bool) -> None:
        """One step of the rendezvous; ``observations`` and ``maps`` are the pair's (side
        0, side 1: poses in the group roots' frames, the partner's peer row)."""
        team = self.team
        rendezvous = team.rendezvous
        assert rendezvous is not None
        config = team.config.rendezvous
        robots = team.pair
        hold = rendezvous.hold
        if hold is not None and team.step >= hold[1] and not rendezvous.in_place:
            rendezvous.hold = None
            team._send(hold[0], self._meeting_goal(rendezvous, hold[0]))
        # The radio on the steps since the last check, once the link is up (the partner's
        # positions come over it): for the hypothesis under test (a drive ends as soon as
        # the link says the robots are not where it puts them) and those waiting their turn.
        if link:
            since, self._radio_since = self._radio_since, len(team.contact.link_track)
            for hypothesis in team.hypotheses[rendezvous.index + 1 :]:
                if not any(hypothesis is rejected for rejected in team.rejected):
                    self.radio_rejects(hypothesis, "waiting its turn", since=since)
            why = self.radio_refutes(rendezvous.hypothesis, since=since)
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
                    rendezvous.first_match = team.step
                    rendezvous.previous = poses
                rendezvous.matches += 1
                rendezvous.last_match = team.step
                if (
                    rendezvous.matches >= config.confirm_sightings
                    and rendezvous.motion >= config.confirm_motion
                ):
                    self.accept(
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
                sight_range = team.config.in_sight_range
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
                self.test_waiting(rendezvous, poses, maps)
        # A waiting hypothesis (from sightings, or a rival the merge left open), still
        # unmatched, waits longer for a later meeting by chance.
        waiting = rendezvous.waits and rendezvous.first_match is None
        lost_after: float = UNSEEN_STEPS
        if waiting and rendezvous.formed_at is not None:
            lost_after = team.config.sighting_wait
        elif waiting:
            wait = team.config.undecided_wait
            lost_after = math.inf if wait is None else wait
        # Robots with nothing left to explore would wait for a chance meeting in vain.
        idle = waiting and all(team.done(r) for r in robots)
        if (
            rendezvous.in_place
            and rendezvous.last_match is not None
            and (team.step - rendezvous.last_match >= lost_after or idle)
            and self._drive_to_meet(rendezvous, maps)
        ):
            return
        if rendezvous.first_match is not None:
            if team.step - rendezvous.first_match >= config.confirm_steps:
                self._set_aside(rendezvous, maps, "seen where predicted, but not confirmed")
                return
            # Seen where predicted: if both robots stand still at the meeting point,
            # side 1's robot drives on so that the sightings test the hypothesis on a motion.
            if team.explorers[robots[1]].status == "arrived":
                team._release(robots[1])
            return
        if rendezvous.in_place:
            if team.step - rendezvous.started >= config.wait_steps + (lost_after - UNSEEN_STEPS):
                why = "no meeting point" if waiting else "lost sight of each other"
                self._set_aside(rendezvous, maps, why)
            return
        stuck = [r for r in robots if team.explorers[r].status == "goal_unreachable"]
        if stuck:
            # Not a test of the hypothesis: the robot cannot get there on its map.
            self._set_aside(
                rendezvous, maps, f"robot_{stuck[0]} cannot reach the meeting point on its map"
            )
            return
        arrived = all(team.explorers[r].status == "arrived" for r in robots)
        if arrived and rendezvous.arrived_at is None:
            rendezvous.arrived_at = team.step
            team._decide("both robots at the rendezvous; waiting for a sighting")
        if (
            rendezvous.arrived_at is not None
            and team.step - rendezvous.arrived_at >= config.wait_steps
        ):
            self._reject(rendezvous, maps, "arrived and waited: the other robot was not there")
        elif team.step - rendezvous.started >= config.timeout_steps:
            self._reject(rendezvous, maps, "rendezvous timed out")

    def accept(self, rendezvous: _Rendezvous, maps: MapSource, how: str, error: float) -> None:
        """Accept the hypothesis of ``rendezvous`` (``how``: the sightings' words, ``error``:
        the last one's, m): refined on the pair's maps (kept only within the rendezvous
        tolerances of what was verified), recorded; the pair's groups are joined by it
        (:meth:`~agents.team_groups.Groups.join_pair`) and the team rests
        (:meth:`TeamCoordinator._accepted`)."""
        team = self.team
        radio = ""
        if team.config.radio_margin is not None:
            radio = f"; radio {self.radio_excess(rendezvous.hypothesis):+.2f} m"
        team._decide(
            f"hypothesis #{rendezvous.index} accepted: {how} (last sighting {error:.2f} m "
            f"off{radio})"
        )
        m0, m1 = maps(0), maps(1)
        verified_at = team._last_poses[1][:2].copy()
        transform, psi, agreement = refine_transform(
            m0, m1, rendezvous.hypothesis, team.config.merge, rng=team.rng
        )
        if not self.within_verified(transform, rendezvous.hypothesis, verified_at):
            team._decide("the refinement left what the sighting verified; kept the hypothesis")
            transform = rendezvous.hypothesis.copy()
        team._decide(
            f"refined by random walk: psi {psi:.3f}, acceptance index {agreement.index:.3f}; "
            "coordinated exploration on the merged map"
        )
        team.acceptances.append(
            Acceptance(
                step=team.step,
                index=rendezvous.index,
                count=len(team.hypotheses),
                proposed_by=team.source_of(rendezvous),
                attempt=None if rendezvous.formed_at is not None else team.hypotheses_attempt,
                how=how,
                verified=rendezvous.hypothesis.copy(),
                refined=np.array(transform, dtype=np.float64),
            )
        )
        team.rendezvous = None
        team._release_pair()
        team.groups.join_pair(transform, rendezvous.hypothesis, verified_at, m0, m1)
        team._accepted()

    def _reject(self, rendezvous: _Rendezvous, maps: MapSource, why: str) -> None:
        """The hypothesis is wrong: never tried again for this pair of groups (unless from
        sightings); on to the next one."""
        team = self.team
        team._decide(f"hypothesis #{rendezvous.index} rejected: {why}")
        if rendezvous.formed_at is None:
            # One from sightings says nothing about the maps' other placements: it is
            # not kept among the rejected, which would hide a merge's answer close to it.
            team.rejected.append(rendezvous.hypothesis)
        team.rendezvous = None
        team._release_pair()
        self.start(rendezvous.index + 1, maps)

    def _set_aside(self, rendezvous: _Rendezvous, maps: MapSource, why: str) -> None:
        """Neither accepted nor rejected: the hypothesis may be proposed again later."""
        team = self.team
        team._decide(f"hypothesis #{rendezvous.index} set aside: {why}")
        team.rendezvous = None
        team._release_pair()
        self.start(rendezvous.index + 1, maps)

    def _give_up(self) -> None:
        """No hypothesis left to test: the team rests."""
        team = self.team
        team._decide("all hypotheses rejected: independent exploration until the maps grow")
        team._rest()

    def meeting_point(
        self, hypothesis: FloatArray, maps: MapSource, *, avoid: FloatArray | None = None
    ) -> tuple[FloatArray, float] | None:
        """The meeting point (side 0's group frame) and the later arrival's cost, each
        robot's travel planned on the map it drives on (:meth:`_driven_map`): a robot
        outside the common frame drives on its own map, which may not know the places
        its group's map (the merge's) does. ``avoid``: points (K, 2, side 0's frame) the
        meeting point keeps ``sighting_verify_distance + sight_margin`` (m) from."""
        team = self.team
        m0 = maps(0)
        planner = team.config.explorer.planner
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
            radius = team.config.sighting_verify_distance + team.config.sight_margin
            for point in avoid:
                near |= np.hypot(*(centres - point).T) < radius
            costs[0] = np.where(near.reshape(rows, cols), np.inf, costs[0])
        chosen = choose_meeting_point(costs[0], costs[1], m0)
        if chosen is not None:
            cell = tuple(m0.world_to_cell(chosen[0][None, :])[0])
            self.meeting_costs = (float(costs[0][cell]), float(costs[1][cell]))
        return chosen

    def _driven_map(self, side: int, maps: MapSource) -> tuple[GridMap, FloatArray, FloatArray]:
        """The map the pair's side-``side`` robot drives on to a given goal, its place in
        the robot's group root's frame (``root_from_map``) and the robot's pose in it."""
        team = self.team
        robot = team.pair[side]
        view = team.views[robot]
        if team.coordinated(robot) and view is not None:  # the merged map, common frame
            return view, np.zeros(3), team._last_poses[side]
        alone = all(team.roots[k] != team.roots[robot] for k in range(team.n_robots) if k != robot)
        if alone:  # its group's map is its own
            return maps(side), np.zeros(3), team._last_poses[side]
        # Outside the common frame a robot explores its own map, even in a group.
        frame = team.frames[robot] if team.roots[robot] != robot else np.zeros(3)
        return team._maps(robot), frame, team._poses[robot]

    def _send_to_meet(self, rendezvous: _Rendezvous) -> None:
        """Both sides of the pair to the meeting point (side 0's frame; side 1 to where
        the hypothesis puts it in its own frame); the side with the shorter way only
        after it explored on for :attr:`TeamConfig.departure_share` of the difference."""
        team = self.team
        if team.first_rendezvous_step is None:
            team.first_rendezvous_step = team.step
        rendezvous.hold = None
        costs, share = self.meeting_costs, team.config.departure_share
        self.meeting_costs = None  # used once: for the point just chosen
        if costs is not None and share > 0:
            follower = team.config.explorer.follower
            early = int(np.argmin(costs))
            steps = int(share * abs(costs[0] - costs[1]) / (follower.cruise_speed * follower.dt))
            if steps > 0:
                rendezvous.hold = (early, team.step + steps)
        for side in (0, 1):
            if rendezvous.hold is None or rendezvous.hold[0] != side:
                team._send(side, self._meeting_goal(rendezvous, side))

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
        team = self.team
        assert rendezvous.last_match is not None
        unseen = team.step - rendezvous.last_match
        hypothesis = rendezvous.hypothesis
        avoid = None
        if rendezvous.formed_at is not None:  # meet where the sightings test the maps
            at0, at1 = rendezvous.formed_at
            avoid = np.array([at0, transform_points(hypothesis, at1[None, :])[0]])
        meeting = self.meeting_point(hypothesis, maps, avoid=avoid)
        if meeting is None or meeting[1] > team.config.max_meeting_cost:
            return False
        point0, cost = meeting
        rendezvous.in_place = False
        rendezvous.meeting_point = point0
        rendezvous.started = team.step
        self._send_to_meet(rendezvous)
        if rendezvous.first_match is not None:
            rendezvous.first_match = team.step  # a full window to confirm at the meeting
        team._decide(
            f"hypothesis #{rendezvous.index}: no sighting for {unseen} steps before "
            f"it was confirmed; both drive to meet at ({point0[0]:.2f}, {point0[1]:.2f}), "
            f"later arrival after ~{cost:.1f} m"
        )
        return True

    def _verify_in_place(self, hypothesis: FloatArray, map0: GridMap) -> bool | None:
        """A rendezvous of length zero: if the hypothesis puts side 1's robot well within
        the peer sensor's range of side 0's, across space side 0's map knows to be free,
        the sensor settles it where they stand (True: seen where predicted; False: not
        seen). None when the robots have to meet first."""
        team = self.team
        if not (team._link and team._last_observations):
            return None  # the other robot's pose is only known over the link
        predicted = predicted_relative_pose(team._last_poses[0], team._last_poses[1], hypothesis)
        distance = float(np.hypot(predicted[0], predicted[1]))
        if not 0.5 < distance < team.config.in_sight_range:
            return None
        peer = team._last_observations[0]["peer"][0]
        if peer[0] > 0.5:
            seen = sighting_pose(peer[1], peer[2], peer[3])
            return judge_sighting(seen, predicted, team.config.rendezvous).matches
        # Not seen: only a rejection if the line of sight is known free in side 0's map.
        sight_range = team.config.in_sight_range
        seen_free = in_plain_sight(team._last_poses[0], predicted, map0, sight_range=sight_range)
        return False if seen_free else None

    def test_waiting(
        self, rendezvous: _Rendezvous, poses: list[FloatArray], maps: MapSource
    ) -> None:
        """With nobody seen: reject each hypothesis waiting its turn that has kept the
        robots in plain sight (:func:`in_plain_sight`) for :data:`UNSEEN_STEPS` steps."""
        team = self.team
        for index in range(rendezvous.index + 1, len(team.hypotheses)):
            hypothesis = team.hypotheses[index]
            if any(hypothesis is rejected for rejected in team.rejected):
                continue
            predicted = predicted_relative_pose(poses[0], poses[1], hypothesis)
            if not _either_in_sight(poses, predicted, maps, team.config.in_sight_range):
                rendezvous.others_unseen[index] = 0
                continue
            unseen = rendezvous.others_unseen.get(index, 0) + 1
            rendezvous.others_unseen[index] = unseen
            if unseen >= UNSEEN_STEPS:
                team.hypotheses_tested += 1
                team.rejected.append(hypothesis)
                team._decide(
                    f"hypothesis #{index} rejected on the way to #{rendezvous.index}'s "
                    f"meeting point: it kept the robots in plain sight of each other for "
                    f"{unseen} steps, and neither saw the other"
                )

    def within_verified(
        self, transform: FloatArray, verified: FloatArray, point: FloatArray
    ) -> bool:
        """Whether ``transform`` stays within the rendezvous tolerances of the
        ``verified`` hypothesis at ``point`` (where the robots met, in the frame
        ``transform`` maps from): the sighting verified no more than that, and a
        refinement that wanders further (in a building with repeated parts the maps can
        fit another placement better) is not trusted."""
        team = self.team
        config = team.config.rendezvous
        at = np.asarray(point, dtype=np.float64).reshape(1, 2)
        moved = float(
            np.hypot(*(transform_points(transform, at) - transform_points(verified, at))[0])
        )
        turned = abs(math.remainder(float(transform[2] - verified[2]), 2 * math.pi))
        return moved <= config.position_tolerance and turned <= config.heading_tolerance

    def radio_excess(self, hypothesis: FloatArray, since: int = 0) -> float:
        """:func:`radio_contradiction` of ``hypothesis`` (the current pair's) on the pair's
        tracks, each position in its group root's frame, from step ``since`` (an index into
        the tracks) to the last step the pair's link was up: a robot's positions reach its
        partner only over the link, so the steps it was down are judged when it is back.
        Each step is allowed the heading tolerance's reach at the partner
        (:func:`heading_allowance`) where it exceeds ``radio_margin``
        (:attr:`TeamConfig.radio_heading_tolerance`)."""
        team = self.team
        a, b = team.pair
        end = len(team.contact.link_track)
        while end > since and not team.contact.link_track[end - 1][a, b]:
            end -= 1
        tracks = []
        for robot in (a, b):
            track = np.asarray(team.contact.tracks[robot][:end], dtype=np.float64).reshape(-1, 2)
            if team.roots[robot] != robot:
                track = transform_points(team.frames[robot], track)
            tracks.append(track)
        link = np.array([links[a, b] for links in team.contact.link_track[since:end]], dtype=bool)
        judged = tracks[1][since:end]
        reach = heading_allowance(judged, tracks[1], team.config.radio_heading_tolerance)
        return radio_contradiction(
            hypothesis,
            tracks[0][since:end],
            judged,
            link,
            comm_range=team.config.comm_range,
            exact=team.config.comm_exact,
            allowance=np.maximum(reach - (team.config.radio_margin or 0.0), 0.0),
        )

    def radio_refutes(self, hypothesis: FloatArray, *, since: int = 0) -> str | None:
        """Why the radio rejects ``hypothesis`` (:attr:`TeamConfig.radio_margin`), judged
        on the steps from ``since`` (:meth:`radio_excess`); None when it does not."""
        team = self.team
        margin = team.config.radio_margin
        if margin is None:
            return None
        excess = self.radio_excess(hypothesis, since)
        if excess <= margin:
            return None
        team.radio_rejections += 1
        return (
            f"the radio: it puts the robots {excess:.1f} m beyond what the link said, past "
            f"the heading tolerance's reach (> the {margin} m margin)"
        )

    def radio_rejects(self, hypothesis: FloatArray, kind: str, *, since: int = 0) -> bool:
        """Whether the radio rejects ``hypothesis`` (:meth:`radio_refutes`); a rejected
        one is logged and kept among the pair's rejected hypotheses."""
        team = self.team
        why = self.radio_refutes(hypothesis, since=since)
        if why is None:
            return False
        team.rejected.append(hypothesis)
        x, y, theta = hypothesis
        team._decide(
            f"hypothesis (x {x:.2f}, y {y:.2f}, theta {theta:.3f}) {kind} rejected by {why}"
        )
        return True

    def _moved_off(self, rendezvous: _Rendezvous, poses: list[FloatArray]) -> bool:
        """Whether sightings now test ``rendezvous``: always for a hypothesis from the
        merge; for one from sightings, once both robots moved
        ``sighting_verify_distance`` from where it formed."""
        team = self.team
        formed_at = rendezvous.formed_at
        if formed_at is None:
            return True
        distance = team.config.sighting_verify_distance
        return all(
            float(np.hypot(*(pose[:2] - at))) >= distance
            for pose, at in zip(poses, formed_at, strict=True)
        )


def _either_in_sight(
    poses: list[FloatArray], predicted: FloatArray, maps: MapSource, sight_range: float
) -> bool:
    """Whether either robot would have the other in plain sight (closer than
    ``sight_range``, m), each judged on its own map, given robot 1's ``predicted`` pose in
    robot 0's body frame."""
    return in_plain_sight(poses[0], predicted, maps(0), sight_range=sight_range) or (
        in_plain_sight(poses[1], inverse(predicted), maps(1), sight_range=sight_range)
    )
