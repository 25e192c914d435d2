"""Teams of N robots: verified transforms join robots into robot 0's frame (composed along
the graph), any pair can be verified by rendezvous, the robots in the common frame share
one merged map and their frontiers; ``mrslam run --robots N`` and ``bench explore
--robots`` cover N robots."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from merge_fixtures import corridor_maps

from agents.team import (
    TeamConfig,
    TeamCoordinator,
    TeamState,
    _reachable,
    _Rendezvous,
    _row,
)
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import FREE, GridMap
from scenarios.bench.explore import format_explore_table, run_explore_benchmark
from scenarios.cli import main
from scenarios.experiment import MapCache, RunConfig

# Three robots along the office corridor (y 7..9), 5 m apart: 0 faces east, 1 and 2 west.
STARTS = ((4.0, 8.0, 0.0), (9.0, 8.3, np.pi), (14.0, 8.0, np.pi))
TRUTH = [compose(inverse(np.array(STARTS[0])), np.array(s)) for s in STARTS]
"""``map0_from_map_i`` (each robot's map frame is its start pose)."""


def test_links_reach_through_teammates_and_rows_skip_the_robot_itself() -> None:
    links = np.zeros((4, 4), dtype=bool)
    links[0, 1] = links[1, 0] = links[1, 2] = links[2, 1] = True
    reach = _reachable(links)
    assert reach[0, 2] and reach[2, 0] and reach[0, 0]  # 0 - 1 - 2
    assert not reach[0, 3] and not reach[3, 2] and reach[3, 3]
    assert [_row(2, j) for j in (0, 1, 3)] == [0, 1, 2]
    assert [_row(0, j) for j in (1, 2, 3)] == [0, 1, 2]


class _Recorder:
    """A policy that stands still and notes the frame changes it is told of."""

    def __init__(self) -> None:
        self.frames: list[np.ndarray] = []
        self.contexts: list[Any] = []

    def reset(self) -> None:
        self.frames.clear()

    def act(self, observation: dict[str, Any], context: Any) -> np.ndarray:
        self.contexts.append(context)
        return np.zeros(2, dtype=np.float32)

    def change_frame(self, new_from_old: np.ndarray) -> None:
        self.frames.append(np.asarray(new_from_old).copy())


def test_transforms_compose_along_the_graph_and_robots_join_with_their_group() -> None:
    team = TeamCoordinator(
        TeamConfig(joint=None),  # chained only: the joint refinement is tested below
        rng=np.random.default_rng(0),
        n_robots=4,
        policy_factory=lambda e, r: _Recorder(),
    )
    t12 = np.array([1.0, 2.0, 0.5])  # map1_from_map2
    t01 = np.array([-3.0, 0.5, -1.0])  # map0_from_map1
    # Robots 1 and 2 meet first: one group in robot 1's frame, not yet the common one.
    team._set_pair(2, 1)
    assert team.pair == (1, 2)
    team.groups.join(t12, t12, np.zeros(2))
    assert team.roots == [0, 1, 1, 3] and team.members == [0]
    assert np.allclose(team.frames[2], t12) and team.step_joined[2] is None
    assert all(not p.frames for p in team.policies)  # type: ignore[attr-defined]
    # Robot 0 meets robot 2: the merge places robot 2's group (in its root's, robot 1's,
    # frame) in robot 0's; the whole group joins, its transforms composed.
    team._set_pair(2, 0)
    assert team.pair == (0, 2)
    team.groups.join(t01, t01, np.zeros(2))
    t02 = compose(t01, t12)
    assert team.members == [0, 1, 2] and team.roots[3] == 3
    assert np.allclose(team.common_transform(1), t01)
    assert np.allclose(team.common_transform(2), t02)
    assert team.common_transform(3) is None
    assert np.allclose(team.transform, t01)  # the two-robot view: map0_from_map1
    # Each joining robot's policy is told its own frame's place in the common one.
    assert np.allclose(team.policies[1].frames[-1], t01)  # type: ignore[attr-defined]
    assert np.allclose(team.policies[2].frames[-1], t02)  # type: ignore[attr-defined]


def _team_of_three() -> TeamCoordinator:
    return TeamCoordinator(
        TeamConfig(),
        rng=np.random.default_rng(0),
        n_robots=3,
        policy_factory=lambda e, r: _Recorder(),
    )


def test_a_join_outside_the_common_frame_leaves_robot_0_its_current_map() -> None:
    own, truth = corridor_maps()
    team = _team_of_three()
    current = list(own)
    team._maps = lambda i: current[i]
    team._set_pair(1, 2)
    team._last_poses = [np.zeros(3), np.zeros(3)]
    t12 = compose(inverse(truth[1]), truth[2])
    team.verification.accept(
        _Rendezvous(t12, 0, np.zeros(2), 0), team._side_maps(team._maps), "seen", 0.0
    )
    assert team.roots == [0, 1, 1] and team.members == [0]
    # Robot 0 has no teammate in its frame: no merged view, and its side of its next
    # merge is its map as it is then, not as it was at the others' join.
    assert team.merged_map is None and not team.coordinated(0)
    current[0] = own[1]  # robot 0's map has grown (any other map will do)
    team.step += team.config.merged_map_every
    assert team.groups.group_map(0, team._maps) is own[1]


def test_a_group_of_three_is_refined_jointly_not_chained() -> None:
    own, truth = corridor_maps()
    team = _team_of_three()
    team._maps = lambda i: own[i]
    # Each join a little off (as refined against one map), the errors adding up.
    off = np.array([0.08, -0.06, np.radians(1.0)])
    t12 = compose(compose(inverse(truth[1]), truth[2]), off)
    t01 = compose(truth[1], off)
    team._set_pair(1, 2)
    team.groups.join(t12, t12, np.zeros(2))
    assert np.allclose(team.frames[2], t12)  # a group of two: the one edge as it is
    team._set_pair(0, 1)
    team.groups.join(t01, t01, np.zeros(2))
    decisions = [d.text for d in team.pop_decisions()]
    assert any("refined jointly on 3 overlapping pairs" in d for d in decisions), decisions
    for k in (1, 2):
        chained = compose(t01, t12) if k == 2 else t01
        error = compose(inverse(truth[k]), team.frames[k])
        chain_error = compose(inverse(truth[k]), chained)
        assert np.hypot(*error[:2]) < 0.05 and abs(error[2]) < np.radians(0.5), k
        assert np.hypot(*error[:2]) < np.hypot(*chain_error[:2])
        # The policy is told where its frame is in the common one: the refined place.
        assert np.allclose(team.policies[k].frames[-1], team.frames[k])  # type: ignore[attr-defined]


def test_a_group_of_three_is_refined_again_jointly_on_the_grown_maps() -> None:
    own, truth = corridor_maps()
    team = TeamCoordinator(
        TeamConfig(refine_every=10),
        rng=np.random.default_rng(0),
        n_robots=3,
        policy_factory=lambda e, r: _Recorder(),
    )
    team._maps = lambda i: own[i]
    team._set_pair(1, 2)
    team.groups.join(
        compose(inverse(truth[1]), truth[2]), compose(inverse(truth[1]), truth[2]), np.zeros(2)
    )
    team._set_pair(0, 1)
    team.groups.join(truth[1], truth[1], np.zeros(2))
    team._rest()
    team._reach[:] = True
    # The transforms as a join on smaller maps might have left them, within what the
    # rendezvous verified.
    off = np.array([0.1, -0.06, np.radians(1.0)])
    for k in (1, 2):
        team._change_frame(k, compose(compose(team.frames[k], off), inverse(team.frames[k])))
        team.frames[k] = compose(team.frames[k], off)
    team.pop_decisions()
    team.step += 10
    team.groups.keep_merged_map(team._maps)
    decisions = [d.text for d in team.pop_decisions()]
    assert any("refined jointly on 3 overlapping pairs" in d for d in decisions), decisions
    for k in (1, 2):
        error = compose(inverse(truth[k]), team.frames[k])
        assert np.hypot(*error[:2]) < 0.05 and abs(error[2]) < np.radians(0.5), k
        # The policy was told every move of its frame: together, the refined place.
        told = np.zeros(3)
        for change in team.policies[k].frames:  # type: ignore[attr-defined]
            told = compose(change, told)
        assert np.allclose(told, team.frames[k], atol=1e-9), k


def test_the_common_frame_shares_one_map_and_every_teammate() -> None:
    team = _team_of_three()
    cells = np.full((60, 100), FREE, dtype=np.int8)
    grid = GridMap(cells=cells, resolution=0.1)
    team.roots, team.frames = [0, 0, 0], [np.zeros(3), np.array([2.0, 0.0, 0.0]), np.zeros(3)]
    team._reach = np.ones((3, 3), dtype=bool)
    team.groups.received = {(i, j): grid for i in range(3) for j in range(3) if i != j}
    team.groups.fuse(lambda i: grid, shared=True)
    assert team.views[0] is team.views[1] is team.views[2] is team.merged_map
    observations = [{"pose": np.array([1.0 + i, 3.0, 0.0])} for i in range(3)]
    team._poses = [o["pose"] for o in observations]
    team.allocation.act(observations, lambda i: grid)
    for i, policy in enumerate(team.policies):
        context = policy.contexts[-1]  # type: ignore[attr-defined]
        assert context.in_common_frame and context.map is team.merged_map
        assert len(context.teammates) == 2
        # Robot 1's pose is brought into the common frame by its transform.
        assert np.allclose(context.pose, [1.0 + i + (2.0 if i == 1 else 0.0), 3.0, 0.0])
    # Robot 1 joined through robot 2 and never heard from robot 0: its view is what it
    # holds (its own map and robot 2's), in the common frame.
    far = GridMap(cells=cells, resolution=0.1, origin=(-20.0, 0.0))  # robot 0's, 20 m west
    own = [far, grid, grid]
    team.groups.received = {(0, 1): grid, (0, 2): grid, (1, 2): grid, (2, 0): far, (2, 1): grid}
    team.groups.fuse(lambda i: own[i], shared=False)
    view0, view1, view2 = team.views
    assert view0 is not None and view1 is not None and view2 is not None
    assert view0.origin[0] == pytest.approx(-20.0) and view2.origin[0] == pytest.approx(-20.0)
    # Robot 1's own map (2 m east) and robot 2's: x from 0 to 12 m, nothing of robot 0's.
    assert view1.origin[0] == pytest.approx(0.0) and view1.shape == (60, 120)


def _settle(team: TeamCoordinator, env: MultiRobotSlamEnv, maps: MapCache, obs: Any) -> Any:
    """Step until the running rendezvous is settled; returns the last observations."""
    agents = env.possible_agents
    for _ in range(600):
        actions = team.act([obs[a] for a in agents], maps)
        obs, *_ = env.step({a: actions[i] for i, a in enumerate(agents)})
        if team.state is not TeamState.HYPOTHESIS_VERIFICATION:
            break
    return obs


def _office_team_of_three() -> tuple[MultiRobotSlamEnv, dict, MapCache, TeamCoordinator]:
    """Three robots at ``STARTS`` in the office, a coordinator that retries merges at any
    map size (injected) and has seen the links and the poses once."""
    env = MultiRobotSlamEnv(scenario="office", n_robots=3, seed=0, config=EnvConfig(starts=STARTS))
    obs, _ = env.reset()
    maps = MapCache(env)
    team = TeamCoordinator(TeamConfig(), rng=np.random.default_rng(0), n_robots=3)
    team.proposals.retry_area = {pair: np.inf for pair in ((0, 1), (0, 2), (1, 2))}
    team.act([obs[a] for a in env.possible_agents], maps)
    return env, obs, maps, team


def test_any_pair_is_verified_by_rendezvous_and_three_robots_end_in_one_frame() -> None:
    env, obs, maps, team = _office_team_of_three()
    agents = env.possible_agents

    def put(a: int, b: int, hypothesis: np.ndarray) -> None:
        team._set_pair(a, b)
        team._observe_pair([obs[x] for x in agents])
        team.hypotheses = [hypothesis]
        team.verification.start(0, team._side_maps(maps))

    put(0, 1, compose(TRUTH[1], [0.08, -0.05, 0.02]))  # a merge's small error
    obs = _settle(team, env, maps, obs)
    assert team.members == [0, 1] and team.state is TeamState.COORDINATED_EXPLORATION
    # Robot 1, now in robot 0's frame, meets robot 2: the hypothesis is common_from_map2.
    put(1, 2, compose(TRUTH[2], [-0.06, 0.05, -0.015]))
    assert team.pair == (1, 2)
    decisions = [d.text for d in team.pop_decisions()]
    obs = _settle(team, env, maps, obs)
    decisions += [d.text for d in team.pop_decisions()]
    assert team.members == [0, 1, 2], decisions
    assert any("robot_1 sees robot_2" in d or "robot_2 sees robot_1" in d for d in decisions)
    for k in (1, 2):
        error = compose(inverse(TRUTH[k]), team.common_transform(k))
        assert np.hypot(error[0], error[1]) < 0.1 and abs(error[2]) < np.radians(1.0), k
    assert team.step_joined[2] is not None and team.step_joined[2] > team.step_joined[1]  # type: ignore[operator]
    # All three explore one merged map, each passing round the other two.
    team.act([obs[a] for a in agents], maps)
    assert team.merged_map is not None and all(team.coordinated(k) for k in range(3))
    assert all(len(team.explorers[k]._teammates) == 2 for k in range(3))


def test_a_team_needs_two_to_eight_robots() -> None:
    with pytest.raises(ValueError, match="n_robots >= 2"):
        TeamCoordinator(rng=np.random.default_rng(0), n_robots=1)
    for bad in (1, 9):
        with pytest.raises(ValueError, match="robots must be an integer from 2 to 8"):
            RunConfig(robots=bad)


def test_mrslam_run_covers_n_robots(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["run", "--scenario", "maze", "--robots", "3", "--max-steps", "40"]
    assert main([*argv, "--out", str(tmp_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["robots"] == 3 and report["steps"] == 40
    assert (
        set(report["slam"]) == set(report["collision_steps"]) == {"robot_0", "robot_1", "robot_2"}
    )
    assert set(report["merge"]["robots"]) == {"robot_1", "robot_2"}
    assert report["merge"]["joined"] == sum(r["joined"] for r in report["merge"]["robots"].values())
    run_dir = Path(report["outputs"]["run_dir"])
    assert (run_dir / "robot_2.yaml").is_file() and (run_dir / "figure.png").is_file()
    from test_recording import Recording

    recording = Recording(run_dir / "recording.rrd")
    assert any(path.startswith("/robot_2/") for path in recording.chunks), list(recording.chunks)[
        :20
    ]
    assert main([*argv, "--robots", "9", "--out", str(tmp_path)]) == 2
    assert "robots must be an integer from 2 to 8" in capsys.readouterr().err


def test_the_benchmark_reports_each_team_size() -> None:
    rows, runs = run_explore_benchmark(
        ["maze"], [0], max_steps=20, modes=("team", "independent"), robots=(2, 3)
    )
    assert [(r["robots"], r["mode"]) for r in runs] == [
        (2, "team"),
        (2, "independent"),
        (3, "team"),
        (3, "independent"),
    ]
    assert [(r["robots"], r["joinable"]) for r in rows] == [(2, 1), (3, 2)]
    table = format_explore_table(rows).splitlines()
    assert table[0].startswith("| scenario | robots | joined | t90 team (s) |")
    assert table[2].startswith("| maze | 2 | 0/1 |") and table[3].startswith("| maze | 3 | 0/2 |")


def test_a_robot_that_cannot_reach_the_meeting_point_sets_the_hypothesis_aside() -> None:
    env, obs, maps, team = _office_team_of_three()
    agents = env.possible_agents
    team._set_pair(0, 2)
    team._observe_pair([obs[a] for a in agents])
    # Far enough apart that the robots must drive to meet.
    team.hypotheses = [compose(TRUTH[2], [0.0, 0.0, 0.02])]
    team.verification.start(0, team._side_maps(maps))
    assert team.state is TeamState.HYPOTHESIS_VERIFICATION and not team.rendezvous.in_place  # type: ignore[union-attr]
    team.explorers[2].status = "goal_unreachable"  # its map holds no way there
    team.verification.verify(team._last_observations, team._side_maps(maps), link=False)
    decisions = [d.text for d in team.pop_decisions()]
    # Not evidence against the hypothesis: set aside (proposed again later), not rejected.
    assert any("set aside: robot_2 cannot reach" in d for d in decisions), decisions
    assert not team.rejected and team.rendezvous is None
    assert not team._on_goal[0] and not team._on_goal[2]
