"""RL adapters: the flat observation and its layout, state(), the single-robot Gymnasium
env, the once-per-cell reward with team novelty, privileged infos, varying episodes."""

from __future__ import annotations

from dataclasses import replace

import gymnasium
import numpy as np
import pytest

from agents.explorer import ExplorerPolicy
from agents.single_robot import SingleRobotEnv
from agents.wander import WanderPolicy
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.wrappers import SINGLE_ROBOT_ID, ObservationFlattener

SMALL = "tb3_sandbox"
FAST = EnvConfig(lidar=replace(EnvConfig().lidar, n_beams=90))


def test_flat_layout_order_sizes_and_bounds() -> None:
    flattener = ObservationFlattener(FAST, 3)
    layout = flattener.layout()
    cells = FAST.local_map.cells
    assert list(layout) == ["scan", "odom", "peer", "comm", "pose", "local_map"]
    sizes = {name: s.stop - s.start for name, s in layout.items()}
    assert sizes == {
        "scan": 90,
        "odom": 3,
        "peer": 8,
        "comm": 2,
        "pose": 3,
        "local_map": 2 * cells * cells,
    }
    assert layout["scan"].start == 0 and layout["local_map"].stop == flattener.size
    space = flattener.space
    assert space.dtype == np.float32 and space.shape == (flattener.size,)
    assert (space.low[layout["odom"]] == -1).all() and (space.low[layout["scan"]] == 0).all()
    assert (space.high == 1).all()
    no_slam = ObservationFlattener(replace(FAST, slam=None), 2)
    assert list(no_slam.layout()) == ["scan", "odom", "peer", "comm"]


def test_flat_values_are_the_scaled_dict_observation() -> None:
    dict_env = MultiRobotSlamEnv(scenario=SMALL, seed=4, config=FAST)
    flat_env = MultiRobotSlamEnv(
        scenario=SMALL, seed=4, config=replace(FAST, flat_observation=True)
    )
    flattener = ObservationFlattener(FAST, 2)
    layout = flattener.layout()
    observations, _ = dict_env.reset()
    flat, _ = flat_env.reset()
    for _ in range(5):
        actions = {a: np.array([0.6, 0.3], dtype=np.float32) for a in dict_env.agents}
        observations = dict_env.step(actions)[0]
        flat = flat_env.step(actions)[0]
    for agent in dict_env.agents:
        vector, obs = flat[agent], observations[agent]
        assert flat_env.observation_space(agent).contains(vector)
        np.testing.assert_array_equal(vector, flattener(obs))
        np.testing.assert_allclose(vector[layout["scan"]], obs["scan"] / 8.0, rtol=1e-6)
        scale = FAST.flat_length_scale
        np.testing.assert_allclose(vector[layout["odom"]][:2], obs["odom"][:2] / scale, rtol=1e-5)
        np.testing.assert_allclose(vector[layout["pose"]][2], obs["pose"][2] / np.pi, rtol=1e-5)
        crop = vector[layout["local_map"]]
        assert set(np.unique(crop)) <= {0.0, 1.0}
        np.testing.assert_array_equal(crop, obs["local_map"].ravel())
    # Far-away poses are clipped into the bounds.
    far = dict(observations["robot_0"], odom=np.array([1e4, -1e4, 3.0]))
    assert flattener.space.contains(flattener(far))


def test_state_is_every_robots_flat_observation() -> None:
    env = MultiRobotSlamEnv(scenario=SMALL, n_robots=3, seed=1, config=FAST)
    observations, _ = env.reset()
    flattener = ObservationFlattener(FAST, 3)
    for _ in range(3):
        observations = env.step({a: np.array([0.5, -0.2]) for a in env.agents})[0]
    state = env.state()
    assert env.state_space.contains(state) and state.shape == (3 * flattener.size,)
    expected = np.concatenate([flattener(observations[a]) for a in env.possible_agents])
    np.testing.assert_array_equal(state, expected)


def test_privileged_infos_are_named_and_not_observed() -> None:
    env = MultiRobotSlamEnv(scenario=SMALL, seed=0, config=FAST, max_cycles=7, privileged=True)
    assert env.config.max_cycles == 7 and env.config.privileged
    observations, infos = env.reset()
    for agent in env.agents:
        privileged = infos[agent]["privileged"]
        np.testing.assert_array_equal(privileged["true_pose"], infos[agent]["true_pose"])
        assert {"covered_area", "coverage", "team_covered_area", "team_coverage"} <= set(privileged)
        assert 0.0 < privileged["coverage"] <= privileged["team_coverage"] <= 1.0
        assert "true_pose" not in observations[agent]
        assert "true_pose" not in env.observation_space(agent).spaces


