"""Parameter-shared PPO with Stable-Baselines3: one policy drives every robot, trained on
all robots' experience.

The env emits the flat normalised observation (``EnvConfig(flat_observation=True)``, the
layout is in mrslam_env/wrappers.py) and SuperSuit makes each robot a sub-environment of
one SB3 vector env. The trained model is saved as a zip (``PPO.load`` reads it);
examples/sb3_policy.py turns it into an exploration policy for ``mrslam run --policy``.

Needs the ``rl`` extra: pip install -e '.[rl]'
Run: python examples/train_sb3_ppo.py [--steps 50000] [--scenario office] [--seed 0]
    [--out runs/ppo_mrslam.zip]
"""

import argparse

import supersuit as ss
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.utils import set_random_seed

from mrslam_env import parallel_env
from mrslam_env.config import EnvConfig

torch.set_num_threads(1)  # 2 cores: torch's default threads contend and train 2.5-4x slower

parser = argparse.ArgumentParser()
parser.add_argument("--steps", type=int, default=50_000, help="robot-steps to train for")
parser.add_argument("--scenario", default="office")  # `mrslam scenarios` lists them
parser.add_argument("--episode-steps", type=int, default=500)
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--out", default="runs/ppo_mrslam.zip")
args = parser.parse_args()

set_random_seed(args.seed)  # python, numpy and torch: the network and the action noise
config = EnvConfig(flat_observation=True, max_cycles=args.episode_steps)
env = parallel_env(scenario=args.scenario, seed=args.seed, config=config)  # seeds the env
vec_env = ss.pettingzoo_env_to_vec_env_v1(env)  # robot_i -> sub-environment i
vec_env = ss.concat_vec_envs_v1(vec_env, 1, base_class="stable_baselines3")
# Rollouts of n_steps per robot; SuperSuit's vector env cannot take PPO's seed= (seeded above).
n_steps = max(32, min(512, args.steps // vec_env.num_envs))
model = PPO("MlpPolicy", vec_env, n_steps=n_steps, batch_size=64, verbose=0, device="cpu")
model.learn(total_timesteps=args.steps)
model.save(args.out)
print(f"trained {model.num_timesteps} robot-steps on {vec_env.num_envs} robots; saved {args.out}")
vec_env.close()
