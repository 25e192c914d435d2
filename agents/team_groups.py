"""The team's groups role: groups of joined robots, joins, refinement, the fused map.

A role of :class:`agents.team.TeamCoordinator` (design §6, teams of N robots). Each robot
belongs to a group, the robots verified transforms connect it to, held in the frame of
the group's lowest robot (its root); robot 0's group is the common frame. The group
structure is the coordinator's public state, read by every role and by the recorder:
:attr:`TeamCoordinator.roots`, :attr:`~TeamCoordinator.frames` (``root_from_map``),
:attr:`~TeamCoordinator.verified`, :attr:`~TeamCoordinator.step_joined` and
:attr:`~TeamCoordinator.views` (the merged maps the robots of the common frame explore).
This role is its only writer:

- :meth:`Groups.join_pair` (a hypothesis the verification role accepted): side 1's
  group joins side 0's, its transforms composed with the accepted one; the alignment is
  kept as an edge for :meth:`Groups.refine_group`, which refines a group of three or
  more jointly (:func:`~mrslam_env.merge.graph.refine_jointly`) instead of only chaining;
- :meth:`Groups.give`: known transforms (the oracle,
  :meth:`TeamCoordinator.start_coordinated`);
- :meth:`Groups.keep_merged_map`, every ``merged_map_every`` steps while coordinating:
  the maps exchanged between robots that can talk, the transforms re-refined on the grown
  maps every ``refine_every`` steps, the views fused again (:meth:`Groups.fuse`).

Interface: those, :meth:`~Groups.group_map` (a group's map in its root's frame, what a
merge of two groups merges) and :meth:`~Groups.exchange_and_fuse`. State it owns: the maps
each robot received from each other, the join edges, the cached fusions of groups outside
the common frame, each robot's place at its join and when the views and the transforms
were last refreshed.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from agents.team_config import FloatArray, MapSource, TeamState
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.fuse import fuse_all, fuse_maps, resample_map, warp_map
from mrslam_env.merge.graph import GraphEdge, alignment_edge, refine_jointly
from mrslam_env.merge.pipeline import refine_transform

if TYPE_CHECKING:
    from agents.team import TeamCoordinator

__all__ = ["Groups"]


class Groups:
    """Joins, refines and fuses ``team``'s groups (module notes)."""

    def __init__(self, team: TeamCoordinator) -> None:
        self.team = team
        n = team.n_robots
        self.verified_at: list[FloatArray] = [np.zeros(2) for _ in range(n)]
        """Per robot, its position (own map) when the hypothesis that joined it was
        accepted."""
        self.given = False
        """The transforms were given (:meth:`give`): known, never re-refined."""
        self.received: dict[tuple[int, int], GridMap] = {}
        """``(i, j)``: robot j's map as robot i last received it (while they could talk,
        directly or through teammates)."""
        self._last_merge_step = -(10**9)
        self.last_refine_step = 0
        self._group_maps: dict[int, tuple[tuple[int, ...], int, GridMap]] = {}
        """Per group root (groups outside the common frame): its members, the step and
        the fusion of their maps in its frame."""
        self.join_edges: list[GraphEdge] = []
        """The alignments that joined two groups (nodes: the groups' roots then), each
        refined on the two groups' maps: edges of the joint refinement."""

    def group_map(self, robot: int, maps: MapSource) -> GridMap:
        """The map of ``robot``'s group in its root's frame: the merged map it explores in
        the common frame; its own map when alone; else its group's maps fused."""
        team = self.team
        view = team.views[robot]
        if team.roots[robot] == 0 and view is not None:
            return view
        root = team.roots[robot]
        group = [k for k in range(team.n_robots) if k != root and team.roots[k] == root]
        if not group:
            return maps(root)
        # A group's fusion is remade every ``merged_map_every`` steps, as the views are.
        made = self._group_maps.get(root)
        fresh = made is not None and team.step - made[1] < team.config.merged_map_every
        if made is not None and fresh and made[0] == tuple(group):
            return made[2]
        grid = fuse_all(maps(root), ((maps(k), team.frames[k]) for k in group))
        self._group_maps[root] = (tuple(group), team.step, grid)
        return grid

    def join_pair(
        self,
        transform: FloatArray,
        verified: FloatArray,
        at: FloatArray,
        m0: GridMap,
        m1: GridMap,
    ) -> None:
        """The current pair's groups joined by an accepted hypothesis: ``transform``
        (refined; ``verified`` before refinement; ``at``: where side 1's robot was, in its
        root's frame), aligned on the sides' maps ``m0`` and ``m1`` (an edge of the joint
        refinement), joins side 1's group to side 0's (:meth:`join`)."""
        team = self.team
        root0, root1 = team._pair_roots()
        joined = alignment_edge(root0, root1, m0, m1, transform)
        if joined is not None:
            self.join_edges.append(joined)
        self.join(transform, verified, at)
        self.last_refine_step = team.step

    def join(self, transform: FloatArray, verified: FloatArray, at: FloatArray) -> None:
        """The pair's groups become one: side 1's group, placed by ``transform`` (refined;
        ``verified`` before refinement; ``at``: where side 1's robot was, in its root's
        frame), joins side 0's; robots new in the common frame explore the merged map."""
        team = self.team
        root0, root1 = team._pair_roots()
        before = [frame.copy() for frame in team.frames]
        joining = [k for k in range(team.n_robots) if team.roots[k] == root1]
        for k in joining:
            old = team.frames[k]
            team.frames[k] = compose(transform, old) if k != root1 else transform.copy()
            team.verified[k] = compose(verified, old) if k != root1 else verified.copy()
            self.verified_at[k] = transform_points(inverse(old), at[None, :])[0]
            team.roots[k] = root0
        self.refine_group(root0)
        self._group_maps.pop(root0, None)
        self._group_maps.pop(root1, None)
        for k in range(team.n_robots):
            if team.roots[k] != 0:
                continue
            if k in joining:
                team.step_joined[k] = team.step
                # Robot k now explores the merged map, in robot 0's frame.
                team._change_frame(k, team.frames[k])
            elif k != 0 and not np.array_equal(team.frames[k], before[k]):
                team._change_frame(k, compose(team.frames[k], inverse(before[k])))

    def refine_group(self, root: int) -> None:
        """With three robots or more in ``root``'s group: every member's transform refined
        jointly (:func:`~mrslam_env.merge.graph.refine_jointly` on the members' own maps,
        the root fixed) instead of chained. Kept only when every member stays within the
        rendezvous tolerances of what was verified for it (:meth:`Verification.within_verified
        <agents.team_verification.Verification.within_verified>`)."""
        team = self.team
        group = [k for k in range(team.n_robots) if team.roots[k] == root]
        if len(group) < 3 or team.config.joint is None:
            return
        own = [team._maps(k) for k in group]
        estimate = [team.frames[k] for k in group]
        node = {k: n for n, k in enumerate(group)}
        known = [
            replace(e, i=node[e.i], j=node[e.j])
            for e in self.join_edges
            if e.i in node and e.j in node
        ]
        result = refine_jointly(
            own,
            estimate,
            team.config.joint,
            rng=team.rng,
            fixed=group.index(root),
            known_edges=known,
        )
        pairs = result.edges[: len(result.edges) - len(known)]
        names = ", ".join(f"robot_{group[e.i]}-robot_{group[e.j]}" for e in pairs)
        for k, solved in zip(group, result.transforms, strict=True):
            verified = team.verified[k]
            if (
                k != root
                and verified is not None
                and not team.verification.within_verified(solved, verified, self.verified_at[k])
            ):
                team._decide(
                    f"joint refinement ({names}) left what was verified for robot_{k}; "
                    "kept the chained transforms"
                )
                return
        moved = max(
            float(np.hypot(*(solved[:2] - team.frames[k][:2])))
            for k, solved in zip(group, result.transforms, strict=True)
        )
        for k, solved in zip(group, result.transforms, strict=True):
            if k != root:
                team.frames[k] = solved
        team._decide(
            f"transforms of robot_{root}'s group of {len(group)} refined jointly on "
            f"{len(pairs)} overlapping pairs ({names}) and {len(known)} joins; "
            f"moved up to {moved:.2f} m"
        )

    def give(self, transforms: FloatArray) -> None:
        """Known transforms (``map0_from_map_i``, (N-1, 3)): every robot joins the common
        frame now, never to be re-refined."""
        team = self.team
        for k in range(1, team.n_robots):
            team.frames[k] = transforms[k - 1].copy()
            team.verified[k] = transforms[k - 1].copy()
            team.roots[k] = 0
            team.step_joined[k] = team.step
            self.verified_at[k] = team._poses[k][:2].copy()
            team._change_frame(k, team.frames[k])
        self.given = True

    def exchange_and_fuse(self, *, everyone: bool) -> None:
        """At a join: the robots of the common frame that can talk (``everyone``: all of
        them) hold each other's current maps, and their merged views are made now."""
        team = self.team
        maps = team._maps
        members = team.members
        for i in members:
            for j in members:
                if i != j and (everyone or team._reach[i, j] or {i, j} == set(team.pair)):
                    self.received[(i, j)] = maps(j)
        shared = everyone or bool(team._reach[np.ix_(members, members)].all())
        self.fuse(maps, shared=shared)

    def keep_merged_map(self, maps: MapSource) -> None:
        """Every ``merged_map_every`` steps: the maps exchanged between the robots of the
        common frame that can talk (directly or through teammates), the views refused."""
        team = self.team
        if team.step - self._last_merge_step < team.config.merged_map_every:
            return
        members = team.members
        for i in members:
            for j in members:
                if i != j and team._reach[i, j]:
                    self.received[(i, j)] = maps(j)
        if (
            team.config.refine_every
            and not self.given
            and team.state is TeamState.COORDINATED_EXPLORATION
            and team.step - self.last_refine_step >= team.config.refine_every
            and self._refine_again(maps)
        ):
            self.last_refine_step = team.step
        self.fuse(maps, shared=bool(team._reach[np.ix_(members, members)].all()))

    def _refine_again(self, maps: MapSource) -> bool:
        """The common frame's transforms refined again on the grown maps
        (``TeamConfig.refine_every``), each kept only within the rendezvous tolerances
        of what was verified for it: a group of three or more jointly
        (:meth:`refine_group`, once every member can reach every other), else each
        member robot 0 can reach against robot 0's map. False when nothing could be
        refined for want of the link: the caller tries again at its next tick instead of
        a whole period later."""
        team = self.team
        members = team.members
        if len(members) >= 3 and team.config.joint is not None:
            if not team._reach[np.ix_(members, members)].all():
                return False
            before = {k: team.frames[k] for k in members[1:]}
            self.refine_group(0)
            for k, old in before.items():
                if team.frames[k] is not old:
                    team._change_frame(k, compose(team.frames[k], inverse(old)))
            return True
        refined_any = False
        for k in members[1:]:
            verified = team.verified[k]
            if not team._reach[0, k] or verified is None:
                continue
            refined_any = True
            refined, psi, agreement = refine_transform(
                maps(0), maps(k), team.frames[k], team.config.merge, rng=team.rng
            )
            if not team.verification.within_verified(refined, verified, self.verified_at[k]):
                team._decide(
                    f"re-refinement of robot_{k}'s transform left what the sighting "
                    "verified; kept the transform"
                )
                continue
            at = self.verified_at[k][None, :]
            shift = transform_points(refined, at) - transform_points(team.frames[k], at)
            turn = math.remainder(float(refined[2] - team.frames[k][2]), 2 * math.pi)
            team._decide(
                f"robot_{k}'s transform re-refined on the grown maps: psi {psi:.3f}, "
                f"acceptance index {agreement.index:.3f}; the meeting place moved "
                f"{float(np.hypot(*shift[0])):.3f} m, turned {math.degrees(turn):+.2f}°"
            )
            team._change_frame(k, compose(refined, inverse(team.frames[k])))
            team.frames[k] = refined
        return refined_any

    def fuse(self, maps: MapSource, *, shared: bool) -> None:
        """Refresh the views of the robots of the common frame: each robot's own map,
        current, fused with the others' as it holds them, in robot 0's frame. ``shared``:
        all of them hold each other's current maps, so the views are one fusion."""
        team = self.team
        members = team.members
        owners = members[:1] if shared else members
        views: dict[int, GridMap] = {}
        for i in owners:

            def held(j: int, i: int = i) -> GridMap | None:
                return maps(j) if j == i else self.received.get((i, j))

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
                    view = warp_map(other, team.frames[j])
                else:
                    view = fuse_maps(view, other, team.frames[j])
            assert view is not None  # robot i holds its own map
            views[i] = view
        team.views = [
            (views[owners[0]] if shared else views[i]) if i in members else None
            for i in range(team.n_robots)
        ]
        self._last_merge_step = team.step