@pytest.mark.parametrize("privileged", [None, False])
def test_no_ground_truth_in_the_infos_unless_asked_for(privileged: bool | None) -> None:
    # The default, and an explicit False: flat numbers only, the same as with ground truth.
    env = MultiRobotSlamEnv(scenario=SMALL, seed=0, config=FAST, privileged=privileged)
    told = MultiRobotSlamEnv(scenario=SMALL, seed=0, config=replace(FAST, privileged=True))
    assert not env.config.privileged and told.config.privileged
    results = [(env.reset()[1], told.reset()[1])]
    actions = {agent: np.array([0.5, 0.2]) for agent in env.agents}
    results.append((env.step(actions)[4], told.step(actions)[4]))
    for infos, told_infos in results:
        for agent in env.agents:
            assert set(infos[agent]) == {"collision", "observed_area", "new_area"}
            assert set(told_infos[agent]) == {*infos[agent], "true_pose", "privileged"}
            assert all(infos[agent][key] == told_infos[agent][key] for key in infos[agent])
    with pytest.raises(ValueError, match=r"EnvConfig\.privileged must be a bool, got 'yes'"):
        MultiRobotSlamEnv(scenario=SMALL, privileged="yes")  # type: ignore[arg-type]


def run_explorers(env: MultiRobotSlamEnv, steps: int):
    observations, infos = env.reset()
    policies = [
        ExplorerPolicy.for_env(env.config, np.random.default_rng(i))
        for i in range(len(env.possible_agents))
    ]
    history = [(None, infos)]
    for _ in range(steps):
        actions = {
            a: policies[i].act(observations[a], env.robot_map(a)) for i, a in enumerate(env.agents)
        }
        observations, rewards, _, _, infos = env.step(actions)
        history.append((rewards, infos))
    return history


def test_area_reward_is_paid_once_per_cell_and_never_negative() -> None:
    # The issue: with the frontier explorer the mapped area sometimes shrinks (log-odds
    # drift cells back to unknown), and a reward of "known area now - before" went
    # negative without any collision. The reward now pays a cell the first time only.
    config = EnvConfig(reward=replace(EnvConfig().reward, team_novelty_weight=0.5))
    env = MultiRobotSlamEnv(scenario="office", seed=0, config=config, privileged=True)
    history = run_explorers(env, 200)
    shrinking = 0
    for agent in env.possible_agents:
        previous = history[0][1][agent]
        for rewards, infos in history[1:]:
            info = infos[agent]
            if not info["collision"]:
                assert rewards[agent] >= 0.0
            expected = info["new_area"] + 0.5 * info["privileged"]["team_new_area"]
            expected -= float(info["collision"])
            assert rewards[agent] == pytest.approx(expected)
            shrinking += info["observed_area"] < previous["observed_area"] - 1e-9
            assert info["privileged"]["covered_area"] >= previous["privileged"]["covered_area"]
            previous = info
        # Paid area = the area ever known beyond the first scan >= today's known area.
        paid = sum(infos[agent]["new_area"] for _, infos in history[1:])
        first = history[0][1][agent]["new_area"]
        assert paid + first >= history[-1][1][agent]["observed_area"] - 1e-9
    assert shrinking > 0  # the case the fix is about did occur


@pytest.mark.parametrize("slam", [True, False])
def test_team_novelty_pays_only_area_no_teammate_knew(slam: bool) -> None:
    reward = replace(EnvConfig().reward, area_weight=0.0, collision_penalty=0.0)
    config = replace(FAST, reward=reward)
    config = replace(config, reward=replace(reward, team_novelty_weight=1.0))
    if not slam:
        config = replace(config, slam=None)
    env = MultiRobotSlamEnv(scenario=SMALL, seed=5, config=config, privileged=True)
    observations, infos = env.reset()
    team_start = infos["robot_0"]["privileged"]["team_covered_area"]
    policies = [WanderPolicy.for_env(config, np.random.default_rng(i)) for i in range(2)]
    total = 0.0
    for _ in range(80):
        actions = {a: policies[i].act(observations[a]["scan"]) for i, a in enumerate(env.agents)}
        observations, rewards, _, _, infos = env.step(actions)
        assert all(r >= 0.0 for r in rewards.values())
        for agent in env.agents:
            privileged = infos[agent]["privileged"]
            assert rewards[agent] == pytest.approx(privileged["team_new_area"])
            assert privileged["covered_area"] <= privileged["team_covered_area"] + 1e-9
        total += sum(rewards.values())
    team_end = infos["robot_0"]["privileged"]["team_covered_area"]
    # Cells first covered by both robots in the same step pay both: >=, not ==.
    assert total >= team_end - team_start - 1e-9
    assert total > 0.0


