"""Parameter-shared PPO with RLlib: every robot maps to one policy, ``"shared"``.

RLlib's own PettingZoo wrapper runs the parallel env with the flat normalised observation
(``EnvConfig(flat_observation=True)``; layout in mrslam_env/wrappers.py). The checkpoint is
written to ``--out``; the trained network alone is ``OUT/learner_group/learner/rl_module/
shared`` (``RLModule.from_checkpoint`` reads it).

Needs the ``rl`` extra: pip install -e '.[rl]'
Run: python examples/train_rllib_ppo.py [--steps 20000] [--scenario office] [--seed 0]
    [--env-runners 0] [--out runs/rllib_mrslam]
"""

import argparse
from pathlib import Path

import ray
import torch
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME
from ray.tune.registry import register_env

from mrslam_env import parallel_env
from mrslam_env.config import EnvConfig

torch.set_num_threads(1)  # 2 cores: torch's default threads contend and train 2.5-4x slower

parser = argparse.ArgumentParser()
parser.add_argument("--steps", type=int, default=20_000, help="env steps to train for")
parser.add_argument("--scenario", default="office")  # `mrslam scenarios` lists them
parser.add_argument("--episode-steps", type=int, default=500)
parser.add_argument("--batch", type=int, default=2000, help="env steps per PPO update")
parser.add_argument("--env-runners", type=int, default=0, help="0: sample in this process")
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--out", default="runs/rllib_mrslam")
args = parser.parse_args()


def make_env(env_config: dict) -> ParallelPettingZooEnv:
    config = EnvConfig(flat_observation=True, max_cycles=env_config["episode_steps"])
    return ParallelPettingZooEnv(parallel_env(scenario=env_config["scenario"], config=config))


register_env("mrslam", make_env)
# A Ray instance of its own on this machine (never a cluster found running).
ray.init(address="local", num_cpus=args.env_runners + 1, include_dashboard=False)
config = (
    PPOConfig()
    .environment("mrslam", env_config=vars(args))
    .env_runners(num_env_runners=args.env_runners)
    .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent_id, *_, **__: "shared")
    .training(train_batch_size_per_learner=args.batch, minibatch_size=min(args.batch, 128))
    .debugging(seed=args.seed)  # seeds the network and every env runner's env resets
)
algo = config.build_algo()
sampled = 0
while sampled < args.steps:
    result = algo.train()
    sampled = result[NUM_ENV_STEPS_SAMPLED_LIFETIME]
    print(f"{sampled} env steps, return {result['env_runners'].get('episode_return_mean')}")
checkpoint = algo.save_to_path(str(Path(args.out).absolute()))
print(f"trained {sampled} env steps; saved {checkpoint}")
algo.stop()
ray.shutdown()
