"""The training examples (issue 18) train for a few hundred steps, save a policy, and the
saved policy acts: the SB3 model directly and as an exploration policy through
examples/sb3_policy.py, the RLlib checkpoint through its RLModule.

Each example runs as a user would run it (a subprocess, small size knobs, one torch
thread, files in a temporary folder).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from test_examples import EXAMPLES, numbers, run_example

from agents.policy import ExplorationPolicy, PolicyContext, load_policy_factory
from mrslam_env import parallel_env
from mrslam_env.config import EnvConfig
from mrslam_env.wrappers import ObservationFlattener

# One torch thread (the machine has two cores, shared with the rest of the suite); never a
# Ray cluster named by the caller's environment.
QUIET = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "RAY_ADDRESS": ""}
SEED = 3


def observations_after(steps: int, config: EnvConfig, n_robots: int = 2) -> tuple[dict, object]:
    """The env's observations after ``steps`` fixed forward-turning steps from seed SEED."""
    env = parallel_env(scenario="office", n_robots=n_robots, config=config)
    observations, _ = env.reset(seed=SEED)
    action = np.array([0.6, 0.3], dtype=np.float32)
    for _ in range(steps):
        observations, *_ = env.step(dict.fromkeys(env.agents, action))
    return observations, env


@pytest.fixture(scope="module")
def sb3_model(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    folder = tmp_path_factory.mktemp("sb3")
    out = run_example(
        "train_sb3_ppo.py",
        *("--steps", "256", "--episode-steps", "64", "--seed", "1", "--out", "model.zip"),
        cwd=folder,
        timeout=240.0,
        environment=QUIET,
    )
    return folder / "model.zip", out


def test_sb3_example_saves_a_model_that_acts_on_the_flat_observation(
    sb3_model: tuple[Path, str],
) -> None:
    from stable_baselines3 import PPO

    path, out = sb3_model
    assert numbers(r"trained (\d+) robot-steps on (\d+) robots", out) == [256, 2]
    model = PPO.load(path, device="cpu")
    assert model.num_timesteps == 256
    space = ObservationFlattener(EnvConfig(), 2).space
    assert model.observation_space.shape == space.shape
    observations, _ = observations_after(5, EnvConfig(flat_observation=True))
    batch = np.stack([observations[agent] for agent in sorted(observations)])
    actions, _ = model.predict(batch, deterministic=True)
    assert actions.shape == (2, 2)
    assert np.all(np.isfinite(actions)) and np.all(np.abs(actions) <= 1.0)


def test_sb3_policy_adapter_acts_as_the_model_on_the_training_observation(
    sb3_model: tuple[Path, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from stable_baselines3 import PPO

    path, _ = sb3_model
    monkeypatch.setenv("MRSLAM_SB3_MODEL", str(path))
    factory = load_policy_factory(f"{EXAMPLES / 'sb3_policy.py'}:sb3_policy")
    config = EnvConfig()
    policy = factory(config, np.random.default_rng(0))
    assert isinstance(policy, ExplorationPolicy)
    policy.reset()

    observations, env = observations_after(5, config)
    flat, _ = observations_after(5, EnvConfig(flat_observation=True))
    model = PPO.load(path, device="cpu")
    for index, agent in enumerate(sorted(observations)):
        observation = observations[agent]
        # The same episode: the adapter's flattening is the env's flat observation.
        np.testing.assert_array_equal(ObservationFlattener(config, 2)(observation), flat[agent])
        own_map = env.robot_map(agent)  # type: ignore[attr-defined]
        context = PolicyContext(
            robot=index, step=5, map=own_map, pose=observation["pose"], own_map=own_map
        )
        action = policy.act(observation, context)
        expected, _ = model.predict(flat[agent], deterministic=True)
        assert action.dtype == np.float32 and action.shape == (2,)
        np.testing.assert_allclose(action, np.clip(expected, -1.0, 1.0), rtol=0, atol=1e-6)


def test_sb3_policy_adapter_refuses_a_team_of_another_size(
    sb3_model: tuple[Path, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    path, _ = sb3_model
    monkeypatch.setenv("MRSLAM_SB3_MODEL", str(path))
    policy = load_policy_factory(f"{EXAMPLES / 'sb3_policy.py'}:sb3_policy")(
        EnvConfig(), np.random.default_rng(0)
    )
    observations, env = observations_after(1, EnvConfig(), n_robots=3)
    own_map = env.robot_map("robot_0")  # type: ignore[attr-defined]
    observation = observations["robot_0"]
    context = PolicyContext(robot=0, step=1, map=own_map, pose=observation["pose"], own_map=own_map)
    with pytest.raises(ValueError, match=r"shape \(8563,\).*shape \(8568,\) \(3 robots\)"):
        policy.act(observation, context)


def test_rllib_example_saves_a_shared_module_that_acts(tmp_path: Path) -> None:
    import torch
    from ray.rllib.core.rl_module.rl_module import RLModule

    out = run_example(
        "train_rllib_ppo.py",
        *("--steps", "200", "--batch", "200", "--episode-steps", "100", "--out", "checkpoint"),
        cwd=tmp_path,
        timeout=240.0,
        # Ray's sockets live under TMPDIR, in a path of at most 107 bytes.
        environment={**QUIET, "TMPDIR": tempfile.gettempdir()},
    )
    assert numbers(r"trained ([\d.]+) env steps", out) == [200]
    module_path = tmp_path / "checkpoint" / "learner_group" / "learner" / "rl_module" / "shared"
    module = RLModule.from_checkpoint(module_path)
    assert module.observation_space is not None and module.action_space is not None
    assert module.observation_space.shape == ObservationFlattener(EnvConfig(), 2).space.shape
    assert module.action_space.shape == (2,)
    observations, _ = observations_after(5, EnvConfig(flat_observation=True))
    batch = torch.from_numpy(np.stack([observations[agent] for agent in sorted(observations)]))
    with torch.no_grad():
        logits = module.forward_inference({"obs": batch})["action_dist_inputs"]
    distribution = module.get_inference_action_dist_cls().from_logits(logits)
    actions = np.asarray(distribution.to_deterministic().sample())
    assert actions.shape == (2, 2) and np.all(np.isfinite(actions))
    assert not np.array_equal(actions[0], actions[1])  # the robots see different things


def test_a_trained_sb3_policy_explores_in_bench_explore_beside_the_frontier_baseline(
    sb3_model: tuple[Path, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from scenarios.bench.explore import format_explore_table, run_explore_benchmark

    path, _ = sb3_model
    monkeypatch.setenv("MRSLAM_SB3_MODEL", str(path))
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    rows, runs = run_explore_benchmark(
        ["office"],
        range(1),
        60,
        modes=("team",),
        policy=f"{EXAMPLES / 'sb3_policy.py'}:sb3_policy",
    )
    assert [row["policy"] for row in rows] == ["frontier", "sb3_policy:sb3_policy"]
    assert [run["policy"] for run in runs] == ["frontier", "sb3_policy:sb3_policy"]
    assert all(run["steps"] == 60 for run in runs)  # both ran to the step limit
    assert "sb3_policy:sb3_policy" in format_explore_table(rows)
