"""Worlds and scans shared by the SLAM tests."""

from __future__ import annotations

import numpy as np

from mrslam_env.sim.lidar import cast_scan
from mrslam_env.sim.world import WorldSpec, box

NO_DISCS = np.zeros((0, 3))


def corridor_world() -> WorldSpec:
    """Two parallel walls 60 m long and 2 m apart: from the middle, no end is in range."""
    walls = [box(-30.0, -1.1, 30.0, -1.0), box(-30.0, 1.0, 30.0, 1.1)]
    return WorldSpec.from_walls("corridor", walls, [[0.0, 0.0, 0.0]])


def noisy_scan(world: WorldSpec, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A 360-beam, 8 m scan of ``world`` from ``pose`` with 1 cm Gaussian range noise."""
    ranges = cast_scan(pose[0], pose[1], pose[2], 360, 8.0, world.segments, NO_DISCS)
    noisy = np.clip(ranges + rng.normal(0.0, 0.01, ranges.shape), 0.0, 8.0)
    return np.where(ranges < 8.0, noisy, 8.0)
