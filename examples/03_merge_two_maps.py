"""Merge two ROS map files: find map1_from_map2, fuse the maps, write the merged map.

Run: python examples/03_merge_two_maps.py [MAP1.yaml MAP2.yaml] [-o OUT.yaml] [--overwrite]
No maps: a demo pair (two overlapping crops of the office, the second turned and shifted by
a known transform) in a temporary folder. OUT (runs/merged.yaml) is new, or --overwrite."""

import argparse
import math
import tempfile
from pathlib import Path

from mrslam_env.geometry import inverse, pose
from mrslam_env.gridmap import GridMap
from mrslam_env.mapio import load_map, map_yaml_path, save_map
from mrslam_env.merge.fuse import warp_map
from mrslam_env.merge.pipeline import merge_maps
from mrslam_env.registry import build_world
from mrslam_env.sim.world import ground_truth_map

parser = argparse.ArgumentParser()
parser.add_argument("maps", nargs="*", help="MAP1.yaml MAP2.yaml (none: a demo pair)")
parser.add_argument("-o", "--out", type=map_yaml_path, default="runs/merged.yaml")
parser.add_argument("--overwrite", action="store_true", help="replace an existing output")
args = parser.parse_args()
if not args.overwrite and (args.out.exists() or args.out.with_suffix(".pgm").exists()):
    parser.error(f"{args.out} exists; --overwrite replaces it")  # never a silent overwrite

if not args.maps:  # demo: map 1 = the office's x < 16 m, map 2 = its x > 10 m, turned
    truth = ground_truth_map(build_world("office"), resolution=0.05)
    m1 = GridMap(cells=truth.cells[:, :320], resolution=0.05, origin=truth.origin)
    x0, y0 = truth.origin
    right = GridMap(cells=truth.cells[:, 200:], resolution=0.05, origin=(x0 + 10.0, y0))
    m2 = warp_map(right, inverse(pose(12.0, 3.0, math.radians(30.0))))  # map1_from_map2: that pose
    folder = Path(tempfile.mkdtemp())
    args.maps = [save_map(folder / "m1.yaml", m1), save_map(folder / "m2.yaml", m2)]
    print(f"demo pair in {folder}; true transform: x 12.000 m, y 3.000 m, theta 30.00°")

result = merge_maps(load_map(args.maps[0]), load_map(args.maps[1]), rng=0)  # seeded
if result.transform is None:
    print(result.reason)  # "no confident merge: ...": never a silent guess
else:
    x, y, theta = result.transform
    print(f"map1_from_map2: x {x:.3f} m, y {y:.3f} m, theta {math.degrees(theta):.2f}°")
    print(f"{result.reason}; wrote {save_map(args.out, result.fused)}")
