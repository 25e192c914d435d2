"""The team's state machine (the table in :mod:`agents.team`'s notes and docs/design.md):
every transition the table states happens in the code, in scripted steps.

The robots stand in one known room, every map the same and in one frame (the true
relative pose is the identity); the observations (poses, peer sightings, links) are
scripted, the merge's answer is injected where it matters, and the policies stand still.
A coordinator that notes every state it enters gives the sequence of states, the transient
``hypothesis_generation`` included (it is left within the step it is entered).
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from agents.team import TeamConfig, TeamCoordinator, TeamState, _row
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.merge.pipeline import MergeInputError

N = TeamState.NO_INTERACTION
G = TeamState.HYPOTHESIS_GENERATION
V = TeamState.HYPOTHESIS_VERIFICATION
C = TeamState.COORDINATED_EXPLORATION

IDENTITY = np.zeros(3)


def room() -> GridMap:
    """14 m x 10 m at 0.1 m, all known: free inside a wall one cell thick."""
    cells = np.full((100, 140), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    return GridMap(cells=cells, resolution=0.1)


ROOM = room()


def maps(robot: int) -> GridMap:
    return ROOM


class Trail(TeamCoordinator):
    """A coordinator that notes every state it enters, in order."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        object.__setattr__(self, "trail", [])
        super().__init__(*args, **kwargs)

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "state":
            self.trail.append(value)
        super().__setattr__(name, value)


class _Still:
    """A policy that stands still."""

    def reset(self) -> None:
        pass

    def act(self, observation: dict[str, Any], context: Any) -> np.ndarray:
        return np.zeros(2, dtype=np.float32)


def team_of(n: int = 2, **config: Any) -> Trail:
    return Trail(
        TeamConfig(**config),
        rng=np.random.default_rng(0),
        n_robots=n,
        policy_factory=lambda env, rng: _Still(),
    )


def observe(
    poses: list[tuple[float, float, float]],
    seen: set[tuple[int, int]],
    links: set[tuple[int, int]],
) -> list[dict[str, Any]]:
    """The robots' observations: ``poses`` (one frame for all), robot i seeing robot j
    for each ``(i, j)`` in ``seen`` (exactly: no noise), the links in ``links`` up."""
    n = len(poses)
    out = []
    for i in range(n):
        peer, comm = np.zeros((n - 1, 4)), np.zeros(n - 1)
        for j in range(n):
            if j == i:
                continue
            if (i, j) in seen:
                x, y, theta = compose(inverse(np.array(poses[i])), np.array(poses[j]))
                peer[_row(i, j)] = [1.0, math.hypot(x, y), math.atan2(y, x), theta]
            comm[_row(i, j)] = float((i, j) in links or (j, i) in links)
        out.append({"pose": np.array(poses[i]), "scan": np.zeros(1), "peer": peer, "comm": comm})
    return out


def merge_answers(
    monkeypatch: pytest.MonkeyPatch, hypotheses: list[np.ndarray], decided: Any = None
) -> None:
    """The merge (where the proposals role looks it up) answers ``hypotheses``, all
    confident, with ``decided`` as its own answer."""
    answers = [SimpleNamespace(map1_from_map2=h, confident=True) for h in hypotheses]
    result = SimpleNamespace(transform=decided, hypotheses=answers)
    monkeypatch.setattr("agents.team_proposals.merge_maps", lambda *args, **kwargs: result)


FACING = [(3.0, 2.0, 0.0), (5.0, 2.0, math.pi)]
"""Two robots 2 m apart, facing each other: each in the other's sight."""
BOTH = {(0, 1), (1, 0)}


def walk(poses: list[tuple[float, float, float]], k: int) -> list[tuple[float, float, float]]:
    """``poses`` moved ``0.5 k`` m along y: the sightings keep matching while they move."""
    return [(x, y + 0.5 * k, theta) for x, y, theta in poses]


def texts(team: TeamCoordinator) -> list[str]:
    return [d.text for d in team.pop_decisions()]


def test_the_team_starts_without_interaction() -> None:
    team = team_of()
    assert team.trail == [N] and team.state is N


