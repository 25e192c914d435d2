"""Frontier exploration (agents.explorer): utility, the team frontier split, the policy on
synthetic maps, and one end-to-end exploration of the office in the real env."""

from __future__ import annotations

import numpy as np
import pytest

from agents.explorer import (
    ExplorerConfig,
    ExplorerPolicy,
    assign_frontiers,
    frontier_utility,
    team_discount,
    team_frontier_goals,
)
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap

RESOLUTION = 0.05


def test_utility_weighs_gain_against_path_cost() -> None:
    utility = frontier_utility([10.0, 10.0, 3.0, 10.0], [1.0, 4.0, 0.5, np.inf], 2.0, min_gain=5)
    assert utility[0] == pytest.approx(8.0)
    assert utility[1] == pytest.approx(2.0)
    assert utility[2] == -np.inf  # worthless
    assert utility[3] == -np.inf  # unreachable


def test_assignment_sends_two_robots_to_different_places() -> None:
    # Two frontiers next to each other near both robots, one farther away.
    goals = np.array([[0.0, 0.0], [0.5, 0.0], [6.0, 0.0]])
    gains = np.array([20.0, 19.0, 18.0])
    costs = np.array([[1.0, 1.2, 5.0], [1.1, 1.0, 4.0]])
    assignment = assign_frontiers(goals, gains, costs, cost_weight=1.0, separation=4.0)
    assert sorted(assignment.tolist()) == [0, 2] or sorted(assignment.tolist()) == [1, 2]
    far_robot = int(np.flatnonzero(assignment == 2)[0])
    assert far_robot == 1  # the one closer to the far frontier
    # Without the separation discount both would crowd the same corner.
    crowded = assign_frontiers(goals, gains, costs, cost_weight=1.0, separation=1e-9)
    assert set(crowded.tolist()) <= {0, 1}


def test_team_discount_is_the_share_of_the_view_no_teammate_covers() -> None:
    # Views are 8 m x 8 m squares (half-width 4 m): the share two of them have in common
    # is (1 - |dx| / 8) (1 - |dy| / 8).
    goals = np.array([[0.0, 0.0], [2.0, 2.0], [8.0, 0.0], [-6.0, 0.0]])
    left = team_discount(goals, [[0.0, 0.0]], 4.0)
    np.testing.assert_allclose(left, [0.0, 1 - 0.75 * 0.75, 1.0, 0.75], atol=1e-12)
    # Against two targets the shares left multiply.
    both = team_discount(goals, [[0.0, 0.0], [4.0, 0.0]], 4.0)
    np.testing.assert_allclose(both[1], (1 - 0.75 * 0.75) * (1 - 0.75 * 0.75), atol=1e-12)
    np.testing.assert_array_equal(team_discount(goals, np.empty((0, 2)), 4.0), np.ones(4))
    with pytest.raises(ValueError, match="view_range"):
        team_discount(goals, [[0.0, 0.0]], 0.0)


def test_team_discount_sees_no_overlap_across_a_mapped_wall() -> None:
    # Two goals 2 m apart on either side of a wall, two more with the same offset in the
    # open: the wall hides the target, the open floor does not.
    cells = np.full((100, 100), FREE, dtype=np.int8)
    cells[:50, 50] = OCCUPIED  # a wall along x = 2.5 m for y < 2.5 m
    grid = GridMap(cells=cells, resolution=RESOLUTION)
    goals = np.array([[1.5, 1.0], [1.5, 4.0]])
    targets = np.array([[3.5, 1.0], [3.5, 4.0]])
    hidden = team_discount(goals[:1], targets[:1], 4.0, grid)
    seen = team_discount(goals[1:], targets[1:], 4.0, grid)
    np.testing.assert_allclose(hidden, [1.0])
    np.testing.assert_allclose(seen, [0.25])  # 2 m apart: 1 - 0.75 of the view is left
    np.testing.assert_allclose(team_discount(goals[:1], targets[:1], 4.0), [0.25])


