"""The env in TorchRL, RLlib and Stable-Baselines3 as it comes, with zero lines of glue
(issue 38): each library's own wrapper or checker on ``mrslam_env.parallel_env(...)`` or
the registered single-robot env, and no ground truth in what reaches the learner (infos
included, which TorchRL turns into observation specs). A few steps each, no training run
(tests/test_train_examples.py trains the examples)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import gymnasium
import numpy as np
import pytest
import torch

import mrslam_env
from mrslam_env.config import EnvConfig
from mrslam_env.wrappers import SINGLE_ROBOT_ID

SMALL = "tb3_sandbox"
FAST = EnvConfig(lidar=replace(EnvConfig().lidar, n_beams=90), max_cycles=12)
INFOS = {"collision", "observed_area", "new_area"}
"""Every robot's infos by default: no ground truth (``true_pose``, ``privileged``)."""
GROUND_TRUTH = {"true_pose", "privileged"}


def plain(info: dict[str, Any]) -> bool:
    """The env's default infos (SB3 adds keys of its own: ``episode``, ...), no ground truth."""
    return set(info) >= INFOS and not GROUND_TRUTH & set(info)


def learn_and_collect_infos(model: Any, steps: int) -> list[dict[str, Any]]:
    """``model.learn(steps)``; every infos dict SB3 saw on the way."""
    seen: list[dict[str, Any]] = []

    def collect(local: dict[str, Any], _: dict[str, Any]) -> bool:
        seen.extend(local["infos"])
        return True

    model.learn(steps, callback=collect)
    return seen


@pytest.fixture(autouse=True)
def one_torch_thread() -> Iterator[None]:
    # Two cores shared with the other test worker: more threads only contend.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    torch.manual_seed(0)  # the libraries' random actions and network weights
    yield
    torch.set_num_threads(threads)


@pytest.mark.filterwarnings("ignore:PettingZoo in TorchRL is tested")
@pytest.mark.parametrize("flat", [False, True])
def test_torchrl_pettingzoo_wrapper_takes_the_env_as_it_comes(flat: bool) -> None:
    # Before: "Could not infer dtype of dict" (the nested ground-truth infos).
    from torchrl.envs import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    config = replace(FAST, flat_observation=flat)
    env = PettingZooWrapper(env=mrslam_env.parallel_env(scenario=SMALL, seed=0, config=config))
    assert env.group_map == {"robot": ["robot_0", "robot_1"]}
    check_env_specs(env, seed=0)
    names = {name for key in env.observation_spec.keys(True, True) for name in key}
    assert not GROUND_TRUTH & names
    assert set(env.observation_spec["robot", "info"].keys()) == INFOS
    rollout = env.rollout(10)
    assert rollout.batch_size == torch.Size([10])
    observation = rollout["next", "robot", "observation"]
    if flat:
        assert observation.shape == (10, 2, env.observation_spec["robot", "observation"].shape[-1])
    else:
        assert observation["scan"].shape == (10, 2, 90)
    assert rollout["next", "robot", "reward"].shape == (10, 2, 1)
    assert torch.isfinite(rollout["next", "robot", "info", "observed_area"]).all()
    # Truncation after max_cycles ends the rollout, as TorchRL's done flags say.
    longer = env.rollout(20)
    assert longer.batch_size == torch.Size([FAST.max_cycles])
    assert longer["next", "truncated"][-1].all()


def test_rllib_parallel_pettingzoo_env_steps_the_env_as_it_comes() -> None:
    # Before: ground truth in every step's infos (RLlib keeps them in its episodes) and
    # the wrapper's render() failed (it passes a render mode on).
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.rllib.utils.pre_checks.env import check_multiagent_environments

    config = replace(FAST, flat_observation=True)
    env = ParallelPettingZooEnv(
        mrslam_env.parallel_env(scenario=SMALL, seed=0, config=config, render_mode="rgb_array")
    )
    check_multiagent_environments(env)  # what RLlib's env runners run on a new env
    observations, infos = env.reset(seed=3)
    assert sorted(observations) == ["robot_0", "robot_1"]
    rng = np.random.default_rng(0)
    for step in range(1, FAST.max_cycles + 1):
        actions = {agent: rng.uniform(-1, 1, 2).astype(np.float32) for agent in observations}
        observations, rewards, terminateds, truncateds, infos = env.step(actions)
        for agent, observation in observations.items():
            assert env.get_observation_space(agent).contains(observation)
            assert set(infos[agent]) == INFOS
            assert isinstance(rewards[agent], float)
        assert not terminateds["__all__"] and truncateds["__all__"] == (step == FAST.max_cycles)
    frame = env.render()
    assert frame is not None and frame.ndim == 3 and frame.dtype == np.uint8


def test_sb3_check_env_and_ppo_on_the_single_robot_env() -> None:
    # Before: ground truth in the infos SB3 passes to callbacks and Monitor.
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_checker import check_env

    env = gymnasium.make(SINGLE_ROBOT_ID, scenario=SMALL, teammates="idle", config=FAST)
    check_env(env)
    _, info = env.reset(seed=0)
    assert set(info) == INFOS
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu")
    seen = learn_and_collect_infos(model, 64)
    assert model.num_timesteps == 64 and seen
    assert all(map(plain, seen))
    env.close()


def test_sb3_ppo_on_the_parallel_env_through_supersuit() -> None:
    # Before: the same ground truth in every robot's infos of the vector env.
    import supersuit as ss
    from stable_baselines3 import PPO

    env = mrslam_env.parallel_env(
        scenario=SMALL, seed=0, config=replace(FAST, flat_observation=True)
    )
    vec_env = ss.concat_vec_envs_v1(
        ss.pettingzoo_env_to_vec_env_v1(env), 1, base_class="stable_baselines3"
    )
    model = PPO("MlpPolicy", vec_env, n_steps=16, batch_size=32, n_epochs=1, device="cpu")
    seen = learn_and_collect_infos(model, 64)
    assert model.num_timesteps == 64 and len(seen) == 64  # 2 robots x 32 steps
    assert all(map(plain, seen))
    vec_env.close()
