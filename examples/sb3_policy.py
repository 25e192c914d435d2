"""A trained Stable-Baselines3 model as an exploration policy (the protocol of
agents/policy.py), so that the team runs it like the frontier explorer.

The model is the zip that examples/train_sb3_ppo.py saves; its path comes from the
environment variable ``MRSLAM_SB3_MODEL`` (default ``runs/ppo_mrslam.zip``). The robot's
``Dict`` observation is flattened by :class:`mrslam_env.wrappers.ObservationFlattener`,
exactly as the env did in training (``EnvConfig(flat_observation=True)``), and the model's
deterministic action is returned.

Needs the ``rl`` extra: pip install -e '.[rl]'
Run: MRSLAM_SB3_MODEL=runs/ppo_mrslam.zip mrslam run --policy examples/sb3_policy.py:sb3_policy
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.policy import PolicyContext
from mrslam_env.config import EnvConfig
from mrslam_env.wrappers import ObservationFlattener

MODEL_VARIABLE = "MRSLAM_SB3_MODEL"
DEFAULT_MODEL = "runs/ppo_mrslam.zip"


class SB3Policy:
    """``act(observation, context)``: the model's action on the flattened observation.

    Parameters
    ----------
    model : stable_baselines3 BaseAlgorithm
        Trained on the flat observation of an env with this ``env`` configuration.
    env : EnvConfig
        The env the robot is in (lidar, peer range, SLAM, crop size, length scale).
    """

    def __init__(self, model: Any, env: EnvConfig) -> None:
        self.model = model
        self.env = env
        self.flattener: ObservationFlattener | None = None

    def reset(self) -> None:
        """Nothing to forget: the policy has no memory (an MLP)."""

    def act(self, observation: dict[str, Any], context: PolicyContext) -> NDArray[np.float32]:
        if self.flattener is None:  # the team size shows in the peer rows
            robots = len(np.asarray(observation["peer"]).reshape(-1, 4)) + 1
            self.flattener = ObservationFlattener(self.env, robots)
            expected = self.model.observation_space.shape
            if expected != self.flattener.space.shape:
                raise ValueError(
                    f"the model takes observations of shape {expected}, this env's flat "
                    f"observation has shape {self.flattener.space.shape} ({robots} robots)"
                )
        action, _ = self.model.predict(self.flattener(observation), deterministic=True)
        return np.clip(np.asarray(action, dtype=np.float32).reshape(2), -1.0, 1.0)


def sb3_policy(env: EnvConfig, rng: np.random.Generator) -> SB3Policy:
    """The policy factory (``agents.policy.PolicyFactory``): loads the PPO model named by
    ``MRSLAM_SB3_MODEL``. ``rng`` is unused: the action is the deterministic one."""
    from stable_baselines3 import PPO

    path = os.environ.get(MODEL_VARIABLE, DEFAULT_MODEL)
    return SB3Policy(PPO.load(path, device="cpu"), env)
