"""The PettingZoo environment: conformance, determinism, physics safety, bad input."""

from __future__ import annotations

import pickle
import warnings
from dataclasses import replace

import numpy as np
import pettingzoo
import pytest
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, render_test

from mrslam_env import ENV_ID
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv, env, parallel_env
from mrslam_env.gridmap import OCCUPIED
from mrslam_env.mapio import load_map, save_map
from mrslam_env.registry import UnknownScenarioError, available_scenarios
from mrslam_env.sim.world import WorldSpec, box, ground_truth_map
from scenarios.bench.sim import driving_commands


def scenario_names() -> list[str]:
    names = []
    for key, scenario in sorted(available_scenarios().items()):
        names += [f"{key}-0", f"{key}-3"] if scenario.parametric else [key]
    return names


SCENARIOS = scenario_names()


def small_world() -> WorldSpec:
    walls = [box(0, 0, 8, 0.1), box(0, 0, 0.1, 6), box(7.9, 0, 8, 6), box(0, 5.9, 8, 6)]
    walls.append(box(3.9, 0.0, 4.0, 4.0))
    return WorldSpec.from_walls("small", walls, [(1.5, 1.5, 0.0), (6.0, 4.5, 2.0)])


def assert_same(a: object, b: object) -> None:
    """Bit-identical nested dicts and tuples of arrays and scalars."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, tuple | list):
        assert isinstance(b, tuple | list) and len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_same(x, y)
    else:
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_builtin_catalogue_has_the_promised_worlds() -> None:
    catalogue = available_scenarios()
    assert {"office", "warehouse", "maze", "twin_wings", "procedural"} <= set(catalogue)
    assert catalogue["procedural"].parametric


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_pettingzoo_conformance(scenario: str) -> None:
    parallel_api_test(parallel_env(scenario=scenario, seed=0), num_cycles=60)
    parallel_seed_test(lambda: parallel_env(scenario=scenario), num_cycles=20)
    api_test(env(scenario=scenario, seed=0), num_cycles=20)

    # "human" on a headless machine warns once and draws nothing (render returns None).
    def make(render_mode: str | None = None) -> pettingzoo.AECEnv:
        return env(scenario=scenario, render_mode=render_mode)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        render_test(make)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_multi_step_determinism_and_pickling(scenario: str) -> None:
    steps = 150
    commands = driving_commands(steps, 2, seed=4)
    first, second = parallel_env(scenario=scenario), parallel_env(scenario=scenario)
    outputs = []
    for e in (first, second):
        run = [e.reset(seed=11)]
        for k in range(steps):
            run.append(e.step({a: commands[k, i] for i, a in enumerate(e.possible_agents)}))
        outputs.append(run)
    for a, b in zip(*outputs, strict=True):
        assert_same(a, b)

    # A pickled env continues exactly like the original, also while robots touch walls.
    clone = pickle.loads(pickle.dumps(first))
    for k in range(40):
        actions = {a: commands[k, i] for i, a in enumerate(first.possible_agents)}
        assert_same(first.step(actions), clone.step(actions))

    # Another seed gives another run (sensor noise differs).
    first.reset(seed=12)
    other = first.step({a: commands[0, i] for i, a in enumerate(first.possible_agents)})
    assert not np.array_equal(other[0]["robot_0"]["scan"], outputs[0][1][0]["robot_0"]["scan"])


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_full_speed_never_inside_a_wall(scenario: str, tmp_path) -> None:
    """Thousands of full-speed steps; robot centres checked against the exported raster.

    The physics alone is under test, so the onboard SLAM is off (a fifth of the cost);
    the observations with SLAM are checked against their spaces by the API tests above.
    """
    steps = 2000
    config = EnvConfig(max_cycles=steps, slam=None, privileged=True)
    e = MultiRobotSlamEnv(scenario=scenario, seed=1, config=config)
    observations, infos = e.reset()
    # Ground truth as a user gets it: exported to a ROS map and read back.
    exported = load_map(save_map(tmp_path / "gt.yaml", ground_truth_map(e.world, 0.05)))
    commands = driving_commands(steps, 2, seed=7)
    commands[..., 0] = np.sign(commands[..., 0])  # full speed, forwards
    commands[::50, :, 0] *= -1  # and now and then a burst backwards
    observation_spaces = {a: e.observation_space(a) for a in e.possible_agents}
    for k in range(steps):
        observations, _, _, _, infos = e.step(
            {a: commands[k, i] for i, a in enumerate(e.possible_agents)}
        )
        poses = np.array([infos[a]["true_pose"] for a in e.possible_agents])
        cells = exported.world_to_cell(poses[:, :2])
        assert exported.contains(cells).all(), f"robot left the map at step {k}"
        assert not (exported.cells[cells[:, 0], cells[:, 1]] == OCCUPIED).any(), (
            f"robot centre inside a wall at step {k}: {poses}"
        )
        if k % 100 == 0:
            for a in e.possible_agents:
                assert observation_spaces[a].contains(observations[a]), f"{a} obs out of space"
    assert (e.world.clearance(poses[:, :2]) > e.config.robot.radius - 0.01).all()


def test_rewards_count_new_area_and_collisions() -> None:
    config = EnvConfig(reward=replace(EnvConfig().reward, collision_penalty=5.0))
    e = MultiRobotSlamEnv(scenario=small_world(), seed=0, config=config)
    e.reset()
    _, rewards, _, _, infos = e.step({a: np.array([0.5, 0.0]) for a in e.agents})
    # The first scan was counted at reset: a short move adds a little new area, not a lot.
    assert all(0.0 <= r < 5.0 for r in rewards.values())
    area_after_reset = infos["robot_0"]["observed_area"]
    assert 0.3 * e.observable_area < area_after_reset <= e.observable_area + 1e-9
    # Drive robot_0 into the wall ahead (x = 3.9) until it touches: penalty applies.
    touched = False
    for _ in range(60):
        _, rewards, _, _, infos = e.step({"robot_0": np.array([1.0, 0.0]), "robot_1": np.zeros(2)})
        if infos["robot_0"]["collision"]:
            touched = True
            assert rewards["robot_0"] <= -5.0 + 1.0
            break
    assert touched


def test_truncation_ends_the_episode() -> None:
    e = parallel_env(scenario=small_world(), config=EnvConfig(max_cycles=3))
    e.reset(seed=0)
    for k in range(3):
        _, _, terminations, truncations, _ = e.step({a: np.zeros(2) for a in e.agents})
        assert not any(terminations.values())
        assert all(truncations.values()) == (k == 2)
    assert e.agents == []
    with pytest.raises(RuntimeError, match="episode ended"):
        e.step({})


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_names_the_agent(bad: float) -> None:
    e = parallel_env(scenario=small_world())
    e.reset(seed=0)
    with pytest.raises(ValueError, match="robot_1"):
        e.step({"robot_0": np.zeros(2), "robot_1": np.array([0.2, bad])})


def test_out_of_range_actions_are_clipped() -> None:
    runs = []
    for action in ([1.0, -1.0], [7.0, -3.5]):
        e = parallel_env(scenario=small_world(), privileged=True)
        e.reset(seed=3)
        for _ in range(10):
            out = e.step({a: np.array(action) for a in e.agents})
        runs.append(out)
    for a in ("robot_0", "robot_1"):
        np.testing.assert_array_equal(runs[0][4][a]["true_pose"], runs[1][4][a]["true_pose"])


def test_bad_action_shape_and_missing_agent() -> None:
    e = parallel_env(scenario=small_world())
    e.reset(seed=0)
    with pytest.raises(ValueError, match="robot_0 must have shape"):
        e.step({"robot_0": np.zeros(3), "robot_1": np.zeros(2)})
    with pytest.raises(ValueError, match="missing action for robot_1"):
        e.step({"robot_0": np.zeros(2)})


def test_unknown_scenario_lists_the_valid_ones() -> None:
    with pytest.raises(UnknownScenarioError, match=r"valid scenarios: .*office"):
        parallel_env(scenario="ofice")


def test_start_inside_a_wall_is_refused() -> None:
    config = EnvConfig(starts=((3.95, 2.0, 0.0), (6.0, 4.5, 0.0)))
    e = parallel_env(scenario=small_world(), config=config)
    with pytest.raises(ValueError, match=r"start pose 0 .* inside a wall"):
        e.reset(seed=0)


def test_more_robots_get_automatic_starts() -> None:
    e = parallel_env(scenario=small_world(), n_robots=4, seed=2, privileged=True)
    observations, infos = e.reset()
    assert e.agents == ["robot_0", "robot_1", "robot_2", "robot_3"]
    poses = np.array([infos[a]["true_pose"] for a in e.agents])
    assert (small_world().clearance(poses[:, :2]) > 0.45).all()
    assert observations["robot_2"]["peer"].shape == (3, 4)
    assert observations["robot_2"]["comm"].shape == (3,)


def test_registered_with_pettingzoo() -> None:
    par = pettingzoo.make("parallel", ENV_ID, scenario=small_world(), seed=0)
    aec = pettingzoo.make("aec", ENV_ID, scenario=small_world(), seed=0)
    assert isinstance(par, MultiRobotSlamEnv)
    assert isinstance(aec, pettingzoo.AECEnv)


def test_render_draws_walls_and_robots() -> None:
    e = parallel_env(scenario=small_world(), render_mode="rgb_array")
    e.reset(seed=0)
    image = e.render()
    assert image is not None and image.dtype == np.uint8 and image.ndim == 3
    dark = (image.sum(axis=2) < 200).mean()
    coloured = ((image[..., 0] < 100) & (image[..., 2] > 150)).sum()  # robot_0 is blue
    assert 0.01 < dark < 0.2
    assert coloured > 20


def test_invalid_render_mode_is_refused() -> None:
    with pytest.raises(ValueError, match="render_mode"):
        parallel_env(scenario=small_world(), render_mode="ansi")
