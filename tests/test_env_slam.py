"""The env's onboard SLAM: pose and local-map observations, robot maps, map-based reward."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from agents.wander import WanderPolicy
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.evaluation import map_agreement
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import UNKNOWN
from mrslam_env.sim.world import WorldSpec, box, ground_truth_map
from mrslam_env.slam.config import SlamConfig
from mrslam_env.slam.local_map import FREE_CHANNEL, OCCUPIED_CHANNEL


def long_room() -> WorldSpec:
    """An 8 m x 4 m room (inner faces at x = 0.1, 7.9 and y = 0.1, 3.9)."""
    walls = [box(0, 0, 8, 0.1), box(0, 3.9, 8, 4), box(0, 0, 0.1, 4), box(7.9, 0, 8, 4)]
    return WorldSpec.from_walls("long_room", walls, [(3.0, 2.0, 0.0)])


def wander(env: MultiRobotSlamEnv, steps: int, seed: int = 0):
    observations, infos = env.reset(seed=seed)
    n_beams = env.config.lidar.n_beams
    policies = [WanderPolicy(n_beams, np.random.default_rng([seed, i])) for i in range(2)]
    history = []
    for _ in range(steps):
        actions = {
            agent: policies[i].act(observations[agent]["scan"])
            for i, agent in enumerate(env.agents)
        }
        observations, rewards, _, _, infos = env.step(actions)
        history.append((observations, rewards, infos))
    return history


def test_observations_carry_the_slam_pose_and_local_map() -> None:
    env = MultiRobotSlamEnv(scenario="office", seed=1)
    history = wander(env, 50, seed=1)
    for observations, _, _ in history[::10]:
        for agent in env.agents:
            assert env.observation_space(agent).contains(observations[agent])
            assert observations[agent]["local_map"].shape == (2, 64, 64)
    for agent in env.agents:
        observation = history[-1][0][agent]
        np.testing.assert_array_equal(observation["pose"], env.robot_slam(agent).pose)
        np.testing.assert_array_equal(observation["pose"], env.robot_slam(agent).trajectory[-1])
    # The local map shows known space around the robot, walls among it.
    crop = observation["local_map"]
    assert crop[FREE_CHANNEL].sum() > 500 and crop[OCCUPIED_CHANNEL].sum() > 30


def crop_at(heading: float) -> np.ndarray:
    # Off the cell boundaries: every wall face lands well inside one crop cell.
    config = EnvConfig(starts=((3.03, 2.03, heading),))
    env = MultiRobotSlamEnv(scenario=long_room(), n_robots=1, seed=0, config=config)
    observations, _ = env.reset()
    return observations["robot_0"]["local_map"][OCCUPIED_CHANNEL]


def occupied_indices(line: np.ndarray) -> list[int]:
    return [int(i) for i in np.flatnonzero(line)]


def test_local_map_is_centred_on_the_robot_and_turns_with_it() -> None:
    # 64 cells of 0.1 m: the robot at the centre (index 32), looking along +column.
    facing_x = crop_at(0.0)
    # Row 32 runs along the heading: the wall behind, 2.93 m back (column 32 - 30 = 2);
    # the wall ahead is 4.87 m away, beyond the crop.
    assert occupied_indices(facing_x[32]) == [2]
    # Column 32 runs to the left (+row, wall 1.87 m away) and right (1.93 m).
    assert occupied_indices(facing_x[:, 32]) == [12, 50]
    # Turned left by 90°: those walls are now ahead and behind, the 2.93 m one left.
    facing_y = crop_at(np.pi / 2)
    assert occupied_indices(facing_y[32]) == [12, 50]
    assert occupied_indices(facing_y[:, 32]) == [61]


def test_reward_is_the_growth_of_the_robots_own_map() -> None:
    config = EnvConfig(reward=replace(EnvConfig().reward, collision_penalty=0.0))
    env = MultiRobotSlamEnv(scenario="office", seed=2, config=config)
    history = wander(env, 200, seed=2)
    for agent in env.agents:
        total = sum(rewards[agent] for _, rewards, _ in history)
        robot_map = env.robot_map(agent)
        known_area = np.count_nonzero(robot_map.cells != UNKNOWN) * robot_map.resolution**2
        assert history[-1][2][agent]["observed_area"] == pytest.approx(known_area)
        area_after_reset = known_area - total
        assert 0.0 < area_after_reset < known_area and total > 5.0


def test_robot_maps_line_up_with_the_ground_truth() -> None:
    env = MultiRobotSlamEnv(scenario="office", seed=3)
    wander(env, 300, seed=3)
    truth = ground_truth_map(env.world, 0.05, margin=1.0)
    for i, agent in enumerate(env.agents):
        world_from_map = env.simulator.starts[i]
        assert map_agreement(env.robot_map(agent), world_from_map, truth) >= 0.97


def test_slam_modes_are_selectable() -> None:
    odometry = MultiRobotSlamEnv(
        scenario="office", seed=4, config=EnvConfig(slam=SlamConfig(mode="odometry"))
    )
    observations, _, _ = wander(odometry, 40, seed=4)[-1]
    for agent in odometry.agents:  # odometry starts at zero: dead reckoning is the pose
        np.testing.assert_allclose(observations[agent]["pose"], observations[agent]["odom"])
    truth = MultiRobotSlamEnv(
        scenario="office",
        seed=4,
        config=EnvConfig(slam=SlamConfig(mode="ground_truth")),
        privileged=True,
    )
    observations, _, infos = wander(truth, 40, seed=4)[-1]
    for i, agent in enumerate(truth.agents):
        expected = compose(inverse(truth.simulator.starts[i]), infos[agent]["true_pose"])
        np.testing.assert_allclose(observations[agent]["pose"], expected, atol=1e-12)


def test_slam_off_is_the_raw_simulator() -> None:
    env = MultiRobotSlamEnv(scenario="office", seed=5, config=EnvConfig(slam=None))
    observations, infos = env.reset()
    assert set(observations["robot_0"]) == {"scan", "odom", "peer", "comm"}
    assert infos["robot_0"]["observed_area"] > 0.0
    with pytest.raises(RuntimeError, match="onboard SLAM is off"):
        env.robot_map("robot_0")


def test_robot_map_names_a_bad_agent() -> None:
    env = MultiRobotSlamEnv(scenario="office", seed=6)
    with pytest.raises(RuntimeError, match="not been reset"):
        env.robot_map("robot_0")
    env.reset()
    with pytest.raises(ValueError, match="unknown agent 'robot_9'"):
        env.robot_map("robot_9")
