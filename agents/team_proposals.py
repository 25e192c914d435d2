"""The team's proposals role: merge attempts and sightings, turned into hypotheses.

A role of :class:`agents.team.TeamCoordinator` (design §6). A hypothesis is a relative
pose of two groups' frames (``side0_from_side1``) the team may put to verification; it
comes from one of two places:

- **a merge** (:meth:`Proposals.generate`): two robots of different groups that can talk
  exchange their groups' maps once both are ripe (``min_map_area``, ``regrow_factor``);
  :func:`~mrslam_env.merge.pipeline.merge_maps` ranks placements, the confident ones not
  one answer with a better or a rejected one (:func:`distinct_hypotheses`) and not refuted
  by the radio become :attr:`TeamCoordinator.hypotheses`; rivals the merge left open wait
  (:attr:`Proposals.undecided`);
- **sightings** (:meth:`Proposals.maybe_sighting`): two robots that saw each other on
  ``sighting_count`` steps give the relative pose directly; averaged, refined on the maps
  and checked where they met (:meth:`Proposals.form_from_sightings`), it is one
  hypothesis that waits for a later chance meeting.

Either way the hypotheses go on to the verification role
(:meth:`agents.team_verification.Verification.start` for a merge's; a sighting's is
handed over waiting, :meth:`TeamCoordinator._verifying`). While one waits, the maps are
still merged as they grow (:meth:`Proposals.generate_beside_sightings`).

Interface: :meth:`~Proposals.maybe_generate`, :meth:`~Proposals.maybe_sighting` and
:meth:`~Proposals.generate_beside_sightings` (the coordinator's step),
:meth:`~Proposals.is_decided` (whether a hypothesis is driven to at once),
:meth:`~Proposals.is_gathering` and :meth:`~Proposals.pop_merge_attempts` (for
recording). State it owns: the area each pair's maps must reach before the next attempt,
the attempts, the recent sightings per pair, the waiting rivals and a generator of its own
for refining sightings' hypotheses.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from agents.rendezvous import sighting_pose
from agents.team_config import FloatArray, MapSource, TeamState
from agents.team_contact import peer_row
from agents.team_verification import _Rendezvous
from mrslam_env.geometry import compose, inverse, mean_pose
from mrslam_env.gridmap import UNKNOWN, GridMap
from mrslam_env.merge.decide import check_conflict_fraction
from mrslam_env.merge.dissimilarity import acceptance_index
from mrslam_env.merge.fuse import at_resolution
from mrslam_env.merge.pipeline import (
    MergeConfig,
    MergeInputError,
    MergeResult,
    merge_maps,
    refine_transform,
    same_answer,
)

if TYPE_CHECKING:
    from agents.team import TeamCoordinator

__all__ = ["MergeAttempt", "Proposals", "distinct_hypotheses", "window"]


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


class Proposals:
    """Hypotheses for ``team``'s current pair, from merges and from sightings (module
    notes); ``sighting_rng`` refines the sightings' hypotheses, so that one formed (and
    perhaps set aside) does not shift the draws of the merges and explorers."""

    def __init__(self, team: TeamCoordinator, *, sighting_rng: np.random.Generator) -> None:
        self.team = team
        self._sighting_rng = sighting_rng
        self.retry_area: dict[tuple[int, int], float] = {}
        """Per pair of group roots: the area the maps must know before the next attempt."""
        self._merges_tried = 0
        self._merge_attempts: list[MergeAttempt] = []
        self._sightings: dict[tuple[int, int], deque[tuple[int, FloatArray]]] = {}
        """Per pair of robots (side 0, side 1), the recent steps on which they saw each
        other, each with the relative pose of their groups' frames it gives."""
        self.undecided: list[FloatArray] = []
        """The last merge's hypotheses that wait (:attr:`TeamConfig.undecided_wait`): its
        confident answers other than its own ``merged`` one, when it left a rival open."""

    def pop_merge_attempts(self) -> list[MergeAttempt]:
        """The merge attempts since the last call (empty unless ``config.keep_merges``)."""
        attempts, self._merge_attempts = self._merge_attempts, []
        return attempts

    def is_gathering(self) -> bool:
        """Whether two robots saw each other lately enough that the sightings may still
        become a hypothesis (within ``2 * sighting_count`` steps)."""
        team = self.team
        span = 2 * team.config.sighting_count
        return any(t and team.step - t[-1][0] < span for t in self._sightings.values())

    def is_decided(self, hypothesis: FloatArray) -> bool:
        """Whether ``hypothesis`` is not one the last merge left waiting (a confident
        answer other than its own ``merged`` one, beside an open rival)."""
        return not any(hypothesis is undecided for undecided in self.undecided)

    # --- 1 -> 2: hypothesis generation ------------------------------------------------------

    def candidate_pairs(self) -> list[tuple[int, int]]:
        """Pairs of robots of two groups that can talk now, those that bring a robot into
        the common frame first."""
        team = self.team
        n = team.n_robots
        pairs = [
            (a, b)
            for a in range(n)
            for b in range(a + 1, n)
            if team._links[a, b] and team.roots[a] != team.roots[b]
        ]
        return sorted(pairs, key=lambda p: (min(team.roots[p[0]], team.roots[p[1]]) != 0, p))

    def maybe_generate(self, observations: list[dict[str, Any]], maps: MapSource) -> None:
        """Merge the maps of the first candidate pair whose maps are ripe for it."""
        team = self.team
        for a, b in self.candidate_pairs():
            team._set_pair(a, b)
            team._observe_pair(observations)
            if self.generate(team._side_maps(maps)):
                return

    def generate(self, sides: MapSource) -> bool:
        """Merge the current pair's maps; False when they are not ripe for it."""
        team = self.team
        config = team.config
        m0, m1 = sides(0), sides(1)
        areas = [np.count_nonzero(~m.unknown) * m.resolution**2 for m in (m0, m1)]
        key = team._pair_roots()
        if min(areas) < config.min_map_area or sum(areas) < self.retry_area.get(key, 0.0):
            return False
        a, b = team.pair
        team._generating()
        names = "" if team.n_robots == 2 else f" (robot_{a} and robot_{b})"
        team._decide(
            f"comm up: maps exchanged{names} ({areas[0]:.0f} m² and {areas[1]:.0f} m²), "
            "generating hypotheses by virtual robot motion"
        )
        self.retry_area[key] = sum(areas) * config.regrow_factor
        try:
            result = merge_maps(m0, m1, config.merge, rng=team.rng, trace=config.keep_merges)
        except MergeInputError as error:
            team._decide(f"no hypotheses: {error}")
            team._rest()
            return True
        self._merges_tried += 1
        if config.keep_merges:
            self._merge_attempts.append(
                MergeAttempt(
                    number=self._merges_tried,
                    step=team.step,
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
            team.rejected,
            pivot,
            config.merge,
        )
        fresh = [h for h in fresh if not team.verification.radio_rejects(h, "from the merge")]
        team.hypotheses = fresh[: config.max_rendezvous]
        sources = {
            id(h.map1_from_map2): getattr(h, "proposed_by", "virtual robot")
            for h in result.hypotheses
        }
        team.hypothesis_sources = [sources.get(id(h), "virtual robot") for h in team.hypotheses]
        team.hypotheses_attempt = self._merges_tried
        # Rivals: one meeting cannot tell which of two open answers is right, more map
        # may; the merge's own answer (if it gave one) is still driven to at once.
        rivals = len(fresh) > 1
        self.undecided = [
            h
            for h in team.hypotheses
            if rivals and (decided is None or not same_answer(h, decided, pivot, config.merge))
        ]
        if not team.hypotheses:
            team._decide("no hypothesis worth a rendezvous; exploring on, retry when maps grow")
            team._rest()
            return True
        team._decide(f"{len(team.hypotheses)} hypotheses to verify by rendezvous")
        team.verification.start(0, sides)
        return True

    # --- 1 -> 3: a hypothesis from a chance meeting ---------------------------------------

    def maybe_sighting(self, observations: list[dict[str, Any]], maps: MapSource) -> bool:
        """A hypothesis from a chance meeting (:attr:`TeamConfig.sighting_count`): two
        robots of different groups with the link up that see each other give the relative
        pose of their groups' frames directly, ``T = p0 · s · p1⁻¹``; averaged over
        ``sighting_count`` steps of sightings it is refined and checked on the maps
        (:meth:`form_from_sightings`). True when one was put to verification."""
        team = self.team
        count = team.config.sighting_count
        if not count:
            return False
        for a, b in self.candidate_pairs():
            team._set_pair(a, b)
            side0, side1 = team.pair
            poses = [team.pose_in_root(r, team._poses[r]) for r in team.pair]
            estimates = []
            for me, other in ((side0, side1), (side1, side0)):
                peer = np.asarray(observations[me]["peer"])[peer_row(me, other)]
                if peer[0] < 0.5:
                    continue
                seen = sighting_pose(peer[1], peer[2], peer[3])
                side1_in_side0 = seen if me == side0 else inverse(seen)
                estimates.append(compose(compose(poses[0], side1_in_side0), inverse(poses[1])))
            if not estimates:
                continue
            track = self._sightings.setdefault(team.pair, deque(maxlen=count))
            track.append((team.step, np.array(estimates)))
            if len(track) < count or team.step - track[0][0] >= 2 * count:
                continue
            hypothesis = mean_pose(np.concatenate([e for _, e in track]))
            track.clear()
            team._observe_pair(observations)
            if self.form_from_sightings(hypothesis, team._side_maps(maps), poses):
                return True
        return False

    def form_from_sightings(
        self, hypothesis: FloatArray, sides: MapSource, poses: list[FloatArray]
    ) -> bool:
        """Refine the sightings' ``hypothesis`` on the pair's maps (kept only when the
        refined placement stays within the rendezvous tolerances and the maps do not
        conflict there), check the maps agree at it within the peer sensor's range of
        both robots (the merge's conflict check), and put it to verification: True;
        False when the maps conflict (rejected)."""
        team = self.team
        config = team.config
        verification = team.verification
        m0, m1 = sides(0), sides(1)
        # Checked where the robots met: the sightings vouch for the maps there; far
        # from it, either map's SLAM drift may make even the true placement conflict.
        near0, near1 = (
            window(m, pose[:2], config.peer_range) for m, pose in zip((m0, m1), poses, strict=True)
        )
        names = [f"robot_{r}" for r in team.pair]
        x, y, theta = hypothesis
        team.hypotheses_tested += 1
        team.sighting_hypotheses += 1
        team._note_hypothesis()
        try:
            refined, _, _ = refine_transform(
                m0, m1, hypothesis, config.merge, rng=self._sighting_rng
            )
        except MergeInputError:
            refined = None
        if (
            refined is not None
            and verification.within_verified(refined, hypothesis, poses[1][:2])
            and self.map_check(near0, near1, refined) is None
        ):
            transform, how, conflict = refined, "refined on the maps", None
        else:
            transform, how = hypothesis, "kept as seen"
            conflict = self.map_check(near0, near1, transform)
        seen = (
            f"{names[0]} and {names[1]} saw each other on {config.sighting_count} "
            f"steps: hypothesis x {x:.2f}, y {y:.2f}, theta {theta:.3f}"
        )
        if conflict is not None:
            team._decide(f"{seen}; rejected, the maps conflict there ({conflict})")
            return False
        why = verification.radio_refutes(transform)
        if why is not None:
            team._decide(f"{seen}; rejected by {why}")
            return False
        team.hypotheses = [transform]
        team.hypothesis_sources, team.hypotheses_attempt = ["sighting"], None
        team._verifying(
            _Rendezvous(
                hypothesis=transform,
                index=0,
                meeting_point=poses[0][:2].copy(),
                started=team.step,
                last_match=team.step,
                in_place=True,
                waits=True,
                formed_at=[pose[:2].copy() for pose in poses],
            )
        )
        team._decide(
            f"{seen} ({how}); to verify by sightings after both moved "
            f"{config.sighting_verify_distance:.1f} m"
        )
        return True

    def map_check(self, m0: GridMap, m1: GridMap, transform: FloatArray) -> str | None:
        """Why the maps conflict at ``transform`` (the merge's conflict check, at its
        working resolution), or None."""
        config = self.team.config.merge
        resolution = max(m0.resolution, m1.resolution, config.working_resolution)
        w0, w1 = at_resolution(m0, resolution), at_resolution(m1, resolution)
        agreement = acceptance_index(w0, w1, transform)
        return check_conflict_fraction(agreement, resolution, config)

    # --- while a hypothesis waits ------------------------------------------------------------

    def waiting_on_sightings(self) -> bool:
        """Whether a hypothesis (from sightings, or undecided by the merge) waits,
        unmatched, for a chance meeting (nobody is driven for it yet)."""
        team = self.team
        rendezvous = team.rendezvous
        return (
            team.state is TeamState.HYPOTHESIS_VERIFICATION
            and rendezvous is not None
            and rendezvous.waits
            and rendezvous.in_place
            and rendezvous.first_match is None
        )

    def generate_beside_sightings(self, maps: MapSource) -> None:
        """While a hypothesis waits for a chance meeting, the pair's maps are still
        merged as they grow: the new merge's hypotheses take its place (it is set aside),
        unless the merge gave nothing to drive for, or its first hypothesis waits too and
        the waiting one is from sightings or is the same answer (within the rendezvous
        tolerances where robot 1 is): then it waits on, its wait counted from its start."""
        team = self.team
        waiting, hypotheses = team.rendezvous, team.hypotheses
        sources, attempt = team.hypothesis_sources, team.hypotheses_attempt
        undecided, tested = self.undecided, team.hypotheses_tested
        assert waiting is not None
        if not team._link or not self.generate(team._side_maps(maps)):
            return
        kind = "from sightings" if waiting.formed_at is not None else f"#{waiting.index}"
        new = team.rendezvous
        keep = new is None or (
            new.waits
            and new.first_match is None
            and (
                waiting.formed_at is not None
                or team.verification.within_verified(
                    new.hypothesis, waiting.hypothesis, team._last_poses[1][:2]
                )
            )
        )
        if keep:
            # The new merge's hypotheses are dropped: its rivals and its count with them.
            team.hypotheses = hypotheses
            team.hypothesis_sources, team.hypotheses_attempt = sources, attempt
            self.undecided, team.hypotheses_tested = undecided, tested
            team._verifying(waiting)
            team._decide(f"the hypothesis {kind} waits on for a later meeting")
        else:
            team._decide(f"the hypothesis {kind} is set aside for the merge's")


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
