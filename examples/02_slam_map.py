"""Onboard SLAM: let robot_0 wander, then save its map as a ROS map (YAML + PGM).

Shows ``env.unwrapped.robot_map(agent)`` (the robot's own map, in its start frame),
``mrslam_env.mapio.save_map`` and how to judge the SLAM pose against the ground truth
``infos[agent]["true_pose"]``, there with ``privileged=True`` only (evaluation only, never
for a policy).

Run: python examples/02_slam_map.py [--steps 400] [--out runs/robot_0.yaml] [--overwrite]
"""

import argparse

import numpy as np

from agents.wander import WanderPolicy
from mrslam_env import parallel_env
from mrslam_env.geometry import compose
from mrslam_env.mapio import map_yaml_path, save_map

parser = argparse.ArgumentParser()
parser.add_argument("--steps", type=int, default=400)
parser.add_argument("--out", type=map_yaml_path, default="runs/robot_0.yaml")
parser.add_argument("--overwrite", action="store_true", help="replace an existing output")
args = parser.parse_args()
if not args.overwrite and (args.out.exists() or args.out.with_suffix(".pgm").exists()):
    parser.error(f"{args.out} exists; --overwrite replaces it")  # never a silent overwrite

env = parallel_env(scenario="office", seed=0, privileged=True)  # ground truth in the infos
observations, infos = env.reset()
world_from_map = infos["robot_0"]["true_pose"]  # the map frame is the start pose
wander = WanderPolicy(n_beams=len(observations["robot_0"]["scan"]), rng=np.random.default_rng(0))
for _ in range(args.steps):  # robot_0 wanders (it reads only its own scan); robot_1 waits
    actions = {"robot_0": wander.act(observations["robot_0"]["scan"]), "robot_1": [0.0, 0.0]}
    observations, rewards, terminations, truncations, infos = env.step(actions)

grid = env.unwrapped.robot_map("robot_0")  # a GridMap: cells FREE/OCCUPIED/UNKNOWN
save_map(args.out, grid)  # writes the YAML and, next to it, the PGM image
known_area = np.count_nonzero(~grid.unknown) * grid.resolution**2
print(f"saved {args.out}: {grid.shape[1]} x {grid.shape[0]} cells of {grid.resolution} m")
print(f"known area {known_area:.1f} m² ({np.count_nonzero(grid.occupied)} occupied cells)")
for key in ("pose", "odom"):  # the SLAM pose and raw odometry, both in the start frame
    estimate = compose(world_from_map, observations["robot_0"][key])
    error = np.hypot(*(estimate[:2] - infos["robot_0"]["true_pose"][:2]))
    print(f"{key} position error after {args.steps} steps: {error:.3f} m")