def test_a_frontier_the_taken_view_covers_is_no_longer_worth_a_trip() -> None:
    # Both robots next to one frontier, a second one 5 m on (12 m of path round a wall):
    # the first frontier's view is the first robot's; the second robot goes on instead of
    # sharing it, unless any gain left, however small, is worth the trip.
    goals = np.array([[0.0, 0.0], [5.0, 0.0]])
    gains = np.array([6.0, 6.0])
    costs = np.array([[0.5, 12.5], [0.6, 12.4]])
    shared = assign_frontiers(goals, gains, costs, cost_weight=0.5, view_range=4.0)
    assert shared.tolist() == [0, 0]  # min_gain 0: what is left, however little, counts
    split = assign_frontiers(goals, gains, costs, cost_weight=0.5, view_range=4.0, min_gain=0.5)
    assert split.tolist() == [0, 1]


def test_assignment_marks_robots_with_nothing_reachable() -> None:
    goals = np.array([[0.0, 0.0]])
    costs = np.array([[1.0], [np.inf]])
    assignment = assign_frontiers(goals, np.array([10.0]), costs)
    assert assignment.tolist() == [0, -1]
    empty = assign_frontiers(np.empty((0, 2)), np.empty(0), np.empty((2, 0)))
    assert empty.tolist() == [-1, -1]
    with pytest.raises(ValueError, match="path_costs"):
        assign_frontiers(goals, np.array([1.0]), np.ones((2, 3)))


def two_rooms() -> GridMap:
    """Two mapped 3 m x 3 m rooms side by side with a 1 m door between them; each has a
    1 m doorway on its outer side opening onto unknown space."""
    cells = np.full((100, 160), UNKNOWN, dtype=np.int8)
    cells[20:81, 20:141] = OCCUPIED
    cells[21:80, 21:80] = FREE
    cells[21:80, 81:140] = FREE
    cells[40:60, 80] = FREE  # the inner door
    cells[40:60, 20] = FREE  # west doorway
    cells[40:60, 140] = FREE  # east doorway
    return GridMap(cells=cells, resolution=RESOLUTION, origin=(0.0, 0.0))


def test_team_goals_split_the_frontiers_between_the_robots() -> None:
    grid = two_rooms()
    positions = np.array([[2.0, 2.5, 0.0], [2.6, 2.5, 0.0]])  # both in the west room
    goals, frontiers = team_frontier_goals(grid, positions)
    assert len(frontiers) == 2
    assert np.all(np.isfinite(goals))
    assert np.hypot(*(goals[0] - goals[1])) > 4.0  # one robot per doorway
    west = int(np.argmin(goals[:, 0]))
    assert west == 0  # the robot further west takes the west doorway


def test_the_policy_plans_to_a_frontier_and_exposes_plan_and_frontiers() -> None:
    grid = two_rooms()
    policy = ExplorerPolicy(np.random.default_rng(0))
    observation = {"pose": np.array([3.5, 2.5, 0.0])}
    action = policy.act(observation, grid)
    assert action.shape == (2,) and action.dtype == np.float32
    assert np.all(np.abs(action) <= 1.0)
    assert policy.status == "exploring"
    assert policy.frontiers.shape == (2, 2)
    plan = policy.plan
    assert plan.shape[1] == 2 and len(plan) >= 2
    assert policy.target is not None
    np.testing.assert_allclose(plan[-1], policy.target, atol=1e-9)
    assert np.hypot(*(plan[0] - observation["pose"][:2])) < 0.1
    # The nearer doorway wins (the west one, 2.5 m away, against the east one at 3.5 m).
    assert policy.target[0] < 1.5


def test_teammate_targets_push_the_choice_elsewhere() -> None:
    grid = two_rooms()
    policy = ExplorerPolicy(np.random.default_rng(0))
    policy.set_teammate_targets(np.array([[1.0, 2.5]]))  # teammate heads for the west door
    policy.act({"pose": np.array([3.5, 2.5, 0.0])}, grid)
    assert policy.target is not None and policy.target[0] > 6.0


@pytest.mark.parametrize(
    ("allocation", "goes_east"), [("targets", False), ("greedy", True), ("minpos", True)]
)
def test_a_joint_allocation_leaves_a_frontier_to_the_teammate_nearer_to_it(
    allocation: str, goes_east: bool
) -> None:
    # The robot is 2.5 m from the west doorway and 3.5 m from the east one; a teammate
    # (target not known yet) stands 0.5 m from the west doorway. On its own the robot
    # takes the nearer west doorway; a joint allocation gives that one to the teammate
    # and the east one to the robot.
    grid = two_rooms()
    config = ExplorerConfig(team_allocation=allocation)  # type: ignore[arg-type]
    policy = ExplorerPolicy(np.random.default_rng(0), config)
    policy.set_teammates(np.array([[1.5, 2.5]]))
    policy.act({"pose": np.array([3.5, 2.5, 0.0])}, grid)
    assert policy.target is not None
    assert (policy.target[0] > 6.0) == goes_east


