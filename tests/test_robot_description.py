"""One description of the robot: every agent plans, drives and looks with the env's figures
(``EnvConfig``: robot radius, speeds at action 1, control period, lidar beams, peer sensor
range), a config that contradicts the env is refused, and the experiment runner builds its
team from the env's own config. Also the ``mrslam run`` progress bar on an early finish."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import scenarios.experiment as experiment
from agents.explorer import ExplorerConfig, ExplorerPolicy
from agents.follower import FollowerConfig, PathFollower
from agents.planning import PlannerConfig, inflate, plan_path
from agents.team import UNSEEN_STEPS, TeamConfig, TeamCoordinator, _Rendezvous
from agents.wander import WanderConfig, WanderPolicy
from mrslam_env.config import EnvConfig, LidarConfig, PeerSensorConfig, RobotConfig
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap

ROBOT = RobotConfig(radius=0.3, max_speed=1.5, max_turn_rate=3.0, max_acceleration=3.0)
ENV = EnvConfig(
    robot=ROBOT,
    peer=PeerSensorConfig(detect_range=8.0),
    lidar=LidarConfig(n_beams=180),
    dt=0.05,
)
"""A robot unlike the default one in every figure the agents use."""
DEFAULT = EnvConfig()
RESOLUTION = 0.05


def doorway_map(gap: float = 0.7) -> GridMap:
    """4 m x 4 m at 5 cm, all known: a wall along y = 2 m with a doorway ``gap`` wide
    (14 cells: the cell centres in the middle are 0.35 m from the nearest wall cell)."""
    cells = np.full((80, 80), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[40, :] = OCCUPIED
    width = round(gap / RESOLUTION)
    cells[40, 40 - width // 2 : 40 - width // 2 + width] = FREE
    return GridMap(cells=cells, resolution=RESOLUTION)


BELOW, ABOVE = np.array([2.0, 1.0]), np.array([2.0, 3.3])


# --- the configs take the env's figures -----------------------------------------------------


def test_the_defaults_are_the_default_envs_figures() -> None:
    assert PlannerConfig() == PlannerConfig.for_env(DEFAULT)
    assert FollowerConfig() == FollowerConfig.for_env(DEFAULT)
    assert WanderConfig() == WanderConfig.for_env(DEFAULT)
    assert ExplorerConfig() == ExplorerConfig.for_env(DEFAULT)
    assert TeamConfig() == TeamConfig.for_env(DEFAULT)
    assert TeamConfig().in_sight_range == DEFAULT.peer.detect_range - 1.0


def test_every_config_built_for_an_env_carries_its_figures() -> None:
    planner = PlannerConfig.for_env(ENV, safety_margin=0.1)
    assert (planner.robot_radius, planner.safety_margin) == (0.3, 0.1)
    assert planner.blocked_radius == pytest.approx(0.4)
    follower = FollowerConfig.for_env(ENV)
    assert (follower.max_speed, follower.max_turn_rate, follower.dt) == (1.5, 3.0, 0.05)
    assert follower.max_acceleration == 3.0
    assert WanderConfig.for_env(ENV).robot_radius == 0.3
    explorer = ExplorerConfig.for_env(ENV, separation=3.0)
    assert explorer.planner == PlannerConfig.for_env(ENV)
    assert explorer.follower == FollowerConfig.for_env(ENV)
    assert explorer.separation == 3.0
    team = TeamConfig.for_env(ENV, interaction=False)
    assert team.explorer == ExplorerConfig.for_env(ENV)
    assert (team.peer_range, team.in_sight_range, team.interaction) == (8.0, 7.0, False)


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: PlannerConfig.for_env(ENV, robot_radius=0.2), "robot_radius"),
        (lambda: FollowerConfig.for_env(ENV, max_speed=1.0), "max_speed"),
        (lambda: FollowerConfig.for_env(ENV, dt=0.1), "dt"),
        (lambda: FollowerConfig.for_env(ENV, max_acceleration=2.0), "max_acceleration"),
        (lambda: WanderConfig.for_env(ENV, robot_radius=0.2), "robot_radius"),
        (lambda: TeamConfig.for_env(ENV, peer_range=5.0), "peer_range"),
    ],
)
def test_an_env_figure_cannot_be_overridden(build: Any, field: str) -> None:
    with pytest.raises(ValueError, match=f"{field} comes from the env"):
        build()


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: PlannerConfig().check_env(ENV), r"robot_radius is 0.2 .*robot.radius is 0.3"),
        (lambda: FollowerConfig().check_env(ENV), r"max_speed is 1.0 .* is 1.5"),
        (lambda: replace(FollowerConfig.for_env(ENV), dt=0.1).check_env(ENV), r"\.dt is 0.1"),
        (lambda: WanderConfig().check_env(ENV), "robot_radius is 0.2"),
        (lambda: ExplorerConfig.for_env(ENV, planner=PlannerConfig()), "robot_radius is 0.2"),
        (lambda: ExplorerConfig.for_env(ENV, follower=FollowerConfig()), "max_speed is 1.0"),
        (lambda: TeamConfig.for_env(ENV, explorer=ExplorerConfig()), "robot_radius is 0.2"),
        (lambda: PathFollower.for_env(ENV, FollowerConfig()), "max_speed"),
        (lambda: WanderPolicy.for_env(ENV, np.random.default_rng(0), WanderConfig()), "radius"),
        (
            lambda: ExplorerPolicy.for_env(ENV, np.random.default_rng(0), ExplorerConfig()),
            "robot_radius",
        ),
        (
            lambda: TeamCoordinator.for_env(
                ENV, rng=np.random.default_rng(0), config=TeamConfig.for_env(DEFAULT)
            ),
            r"peer_range is 5.0 .*detect_range is 8.0",
        ),
        (
            lambda: TeamCoordinator.for_env(
                ENV,
                rng=np.random.default_rng(0),
                config=replace(TeamConfig(), peer_range=8.0),
            ),
            "robot_radius is 0.2",
        ),
    ],
)
def test_a_config_that_contradicts_the_env_is_refused(build: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build()


# --- and every agent behaves accordingly ----------------------------------------------------


def test_the_planner_inflates_by_the_env_robots_radius() -> None:
    grid = doorway_map()
    small = inflate(grid, PlannerConfig.for_env(DEFAULT))
    large = inflate(grid, PlannerConfig.for_env(ENV))
    # The middle of the doorway is 0.35 m from the walls: room for 0.2 + 0.08, not 0.3 + 0.08.
    door = grid.world_to_cell(np.array([2.0, 2.0]))
    assert np.isfinite(small.cost[door[0], door[1]])
    assert np.isinf(large.cost[door[0], door[1]])
    assert len(plan_path(small, BELOW, ABOVE)) > 0
    assert len(plan_path(large, BELOW, ABOVE)) == 0
    assert large.passable.sum() < small.passable.sum()


def drive(follower: PathFollower, path: np.ndarray, pose: np.ndarray, steps: int) -> list[Any]:
    follower.set_path(path)
    return [follower.step(pose) for _ in range(steps)]


@pytest.mark.parametrize("env", [DEFAULT, ENV], ids=["default", "other-robot"])
def test_the_follower_scales_and_limits_by_the_env_robot(env: EnvConfig) -> None:
    config = FollowerConfig.for_env(env)
    straight = np.array([[0.0, 0.0], [10.0, 0.0]])
    actions = drive(PathFollower.for_env(env), straight, np.zeros(3), 20)
    # One period's acceleration from rest, over the env's period, in the env's action scale.
    first = config.max_linear_acceleration * env.dt / env.robot.max_speed
    assert actions[0][0] == pytest.approx(first, rel=1e-6)
    assert actions[0][0] == pytest.approx(
        1.5 * (0.1 if env is DEFAULT else 0.05) / (1.0 if env is DEFAULT else 1.5), rel=1e-6
    )
    # Cruising: the same 0.8 m/s is a smaller action for the faster robot.
    assert actions[-1][0] == pytest.approx(config.cruise_speed / env.robot.max_speed, rel=1e-6)
    # Turning in place towards a point 1 rad to the left: 2.5 rad/s wanted, clipped to the
    # robot's turn rate (2 rad/s: action 1; 3 rad/s: action 2.5 / 3).
    aside = np.array([[0.0, 0.0], [5.0 * math.cos(1.0), 5.0 * math.sin(1.0)]])
    actions = drive(PathFollower.for_env(env), aside, np.zeros(3), 20)
    assert actions[-1][0] == 0.0
    turn = min(config.turn_gain * 1.0, env.robot.max_turn_rate) / env.robot.max_turn_rate
    assert actions[-1][1] == pytest.approx(turn, rel=1e-5)
    assert actions[-1][1] == pytest.approx(1.0 if env is DEFAULT else 2.5 / 3.0, rel=1e-5)


def test_the_wander_policy_sweeps_the_env_robots_lane() -> None:
    def first_action(env: EnvConfig) -> Any:
        policy = WanderPolicy.for_env(env, np.random.default_rng(0))
        n = env.lidar.n_beams
        assert len(policy.angles) == n
        scan = np.full(n, 8.0)
        # One return 0.5 m ahead and 0.38 m to the left, outside the 35 degree front cone:
        # in the lane of a 0.3 m robot (half-width 0.4 m), beside that of a 0.2 m one.
        beam = round((math.pi + math.atan2(0.38, 0.5)) / (2 * math.pi / n))
        scan[beam] = math.hypot(0.5, 0.38)
        return policy.act(scan)

    assert first_action(DEFAULT)[0] == pytest.approx(0.8)  # drives on
    assert first_action(ENV)[0] == 0.0  # stops and turns away


def test_the_explorer_plans_for_the_env_robot() -> None:
    outcomes = {}
    for name, env in (("default", DEFAULT), ("other", ENV)):
        policy = ExplorerPolicy.for_env(env, np.random.default_rng(0))
        assert policy.config.planner.robot_radius == env.robot.radius
        assert policy.follower.config == FollowerConfig.for_env(env)
        policy.set_goal(ABOVE)
        action = policy.act({"pose": np.array([*BELOW, math.pi / 2])}, doorway_map())
        outcomes[name] = (policy.status, action)
    assert outcomes["default"][0] == "to_goal"  # through the doorway
    assert outcomes["other"][0] == "goal_unreachable"  # too wide for it
    # Facing the goal, the first action is one period's acceleration in the env's scale.
    assert outcomes["default"][1][0] == pytest.approx(0.15)
    assert outcomes["other"][1][0] == 0.0


def test_the_explorers_scan_guard_watches_the_env_robots_lane() -> None:
    def first_action(env: EnvConfig, obstacle: bool) -> Any:
        policy = ExplorerPolicy.for_env(env, np.random.default_rng(0))
        policy.set_goal(np.array([2.0, 1.8]))
        n = env.lidar.n_beams
        scan = np.full(n, 8.0)
        if obstacle:
            # A return the map does not show, 0.25 m to the left, just ahead: beside the
            # lane of a 0.2 m robot, 0.09 m ahead of a 0.3 m robot's footprint.
            beam = round((math.pi + math.radians(45.0)) / (2 * math.pi / n))
            angle = -math.pi + beam * 2 * math.pi / n
            scan[beam] = 0.25 / math.sin(angle)
        observation = {"pose": np.array([*BELOW, math.pi / 2]), "scan": scan}
        return policy.act(observation, doorway_map())

    assert first_action(DEFAULT, obstacle=True)[0] == pytest.approx(0.15)  # drives on
    assert first_action(ENV, obstacle=False)[0] == pytest.approx(0.05)
    assert first_action(ENV, obstacle=True)[0] == 0.0  # stopped by the guard


def test_the_team_judges_plain_sight_by_the_env_peer_sensor() -> None:
    def rejected_unseen(env: EnvConfig) -> bool:
        team = TeamCoordinator.for_env(env, rng=np.random.default_rng(0))
        assert all(e.config == ExplorerConfig.for_env(env) for e in team.explorers)
        free = GridMap(cells=np.full((100, 200), FREE, dtype=np.int8), resolution=0.1)
        poses = [np.array([5.0, 5.0, 0.0]), np.array([1.0, 1.0, 0.0])]
        driving = np.array([10.0, 0.0, 0.0])
        waiting = np.array([9.5, 4.0, 0.0])  # robot 1 at (10.5, 5): 5.5 m ahead, unseen
        team.hypotheses = [driving, waiting]
        rendezvous = _Rendezvous(
            hypothesis=driving, index=0, meeting_point=np.array([8.0, 5.0]), started=0
        )
        for _ in range(UNSEEN_STEPS):
            team.verification.test_waiting(rendezvous, poses, lambda i: free)
        return any(h is waiting for h in team.rejected)

    assert TeamConfig.for_env(ENV).in_sight_range == 7.0
    assert not rejected_unseen(DEFAULT)  # 5.5 m: beyond 5 m less the margin
    assert rejected_unseen(ENV)  # well within an 8 m sensor's sight


# --- the experiment builds its team from the env --------------------------------------------


def test_the_runners_factory_builds_the_team_for_the_env() -> None:
    team = experiment.build_team(experiment.RunConfig(interaction=False, seed=3), ENV)
    assert team.config == TeamConfig.for_env(ENV, interaction=False, keep_merges=True)
    assert team.config.in_sight_range == 7.0
    for explorer in team.explorers:
        assert explorer.config.planner.robot_radius == 0.3
        assert explorer.follower.config.max_speed == 1.5
        assert explorer.follower.config.max_turn_rate == 3.0
        assert explorer.follower.config.dt == 0.05


def test_the_runner_passes_the_envs_own_config_to_the_team(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Whatever robot the env is built with, the run's team plans for that robot."""
    envs: list[Any] = []
    teams: list[TeamCoordinator] = []
    base_env, base_team = experiment.MultiRobotSlamEnv, experiment.build_team

    class OtherRobotEnv(base_env):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, config: EnvConfig, **kwargs: Any) -> None:
            config = replace(config, robot=ROBOT, peer=ENV.peer)
            super().__init__(*args, config=config, **kwargs)
            envs.append(self)

    def spy(config: experiment.RunConfig, env_config: EnvConfig) -> TeamCoordinator:
        teams.append(base_team(config, env_config))
        return teams[-1]

    monkeypatch.setattr(experiment, "MultiRobotSlamEnv", OtherRobotEnv)
    monkeypatch.setattr(experiment, "build_team", spy)
    run = experiment.RunConfig(
        max_steps=3, out=tmp_path, record=False, figure=False, progress=False
    )
    report = experiment.run_experiment(run)
    assert report["steps"] == 3
    (env,), (team,) = envs, teams
    assert env.config.robot == ROBOT
    team.config.check_env(env.config)  # raises if the team contradicts the env
    assert team.config.explorer.planner.robot_radius == 0.3
    assert team.config.explorer.follower.max_speed == 1.5
    assert team.config.in_sight_range == 7.0


# --- the progress bar of ``mrslam run`` ---------------------------------------------------------


def test_a_run_that_ends_early_ends_its_progress_bar_at_100_percent(capsys: Any) -> None:
    with experiment._progress(3000, enabled=True) as bar:
        for _ in range(600):
            bar.update(1)
    assert (bar.n, bar.total) == (600, 600)
    err = capsys.readouterr().err
    assert "100%" in err and "600/600" in err


def test_a_full_run_keeps_its_total_and_an_interrupted_one_is_not_complete() -> None:
    with experiment._progress(50, enabled=True) as bar:
        bar.update(50)
    assert (bar.n, bar.total) == (50, 50)
    with pytest.raises(RuntimeError), experiment._progress(50, enabled=True) as bar:
        bar.update(10)
        raise RuntimeError("interrupted")
    assert (bar.n, bar.total) == (10, 50)
    with experiment._progress(50, enabled=False) as bar:
        bar.update(10)
    assert bar.total == 50
