"""The RL battery, without shims: PettingZoo's own tests on ``mrslam_env`` as a package
(AEC through ``mrslam_env.env()``, ``max_cycles`` keyword, ``render_mode="human"``) and
Gymnasium's ``check_env`` on the single-robot env. Small worlds and few cycles (one core)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Any

import gymnasium
import pettingzoo
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    seed_test,
    state_test,
)

import mrslam_env
from mrslam_env.config import EnvConfig

SCENARIO = "tb3_sandbox"
FAST = EnvConfig(lidar=replace(EnvConfig().lidar, n_beams=90))


@pytest.fixture(autouse=True)
def quiet() -> Any:
    # Headless "human" rendering warns once per env; PettingZoo's tests warn about
    # observations they find unusual (a 0/1 map is "all zeros" before anything is known).
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def test_package_env_is_the_aec_constructor() -> None:
    from mrslam_env import env

    assert callable(env)
    import mrslam_env.env as module  # the submodule import must not change the answer

    assert isinstance(mrslam_env.env(scenario=SCENARIO), pettingzoo.AECEnv)
    assert isinstance(module.env(scenario=SCENARIO), pettingzoo.AECEnv)
    assert isinstance(module.parallel_env(scenario=SCENARIO), pettingzoo.ParallelEnv)


@pytest.mark.parametrize("flat", [False, True])
def test_pettingzoo_api_and_seed_tests(flat: bool) -> None:
    config = replace(FAST, flat_observation=flat)
    api_test(mrslam_env.env(scenario=SCENARIO, seed=0, config=config), num_cycles=15)
    parallel_api_test(
        mrslam_env.parallel_env(scenario=SCENARIO, seed=0, config=config), num_cycles=15
    )
    seed_test(lambda: mrslam_env.env(scenario=SCENARIO, config=config), num_cycles=10)
    parallel_seed_test(
        lambda: mrslam_env.parallel_env(scenario=SCENARIO, config=config), num_cycles=10
    )


def test_state_test() -> None:
    state_test(
        mrslam_env.env(scenario=SCENARIO, config=FAST),
        mrslam_env.parallel_env(scenario=SCENARIO, config=FAST),
        num_cycles=5,
    )


@pytest.mark.parametrize("flat", [False, True])
def test_omitted_local_maps_change_nothing_else(flat: bool) -> None:
    import numpy as np

    from mrslam_env.env import MultiRobotSlamEnv

    config = replace(FAST, flat_observation=flat)
    whole = MultiRobotSlamEnv(scenario=SCENARIO, n_robots=3, config=config)
    lean = MultiRobotSlamEnv(scenario=SCENARIO, n_robots=3, config=config)
    lean.omit_local_map(["robot_1", "robot_2"])
    with pytest.raises(ValueError, match="unknown agents"):
        lean.omit_local_map(["robot_9"])
    first, _ = whole.reset(seed=4)
    second, _ = lean.reset(seed=4)
    rng = np.random.default_rng(0)
    for step in range(25):
        for agent in whole.possible_agents:
            a, b = first[agent], second[agent]
            if flat:  # the flat observation always holds the crop
                assert np.array_equal(a, b)
                continue
            assert ("local_map" in b) == (agent == "robot_0")
            assert a.keys() - b.keys() <= {"local_map"}
            assert all(np.array_equal(a[key], b[key]) for key in b)
        assert np.array_equal(whole.state(), lean.state())
        actions = {agent: rng.uniform(-1, 1, 2) for agent in whole.possible_agents}
        first, rewards, _, _, infos = whole.step(actions)
        second, lean_rewards, _, _, lean_infos = lean.step(actions)
        assert rewards == lean_rewards and repr(infos) == repr(lean_infos), step


def test_max_cycles_test_on_the_package() -> None:
    max_cycles_test(mrslam_env)  # mod.parallel_env(max_cycles=4), mod.env(max_cycles=4)


def test_render_test_with_human_mode() -> None:
    def make(render_mode: str | None = None) -> pettingzoo.AECEnv:
        return mrslam_env.env(scenario=SCENARIO, render_mode=render_mode, config=FAST)

    render_test(make)


@pytest.mark.parametrize(
    ("teammates", "slam"),
    [("frontier", True), ("frontier", False), ("wander", False), ("idle", True)],
)
def test_gymnasium_check_env_on_the_single_robot_env(teammates: str, slam: bool) -> None:
    import mrslam_env.wrappers  # registers the id

    config = FAST if slam else replace(FAST, slam=None)
    made = gymnasium.make(
        mrslam_env.wrappers.SINGLE_ROBOT_ID,
        scenario=SCENARIO,
        teammates=teammates,
        config=config,
        max_cycles=20,
        render_mode="rgb_array",
    )
    check_env(made.unwrapped)
    observation, _ = made.reset(seed=3)
    assert made.observation_space.contains(observation)
    for _ in range(20):
        observation, _, terminated, truncated, _ = made.step(made.action_space.sample())
        assert made.observation_space.contains(observation) and not terminated
    assert truncated
    made.close()


def test_throughput_benchmark_times_every_rl_configuration() -> None:
    from scenarios.bench.sim import bench_rl

    rows, teammate = bench_rl(SCENARIO, n_steps=12, repeats=1)
    names = [row.configuration for row in rows]
    assert names == [
        "parallel, Dict, SLAM off",
        "parallel, Dict, SLAM on",
        "parallel, flat, SLAM off",
        "parallel, flat, SLAM on",
        "single-robot env, 1 idle teammate, SLAM on",
        "single-robot env, 1 frontier teammate, SLAM on",
        "AsyncVectorEnv, 2 processes x single-robot env (frontier)",
    ]
    for row in rows[:4]:  # two robots act in each parallel env step
        assert row.agent_steps_per_s == pytest.approx(2 * row.env_steps_per_s)
    assert all(row.agent_steps_per_s > 0 for row in rows)
    figures = teammate.as_dict()
    assert figures["explorer_ms_per_step"] > 0 and figures["robot_map_ms_per_step"] > 0
    assert figures["replans_per_100_steps"] > 0  # the first step plans
