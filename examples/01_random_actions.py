"""Random actions in the PettingZoo parallel env: the basic observe-act loop.

Shows how to create the env on a scenario, reset it with a seed, sample actions from the
action spaces until the episode ends, and read rewards and the ``collision`` info.

Run: python examples/01_random_actions.py [--scenario office] [--steps 300] [--seed 0]
"""

import argparse

from mrslam_env import parallel_env
from mrslam_env.config import EnvConfig

parser = argparse.ArgumentParser()
parser.add_argument("--scenario", default="office")  # `mrslam scenarios` lists them
parser.add_argument("--steps", type=int, default=300)
parser.add_argument("--seed", type=int, default=0)
args = parser.parse_args()

config = EnvConfig(max_cycles=args.steps)  # every robot is truncated after this many steps
env = parallel_env(scenario=args.scenario, config=config)
observations, infos = env.reset(seed=args.seed)
for i, agent in enumerate(env.agents):
    env.action_space(agent).seed(args.seed + i)  # seeded sampling: a reproducible run
print("agents:", env.agents, "observation keys:", sorted(observations["robot_0"]))

totals = dict.fromkeys(env.agents, 0.0)
collisions = dict.fromkeys(env.agents, 0)
while env.agents:  # empty once the episode is over
    actions = {agent: env.action_space(agent).sample() for agent in env.agents}  # (v, omega)
    observations, rewards, terminations, truncations, infos = env.step(actions)
    for agent in rewards:
        totals[agent] += rewards[agent]  # m² newly mapped, minus collision penalties
        collisions[agent] += infos[agent]["collision"]

print(f"{args.steps} steps = {args.steps * config.dt:.1f} s simulated")
for agent, total in totals.items():  # the area mapped at reset earns no reward
    area = infos[agent]["observed_area"]
    print(f"{agent}: reward {total:.2f}, map {area:.1f} m², collision steps {collisions[agent]}")
env.close()
