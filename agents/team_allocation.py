"""The team's allocation role: the frontiers split between the robots of the common frame.

A role of :class:`agents.team.TeamCoordinator` (design §6). While robot 0 has teammates in
its frame, :meth:`Allocation.act` is the team's step for everyone: the robots of the
common frame explore the merged map (:attr:`TeamCoordinator.views`), each told its
teammates' positions and targets as it last received them (dropped after
``teammate_memory`` steps without the link); two robots heading for one frontier, the
later one yields (its policy's optional ``request_replan``). A policy with a ``target``
of its own chooses its frontier itself; one without is assigned a frontier of the merged
map every ``replan_interval`` steps (:func:`~agents.explorer.team_frontier_goals`), as
its context's ``goal``. The robots outside the common frame act alone.

Interface: :meth:`~Allocation.act`, :meth:`~Allocation.target_of`. State it owns: what
each robot last received of each teammate, the frontiers assigned and when.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from agents.explorer import team_frontier_goals
from agents.policy import PolicyContext
from agents.team_config import FloatArray, MapSource
from mrslam_env.geometry import compose

if TYPE_CHECKING:
    from agents.team import TeamCoordinator

__all__ = ["Allocation", "as_points"]


class Allocation:
    """Coordinated exploration of ``team``'s common frame (module notes)."""

    def __init__(self, team: TeamCoordinator) -> None:
        self.team = team
        n = team.n_robots
        self.shared: dict[tuple[int, int], tuple[FloatArray, FloatArray | None, int]] = {}
        """``(i, j)``: robot j's position and target in the common frame as robot i last
        received them (coordinated exploration), and the step it received them; dropped
        after ``teammate_memory`` steps."""
        self._assigned: list[FloatArray | None] = [None] * n
        """Per robot whose policy has no ``target``: the frontier the team assigned it
        while coordinating (its context's ``goal``)."""
        self._last_assignment = -(10**9)

    def act(self, observations: list[dict[str, Any]], maps: MapSource) -> list[NDArray[np.float32]]:
        """Actions for all robots while robot 0 has teammates in its frame: the robots of
        the common frame act on their merged views, knowing their teammates' positions and
        targets as last received (the later of two heading for one frontier yields); the
        others act alone (:meth:`TeamCoordinator.act_alone`)."""
        team = self.team
        members = team.members
        poses = [
            pose if team.roots[i] != 0 or i == 0 else compose(team.frames[i], pose)
            for i, pose in enumerate(team._poses)
        ]
        self._assign_frontiers(members, poses)
        actions = []
        for i, policy in enumerate(team.policies):
            if team.roots[i] != 0:
                actions.append(team.act_alone(i, observations[i], maps(i)))
                continue
            # In turn, so that a robot sees the targets the robots before it pick on this
            # very step; a teammate's pose and target are known only as last received.
            memory = team.config.teammate_memory
            for j in members:
                if j != i and team._reach[i, j]:
                    self.shared[(i, j)] = (poses[j][:2].copy(), self.target_of(j), team.step)
                elif (
                    memory and (i, j) in self.shared and team.step - self.shared[(i, j)][2] > memory
                ):
                    del self.shared[(i, j)]  # too old to trust
            known = [(j, *self.shared[(i, j)][:2]) for j in members if (i, j) in self.shared]
            mine = self.target_of(i)
            replan = getattr(policy, "request_replan", None)
            radius = getattr(policy, "shared_target_radius", team.config.explorer.separation / 4)
            if (
                replan is not None
                and mine is not None
                and any(
                    j < i and target is not None and np.hypot(*(mine - target)) < radius
                    for j, _, target in known
                )
            ):
                replan()  # two robots heading for one frontier: the later yields
            view = team.views[i]
            assert view is not None
            if team._on_goal[i]:
                actions.append(team.explorers[i].act(observations[i], view, pose_in_map=poses[i]))
                continue
            context = PolicyContext(
                robot=i,
                step=team.step,
                map=view,
                pose=poses[i],
                own_map=maps(i),
                in_common_frame=True,
                teammates=as_points([position for _, position, _ in known]),
                teammate_targets=as_points([t for _, _, t in known if t is not None]),
                goal=self._assigned[i],
                common_from_own=team.frames[i].copy(),
            )
            actions.append(policy.act(observations[i], context))
        return actions

    def target_of(self, robot: int) -> FloatArray | None:
        """Where ``robot`` heads in the common frame: its policy's ``target`` when it has
        one, else the frontier the team assigned it."""
        team = self.team
        policy = team.policies[robot]
        if hasattr(policy, "target"):
            target = policy.target
            return None if target is None else np.asarray(target, dtype=np.float64)[:2]
        return self._assigned[robot]

    def _assign_frontiers(self, members: list[int], poses: list[FloatArray]) -> None:
        """Every ``replan_interval`` steps, the frontiers of the merged map split between
        the robots of the common frame (:func:`~agents.explorer.team_frontier_goals`), for
        the policies without a ``target`` of their own (their context's ``goal``)."""
        team = self.team
        chooses = [hasattr(team.policies[i], "target") for i in members]
        if all(chooses):
            return
        if team.step - self._last_assignment < team.config.explorer.replan_interval:
            return
        self._last_assignment = team.step
        assert team.merged_map is not None
        positions = np.array([poses[i] for i in members])
        goals, _ = team_frontier_goals(team.merged_map, positions, team.config.explorer)
        for i, own_choice, goal in zip(members, chooses, goals, strict=True):
            self._assigned[i] = None if own_choice or not np.all(np.isfinite(goal)) else goal


def as_points(points: Any) -> FloatArray:
    """``points`` as a (K, 2) float array (None: empty)."""
    if points is None:
        return np.empty((0, 2))
    return np.asarray(points, dtype=np.float64).reshape(-1, 2)