def test_assignment_bonus_keeps_a_robot_on_its_frontier() -> None:
    goals = np.array([[0.0, 0.0], [10.0, 0.0]])
    costs = np.array([[1.0, 9.0], [2.0, 4.0]])  # robot 0 is the nearer to frontier 0
    plain = assign_frontiers(goals, [5.0, 5.0], costs, cost_weight=1.0, min_gain=0.5)
    np.testing.assert_array_equal(plain, [0, 1])
    bonus = np.array([[0.0, 0.0], [8.0, 0.0]])  # robot 1 heads for frontier 0
    kept = assign_frontiers(goals, [5.0, 5.0], costs, cost_weight=1.0, min_gain=0.5, bonus=bonus)
    np.testing.assert_array_equal(kept, [1, 0])
    with pytest.raises(ValueError, match="bonus must have the shape"):
        assign_frontiers(goals, [5.0, 5.0], costs, bonus=np.zeros((1, 2)))


def test_a_robot_whose_frontiers_are_teammates_targets_waits_and_is_not_done() -> None:
    # Regression: the only frontier left is the teammate's target. The robot used to
    # count that as nothing left, report done after `done_after` replans, and with all
    # robots done the run ended early. It now waits, and takes the frontier when the
    # teammate gives it up.
    grid = two_rooms()
    grid.cells[40:60, 20] = OCCUPIED  # close the west doorway
    east_door = np.array([7.0, 2.475])
    pose = {"pose": np.array([3.5, 2.5, 0.0])}
    policy = ExplorerPolicy(np.random.default_rng(0), ExplorerConfig(done_after=2))
    policy.set_teammate_targets(east_door[None])
    for _ in range(20):
        action = policy.act(pose, grid)
    assert policy.status == "waiting" and not policy.done
    assert policy.target is None
    np.testing.assert_array_equal(action, [0.0, 0.0])
    policy.set_teammate_targets(np.empty((0, 2)))  # the teammate gave it up
    for _ in range(policy.config.min_replan_interval):
        policy.act(pose, grid)
    assert policy.status == "exploring" and policy.target is not None
    assert np.hypot(*(policy.target - east_door)) < 0.5
    # A frontier left to a teammate but blacklisted here is no reason to wait.
    blocked = ExplorerPolicy(np.random.default_rng(0), ExplorerConfig(done_after=2))
    blocked.set_teammate_targets(east_door[None])
    blocked._blacklist_point(east_door)
    for _ in range(3 * blocked.config.replan_interval):
        blocked.act(pose, grid)
    assert blocked.done


def test_a_given_goal_overrides_exploration_until_cleared() -> None:
    grid = two_rooms()
    policy = ExplorerPolicy(np.random.default_rng(0))
    pose = np.array([2.0, 2.0, 0.0])
    policy.set_goal([6.0, 3.0])
    policy.act({"pose": pose}, grid)
    assert policy.status == "to_goal"
    np.testing.assert_allclose(policy.plan[-1], [6.0, 3.0], atol=RESOLUTION)
    # Standing at the goal: arrived, and the robot is told to stop.
    policy.set_goal([2.0, 2.0])
    for _ in range(3):
        action = policy.act({"pose": pose}, grid)
    assert policy.status == "arrived"
    np.testing.assert_allclose(action, [0.0, 0.0], atol=1e-6)
    policy.set_goal([-3.0, -3.0])  # off the map
    policy.act({"pose": pose}, grid)
    assert policy.status == "goal_unreachable"
    policy.clear_goal()
    policy.act({"pose": pose}, grid)
    assert policy.status == "exploring"
    with pytest.raises(ValueError, match="finite"):
        policy.set_goal([np.nan, 0.0])