def test_a_merge_with_nothing_to_test_rests_within_the_step(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # no_interaction -> hypothesis_generation (ripe maps) -> no_interaction (no hypothesis).
    team = team_of(min_map_area=0.0, sighting_count=0)
    merge_answers(monkeypatch, [])
    team.act(observe(FACING, set(), {(0, 1)}), maps)
    assert team.trail == [N, G, N]
    assert any("no hypothesis worth a rendezvous" in d for d in texts(team))
    # Maps that have not grown since: not ripe, no merge, no transition.
    team.act(observe(FACING, set(), {(0, 1)}), maps)
    assert team.trail == [N, G, N]


def test_a_merge_that_fails_rests_within_the_step(monkeypatch: pytest.MonkeyPatch) -> None:
    def fails(*args: Any, **kwargs: Any) -> Any:
        raise MergeInputError("no overlap")

    team = team_of(min_map_area=0.0, sighting_count=0)
    monkeypatch.setattr("agents.team_proposals.merge_maps", fails)
    team.act(observe(FACING, set(), {(0, 1)}), maps)
    assert team.trail == [N, G, N]
    assert any("no hypotheses: no overlap" in d for d in texts(team))


def test_maps_too_small_or_no_link_never_leave_no_interaction() -> None:
    team = team_of(min_map_area=1e9, sighting_count=0)
    team.act(observe(FACING, set(), {(0, 1)}), maps)  # the maps not ripe
    team.act(observe(FACING, BOTH, set()), maps)  # no link: nothing exchanged
    assert team.trail == [N]


def test_a_hypothesis_is_verified_then_accepted_into_coordinated_exploration(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # no_interaction -> hypothesis_generation -> hypothesis_verification (seen where
    # predicted, where they stand) -> coordinated_exploration (confirmed while moving).
    team = team_of(min_map_area=0.0, sighting_count=0)
    merge_answers(monkeypatch, [IDENTITY], decided=IDENTITY)
    team.act(observe(FACING, BOTH, {(0, 1)}), maps)
    assert team.trail == [N, G, V] and team.rendezvous is not None and team.rendezvous.in_place
    for k in (1, 2):
        team.act(observe(walk(FACING, k), BOTH, {(0, 1)}), maps)
    decisions = texts(team)
    assert team.trail == [N, G, V, C], decisions
    assert any("hypothesis #0 accepted" in d for d in decisions), decisions
    assert team.members == [0, 1] and team.rendezvous is None
    # Two robots in one frame: nobody left to merge with; coordinated for good.
    for k in (3, 4):
        team.act(observe(walk(FACING, k), BOTH, {(0, 1)}), maps)
    assert team.trail == [N, G, V, C]


def test_a_rejected_hypothesis_passes_verification_to_the_next_then_the_team_rests(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Two rivals, neither the merge's own answer: each waits for a chance meeting. Robot 1
    # is seen 2 m ahead, not where either puts it: each is rejected in turn.
    team = team_of(min_map_area=0.0, sighting_count=0)
    first, second = np.array([4.0, 0.0, 0.0]), np.array([4.0, 5.0, 0.0])
    merge_answers(monkeypatch, [first, second])
    team.act(observe(FACING, BOTH, {(0, 1)}), maps)
    # hypothesis_generation -> verification (#0 waits) -> verification (#0 rejected, #1).
    assert team.trail == [N, G, V, V], texts(team)
    assert team.rendezvous is not None and team.rendezvous.hypothesis is second
    team.act(observe(FACING, BOTH, {(0, 1)}), maps)
    decisions = texts(team)
    assert team.trail == [N, G, V, V, N], decisions
    assert sum("rejected: robot_0 sees robot_1" in d for d in decisions) == 2, decisions
    assert any("all hypotheses rejected" in d for d in decisions), decisions


def test_every_hypothesis_skipped_rests_within_the_step(monkeypatch: pytest.MonkeyPatch) -> None:
    # The merge's own answer, not in sight: a drive, but no meeting point within reach.
    team = team_of(min_map_area=0.0, sighting_count=0)
    merge_answers(monkeypatch, [np.array([4.0, 0.0, 0.0])], decided=np.array([4.0, 0.0, 0.0]))
    team.verification.meeting_point = lambda hypothesis, maps, avoid=None: None  # type: ignore[method-assign]
    team.act(observe(FACING, set(), {(0, 1)}), maps)
    assert team.trail == [N, G, N]
    assert any("no meeting point reachable by both" in d for d in texts(team))


def test_a_drive_to_a_meeting_point_is_verification(monkeypatch: pytest.MonkeyPatch) -> None:
    team = team_of(min_map_area=0.0, sighting_count=0)
    hypothesis = np.array([4.0, 0.0, 0.0])
    merge_answers(monkeypatch, [hypothesis], decided=hypothesis)
    team.verification.meeting_point = (  # type: ignore[method-assign]
        lambda hypothesis, maps, avoid=None: (np.array([6.0, 2.0]), 3.0)
    )
    team.act(observe(FACING, set(), {(0, 1)}), maps)
    assert team.trail == [N, G, V]
    assert team.rendezvous is not None and not team.rendezvous.in_place
    assert all(team._on_goal)


def test_a_merge_beside_a_waiting_hypothesis_returns_to_verification(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A hypothesis waits (a rival open beside it, nobody in sight); the maps are merged
    # again: hypothesis_generation, whose rest is undone, back to verification.
    team = team_of(min_map_area=0.0, sighting_count=0)
    merge_answers(monkeypatch, [np.array([4.0, 0.0, 0.0]), np.array([4.0, 5.0, 0.0])])
    team.act(observe(FACING, set(), {(0, 1)}), maps)
    assert team.trail == [N, G, V]
    waiting = team.rendezvous
    assert waiting is not None and waiting.waits
    merge_answers(monkeypatch, [])
    team.proposals.retry_area = {}  # ripe again
    team.act(observe(FACING, set(), {(0, 1)}), maps)
    assert team.trail == [N, G, V, G, N, V], texts(team)
    assert team.rendezvous is waiting and team.state is V


def test_sightings_put_a_hypothesis_to_verification() -> None:
    # no_interaction -> hypothesis_verification directly: no merge (maps never ripe).
    team = team_of(min_map_area=1e9, sighting_count=2)
    team.act(observe(FACING, BOTH, {(0, 1)}), maps)
    assert team.trail == [N]
    team.act(observe(FACING, BOTH, {(0, 1)}), maps)
    decisions = texts(team)
    assert team.trail == [N, V], decisions
    assert team.rendezvous is not None and team.rendezvous.formed_at is not None
    assert any("to verify by sightings" in d for d in decisions), decisions


def test_given_transforms_coordinate_at_once() -> None:
    team = team_of(n=3)
    team.start_coordinated(np.zeros((2, 3)), maps)
    assert team.trail == [N, C] and team.members == [0, 1, 2]


def test_a_join_outside_robot_0s_group_rests_without_interaction(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Robots 1 and 2 meet, robot 0 out of reach: their groups join, robot 0 still alone.
    team = team_of(n=3, min_map_area=0.0, sighting_count=0)
    merge_answers(monkeypatch, [IDENTITY], decided=IDENTITY)
    poses = [(1.0, 1.0, 0.0), (8.0, 2.0, 0.0), (10.0, 2.0, math.pi)]
    seen = {(1, 2), (2, 1)}
    for k in range(3):
        team.act(observe(walk(poses, k), seen, {(1, 2)}), maps)
    assert team.trail == [N, G, V, N], texts(team)
    assert team.roots == [0, 1, 1] and team.members == [0]


def test_coordinated_exploration_merges_with_another_group_and_comes_back(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Robots 0 and 1 join; robot 2, out of reach until then, comes into link: its group
    # and robot 0's are merged (nothing to test here) and the team coordinates on.
    team = team_of(n=3, min_map_area=0.0, sighting_count=0)
    merge_answers(monkeypatch, [IDENTITY], decided=IDENTITY)
    poses = [*FACING, (12.0, 8.0, 0.0)]
    for k in range(3):
        team.act(observe(walk(poses, k), BOTH, {(0, 1)}), maps)
    assert team.trail == [N, G, V, C], texts(team)
    merge_answers(monkeypatch, [])
    team.act(observe(walk(poses, 3), BOTH, {(0, 1), (0, 2), (1, 2)}), maps)
    assert team.trail == [N, G, V, C, G, C], texts(team)
    assert team.pair == (0, 2) and team.members == [0, 1]