def test_slam_off_reward_is_never_negative_without_collision() -> None:
    config = replace(FAST, slam=None)
    env = MultiRobotSlamEnv(scenario=SMALL, seed=2, config=config)
    observations, _ = env.reset()
    policies = [WanderPolicy.for_env(config, np.random.default_rng(i)) for i in range(2)]
    for _ in range(150):
        actions = {a: policies[i].act(observations[a]["scan"]) for i, a in enumerate(env.agents)}
        observations, rewards, _, _, infos = env.step(actions)
        for agent in env.agents:
            if not infos[agent]["collision"]:
                assert rewards[agent] >= 0.0


def starts_of(env: MultiRobotSlamEnv, seed: int, **options: object) -> np.ndarray:
    _, infos = env.reset(seed=seed, options=options or None)
    return np.array([infos[a]["true_pose"] for a in env.possible_agents])


def test_random_starts_per_episode_deterministic_per_seed() -> None:
    env = MultiRobotSlamEnv(scenario=SMALL, config=FAST, privileged=True)
    fixed = starts_of(env, 0)
    np.testing.assert_array_equal(fixed, starts_of(env, 1))  # the scenario's starts
    a, b = starts_of(env, 0, randomize_starts=True), starts_of(env, 1, randomize_starts=True)
    assert not np.array_equal(a, b) and not np.array_equal(a, fixed)
    np.testing.assert_array_equal(a, starts_of(env, 0, randomize_starts=True))
    switch = MultiRobotSlamEnv(
        scenario=SMALL, config=replace(FAST, randomize_starts=True), privileged=True
    )
    np.testing.assert_array_equal(starts_of(switch, 0), a)
    assert (env.world.clearance(a[:, :2]) > FAST.robot.radius).all()


def test_fresh_procedural_world_per_episode() -> None:
    config = replace(FAST, randomize_world=True)
    env = MultiRobotSlamEnv(scenario="procedural", config=config)
    names = []
    for seed in (0, 1, 0):
        env.reset(seed=seed)
        names.append(env.world.name)
    assert names[0] == names[2] != names[1]
    with pytest.raises(ValueError, match="parametric"):
        MultiRobotSlamEnv(scenario="office", config=config)
    with pytest.raises(ValueError, match="parametric"):
        env.reset(seed=0, options={"scenario": "office"})
    env.reset(seed=0, options={"scenario": "procedural-5"})
    assert env.world.name == "procedural-5"
    env.reset(seed=0)
    assert env.world.name == names[0]  # drawn from the family again


def test_reset_option_switches_the_scenario() -> None:
    env = MultiRobotSlamEnv(scenario=SMALL, seed=0, config=FAST)
    env.reset()
    env.reset(seed=0, options={"scenario": "maze"})
    assert env.world.name == "maze" and env.observable_area > 0
    env.step({a: np.zeros(2) for a in env.agents})
    with pytest.raises(ValueError, match="scenario"):
        env.reset(options={"scenario": 3})


def test_single_robot_env_registration_and_teammates() -> None:
    assert SINGLE_ROBOT_ID in gymnasium.registry
    made = gymnasium.make(SINGLE_ROBOT_ID, scenario=SMALL, teammates="idle", config=FAST)
    assert isinstance(made.unwrapped, SingleRobotEnv)
    with pytest.raises(ValueError, match="teammates must be one of"):
        SingleRobotEnv(scenario=SMALL, teammates="chase")
    alone = SingleRobotEnv(scenario=SMALL, n_robots=1, teammates="frontier", config=FAST)
    observation, _ = alone.reset(seed=0)
    assert alone.observation_space.contains(observation)


@pytest.mark.parametrize(
    ("teammates", "slam"), [("frontier", True), ("frontier", False), ("wander", True)]
)
def test_single_robot_env_is_deterministic_and_teammates_move(teammates: str, slam: bool) -> None:
    # With SLAM off the frontier teammate maps on its own odometry and scans.
    config = FAST if slam else replace(FAST, slam=None)
    runs = []
    for _ in range(2):
        env = SingleRobotEnv(scenario=SMALL, teammates=teammates, config=config, max_cycles=30)
        observation, _ = env.reset(seed=9)
        trace = [observation]
        for _ in range(30):
            observation, _, _, truncated, _ = env.step(np.array([0.3, 0.1], np.float32))
            trace.append(observation)
        assert truncated
        teammate = env.multi.simulator.state.true_poses[1]
        runs.append((np.array(trace), teammate))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    start = env.multi.simulator.starts[1]
    assert np.hypot(*(runs[0][1][:2] - start[:2])) > 0.1  # the scripted teammate drove