def test_with_nothing_left_to_explore_it_stops_and_reports_done() -> None:
    cells = np.full((60, 60), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    grid = GridMap(cells=cells, resolution=RESOLUTION)
    config = ExplorerConfig(done_after=2, replan_interval=1)
    policy = ExplorerPolicy(np.random.default_rng(0), config)
    for _ in range(3):
        action = policy.act({"pose": np.array([1.5, 1.5, 0.0])}, grid)
    assert policy.done
    np.testing.assert_array_equal(action, [0.0, 0.0])
    assert policy.plan.shape == (0, 2)


def test_a_newly_mapped_wall_across_the_path_triggers_a_replan() -> None:
    grid = two_rooms()
    policy = ExplorerPolicy(np.random.default_rng(0))
    pose = np.array([2.0, 2.5, 0.0])
    policy.set_goal([6.5, 2.5])  # through the inner door
    policy.act({"pose": pose}, grid)
    replans = policy.replans
    closed = grid.cells.copy()
    closed[40:60, 80] = OCCUPIED  # the door turns out to be shut
    shut = GridMap(cells=closed, resolution=RESOLUTION, origin=grid.origin)
    policy.act({"pose": pose}, shut)
    assert policy.replans == replans + 1
    assert policy.last_replan_reason == "path_blocked"
    assert policy.status == "goal_unreachable"


@pytest.mark.parametrize(
    ("field", "value"),
    [("cost_weight", -1.0), ("replan_interval", 0), ("separation", 0.0), ("done_after", 1.5)],
)
def test_config_rejects_bad_values_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        ExplorerConfig(**{field: value})  # type: ignore[arg-type]


OFFICE_STEP_BUDGET = 1500
"""Steps one explorer gets to map >= 85% of the office (measured: seeds 0-2 pass 85%
by step 1000, at 0.87 / 0.90 / 0.87, and reach 96-97% by step 1500)."""


def test_one_explorer_maps_the_office() -> None:
    from mrslam_env.config import EnvConfig
    from mrslam_env.env import MultiRobotSlamEnv

    env = MultiRobotSlamEnv(
        scenario="office", n_robots=1, seed=0, config=EnvConfig(max_cycles=OFFICE_STEP_BUDGET)
    )
    observations, infos = env.reset()
    policy = ExplorerPolicy(np.random.default_rng(0))
    collisions = 0
    coverage = 0.0
    for _ in range(OFFICE_STEP_BUDGET):
        action = policy.act(observations["robot_0"], env.robot_map("robot_0"))
        observations, _, _, truncations, infos = env.step({"robot_0": action})
        collisions += int(infos["robot_0"]["collision"])
        coverage = infos["robot_0"]["observed_area"] / env.observable_area
        if coverage >= 0.85 or truncations["robot_0"]:
            break
    assert coverage >= 0.85
    assert collisions <= 5
    assert len(policy.frontiers) > 0 and len(policy.plan) > 0


def test_the_cut_short_search_plans_as_the_whole_search(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The explorer stops its search once no frontier left can beat the best one reached;
    # with the whole search instead, the same office run makes the same plans and actions.
    import agents.explorer_choice as choice_module
    from agents.planning import CostGrid, distance_field
    from mrslam_env.config import EnvConfig
    from mrslam_env.env import MultiRobotSlamEnv

    def run() -> tuple[list[np.ndarray], list[np.ndarray]]:
        env = MultiRobotSlamEnv(
            scenario="office", n_robots=1, seed=1, config=EnvConfig(max_cycles=200)
        )
        observations, _ = env.reset()
        policy = ExplorerPolicy(np.random.default_rng(1))
        actions, plans = [], []
        for _ in range(200):
            action = policy.act(observations["robot_0"], env.robot_map("robot_0"))
            actions.append(action)
            plans.append(policy.plan.copy())
            observations, *_ = env.step({"robot_0": action})
        assert policy.replans >= 8
        return actions, plans

    cut_actions, cut_plans = run()

    def whole_search(grid: CostGrid, start: tuple[int, int], *_: object, **__: object) -> object:
        return distance_field(grid, grid.cell_to_world(np.array(start)), snap_distance=1e-9)

    monkeypatch.setattr(choice_module, "best_goal_field", whole_search)
    whole_actions, whole_plans = run()
    np.testing.assert_array_equal(np.array(cut_actions), np.array(whole_actions))
    for cut, whole in zip(cut_plans, whole_plans, strict=True):
        np.testing.assert_array_equal(cut, whole)


def test_close_scan_returns_the_map_misses_are_planned_around() -> None:
    # An open room; the scan shows a post 0.5 m ahead of the robot that the map lacks.
    cells = np.full((80, 80), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    grid = GridMap(cells=cells, resolution=0.1)
    pose = np.array([2.0, 4.0, 0.0])
    angles = -np.pi + np.arange(360) * (2 * np.pi / 360)
    scan = np.full(360, 8.0)
    scan[np.abs(angles) < np.radians(12)] = 0.45
    policy = ExplorerPolicy(np.random.default_rng(0))
    policy.set_goal([6.0, 4.0])
    policy.act({"pose": pose}, grid)  # no scan: straight through
    assert np.abs(policy.plan[:, 1] - 4.0).max() < 0.05
    for _ in range(6):
        policy.act({"pose": pose, "scan": scan}, grid)
    policy.set_goal([6.0, 4.0])  # replan with the remembered returns
    policy.act({"pose": pose, "scan": scan}, grid)
    post = np.array([2.45, 4.0])
    samples = np.concatenate(
        [np.linspace(a, b, 20) for a, b in zip(policy.plan[:-1], policy.plan[1:], strict=True)]
    )
    assert np.hypot(*(samples - post).T).min() > 0.25, "the path keeps clear of the post"
    np.testing.assert_allclose(policy.plan[-1], [6.0, 4.0], atol=0.1)


def open_room(size: int = 80) -> GridMap:
    cells = np.full((size, size), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    return GridMap(cells=cells, resolution=0.1)


def test_a_teammates_target_is_never_shared() -> None:
    # Only the east doorway is left; the teammate already heads there.
    grid = two_rooms()
    grid.cells[40:60, 20] = OCCUPIED  # close the west doorway
    policy = ExplorerPolicy(np.random.default_rng(0))
    alone = ExplorerPolicy(np.random.default_rng(0))
    alone.act({"pose": np.array([3.5, 2.5, 0.0])}, grid)
    assert alone.target is not None
    policy.set_teammate_targets(alone.target[None])
    policy.act({"pose": np.array([3.5, 2.5, 0.0])}, grid)
    assert policy.target is None or np.hypot(*(policy.target - alone.target)) >= 1.0


@pytest.mark.parametrize(
    ("teammate", "contest", "takes_it"),
    [
        ((13.0, 2.5), True, True),  # the teammate is 6 m from its target, the robot 3.5 m
        ((13.0, 2.5), False, False),
        ((7.0, 1.0), True, False),  # the teammate is 1.5 m from it: its own
    ],
)
def test_a_teammates_target_is_its_own_only_while_it_is_as_near(
    teammate: tuple[float, float], contest: bool, takes_it: bool
) -> None:
    # Only the east doorway is left and a teammate heads there. Regression (maze seed 3,
    # oracle): the robot nearer to the last frontier yielded it to a teammate 15 m away
    # and waited 31 s. With contest_targets the nearer robot keeps it; a farther one
    # still leaves it to the teammate (and waits).
    grid = two_rooms()
    grid.cells[40:60, 20] = OCCUPIED  # close the west doorway
    east_door = np.array([7.0, 2.475])
    policy = ExplorerPolicy(np.random.default_rng(0), ExplorerConfig(contest_targets=contest))
    policy.set_teammates(np.array([teammate]))
    policy.set_teammate_targets(east_door[None])
    policy.act({"pose": np.array([3.5, 2.5, 0.0])}, grid)
    if takes_it:
        assert policy.status == "exploring" and policy.target is not None
        assert np.hypot(*(policy.target - east_door)) < 1.0
    else:
        assert policy.status == "waiting" and policy.target is None


@pytest.mark.parametrize("separation", [4.0, 8.0])
def test_only_frontiers_near_a_teammates_target_are_taken(separation: float) -> None:
    # The teammate heads for the west doorway; the east one, 6 m away, stays available
    # whatever the separation (a wider one must not exclude every frontier).
    grid = two_rooms()
    policy = ExplorerPolicy(np.random.default_rng(0), ExplorerConfig(separation=separation))
    policy.set_teammate_targets(np.array([[1.0, 2.5]]))
    policy.act({"pose": np.array([3.5, 2.5, 0.0])}, grid)
    assert policy.target is not None and policy.target[0] > 6.0


def test_a_teammate_is_planned_around() -> None:
    grid = open_room()
    policy = ExplorerPolicy(np.random.default_rng(0))
    teammate = np.array([4.0, 4.0])
    policy.set_teammates(teammate[None])
    policy.set_goal([6.0, 4.0])
    policy.act({"pose": np.array([2.0, 4.0, 0.0])}, grid)
    samples = np.concatenate(
        [np.linspace(a, b, 20) for a, b in zip(policy.plan[:-1], policy.plan[1:], strict=True)]
    )
    assert np.hypot(*(samples - teammate).T).min() > 0.35, "the path passes round the teammate"
    policy.set_teammates(np.empty((0, 2)))
    policy.set_goal([6.0, 4.0])
    policy.act({"pose": np.array([2.0, 4.0, 0.0])}, grid)
    assert np.abs(policy.plan[:, 1] - 4.0).max() < 0.05  # without it, straight through


def _blocked_at_the_inner_door(blocker: str) -> ExplorerPolicy:
    policy = ExplorerPolicy(np.random.default_rng(0))
    if blocker == "teammate":
        policy.set_teammates(np.array([[4.0, 2.5]]))  # standing in the inner door
    elif blocker == "close_returns":  # a jamb seen from a few cm, a little off, across
        across = np.column_stack([np.full(11, 4.0), np.linspace(2.0, 3.0, 11)])
        policy._close_returns.append((0, across))
    return policy


def _inner_door(blocker: str) -> GridMap:
    """Two rooms, the west doorway closed; with ``blocker == "margin"`` the inner door
    narrowed to 0.5 m: wider than the robot (0.4 m), narrower than its footprint with
    the planner's safety margin (0.56 m)."""
    grid = two_rooms()
    grid.cells[40:60, 20] = OCCUPIED  # close the west doorway
    if blocker == "margin":
        grid.cells[40:45, 80] = OCCUPIED
        grid.cells[55:60, 80] = OCCUPIED
    return grid


@pytest.mark.parametrize("blocker", ["teammate", "close_returns", "margin"])
def test_a_frontier_cut_off_by_a_teammate_close_returns_or_the_margin_is_explored(
    blocker: str,
) -> None:
    # The only frontier left (the east doorway) lies beyond the inner door, which a
    # teammate standing in it, the robot's remembered close returns, or the planner's
    # safety margin close in the planning grid. Regression (planner_test seed 2, team):
    # after the rendezvous both robots found no frontier so, reported done and ended the
    # run at 75 % coverage; (planner_test seed 3, one robot) a ragged wall's margin left
    # the robot on a one-cell island of the cost grid: done at 14 %. Only the map ends
    # exploration: the robot plans to the doorway on the map itself, on its bare footprint.
    grid = _inner_door(blocker)
    pose = {"pose": np.array([2.0, 2.5, 0.0])}
    policy = _blocked_at_the_inner_door(blocker)
    for _ in range(policy.config.done_after + 1):
        policy.act(pose, grid)
    assert policy.status == "exploring" and policy.target is not None
    assert policy.target[0] > 6.5  # the east doorway
    # With the door itself walled up, the map has nothing left: done on the last of
    # done_after replans, one count a replan.
    grid.cells[40:60, 80] = OCCUPIED
    policy = _blocked_at_the_inner_door(blocker)
    for _ in range(policy.config.done_after - 1):
        policy.act(pose, grid)
    assert policy.status == "exploring" and policy.target is None
    policy.act(pose, grid)
    assert policy.status == "done"


def test_a_robot_only_sighted_in_the_doorway_is_not_planned_through() -> None:
    # Before a merge a robot the peer sensor sees stays in the way (the path check would
    # refuse a path through it on the next step): no plan through the door it stands in,
    # and no replan on every step either.
    grid = two_rooms()
    grid.cells[40:60, 20] = OCCUPIED  # only the east doorway is left, beyond the inner door
    seen = {"pose": np.array([2.0, 2.5, 0.0]), "peer": np.array([[1.0, 2.0, 0.0, np.pi]])}
    policy = ExplorerPolicy(np.random.default_rng(0))
    for _ in range(policy.config.done_after):
        policy.act(seen, grid)
    assert policy.status == "done" and policy.target is None
    assert policy.replans == policy.config.done_after


def test_changing_frame_carries_remembered_obstacles_and_goals_over() -> None:
    grid = open_room()
    pose = np.array([2.0, 4.0, 0.0])
    angles = -np.pi + np.arange(360) * (2 * np.pi / 360)
    scan = np.full(360, 8.0)
    scan[np.abs(angles) < np.radians(12)] = 0.45  # a post at (2.45, 4.0) the map lacks
    policy = ExplorerPolicy(np.random.default_rng(0))
    policy.set_goal([6.0, 4.0])
    for _ in range(6):
        policy.act({"pose": pose, "scan": scan}, grid)
    # The new frame is the old one shifted by (1, -1) m: the post is now at (3.45, 3.0).
    new_from_old = np.array([1.0, -1.0, 0.0])
    policy.change_frame(new_from_old)
    assert policy.target is not None
    np.testing.assert_allclose(policy.target, [7.0, 3.0], atol=1e-9)
    assert len(policy.plan) == 0  # the old path is dropped ...
    policy.act({"pose": np.array([3.0, 3.0, 0.0]), "scan": scan}, grid)
    assert len(policy.plan) >= 2  # ... and replanned in the new frame round the moved post
    post = np.array([3.45, 3.0])
    samples = np.concatenate(
        [np.linspace(a, b, 20) for a, b in zip(policy.plan[:-1], policy.plan[1:], strict=True)]
    )
    assert np.hypot(*(samples - post).T).min() > 0.25
    np.testing.assert_allclose(policy.plan[-1], [7.0, 3.0], atol=0.1)
    with pytest.raises(ValueError, match="change_frame"):
        policy.change_frame([np.nan, 0.0, 0.0])


def test_a_sighted_robot_is_not_remembered_as_an_obstacle() -> None:
    # The same close returns as the post above, but the peer sensor says they are a
    # robot: it moves on, so no phantom wall is left where it stood.
    grid = open_room()
    pose = np.array([2.0, 4.0, 0.0])
    angles = -np.pi + np.arange(360) * (2 * np.pi / 360)
    scan = np.full(360, 8.0)
    scan[np.abs(angles) < np.radians(12)] = 0.45
    for peer, straight in ((np.array([[1.0, 0.6, 0.0, np.pi]]), True), (np.zeros((1, 4)), False)):
        policy = ExplorerPolicy(np.random.default_rng(0))
        policy.set_goal([6.0, 4.0])
        for _ in range(6):
            policy.act({"pose": pose, "scan": scan, "peer": peer}, grid)
        policy.set_goal([6.0, 4.0])
        policy.act({"pose": pose, "scan": np.full(360, 8.0), "peer": np.zeros((1, 4))}, grid)
        assert (np.abs(policy.plan[:, 1] - 4.0).max() < 0.05) == straight


def test_while_exploring_a_sighted_robot_is_planned_round() -> None:
    # Before a merge nobody knows where the other robot is in its own map, but the peer
    # sensor sees it: two robots would otherwise meet head-on in a doorway and push.
    grid = two_rooms()
    grid.cells[40:60, 20] = OCCUPIED  # only the east doorway is left
    pose = np.array([4.5, 2.5, 0.0])
    policy = ExplorerPolicy(np.random.default_rng(0))
    policy.act({"pose": pose, "peer": np.zeros((1, 4))}, grid)
    assert policy.target is not None and policy.target[0] > 6.5
    assert np.abs(policy.plan[:, 1] - 2.5).max() < 0.1  # straight to the doorway
    robot = np.array([5.75, 2.5])  # 1.25 m dead ahead, facing us
    policy.act({"pose": pose, "peer": np.array([[1.0, 1.25, 0.0, np.pi]])}, grid)
    assert policy.last_replan_reason == "path_blocked"
    samples = np.concatenate(
        [np.linspace(a, b, 20) for a, b in zip(policy.plan[:-1], policy.plan[1:], strict=True)]
    )
    assert np.hypot(*(samples - robot).T).min() > 0.35, "the path passes round the robot"
    # Driving to a given goal (a rendezvous) the robots mean to meet: no detour.
    policy.set_goal([6.5, 2.5])
    policy.act({"pose": pose, "peer": np.array([[1.0, 1.25, 0.0, np.pi]])}, grid)
    assert np.abs(policy.plan[:, 1] - 2.5).max() < 0.1
