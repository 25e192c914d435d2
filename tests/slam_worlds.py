"""Worlds and scans shared by the SLAM tests."""

from __future__ import annotations

import itertools

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


def room_walls(width: float, height: float, thickness: float = 0.1) -> list[np.ndarray]:
    """The four walls (quads) of a closed ``width`` x ``height`` m room with its inner
    corner at the origin."""
    t = thickness
    return [
        box(-t, -t, width + t, 0.0),
        box(-t, height, width + t, height + t),
        box(-t, -t, 0.0, height + t),
        box(width, -t, width + t, height + t),
    ]


def ring_world(length: float = 18.0, width: float = 10.0, corridor: float = 2.0) -> WorldSpec:
    """A ring corridor ``corridor`` m wide around a solid block: ``length`` x ``width`` m
    outside. Along the middle of its long sides no corridor end is in range."""
    walls = room_walls(length, width)
    walls.append(box(corridor, corridor, length - corridor, width - corridor))
    half = corridor / 2.0
    return WorldSpec.from_walls("ring", walls, [[half, half, 0.0]])


def ring_path(world_length: float, world_width: float, step: float, laps: float) -> np.ndarray:
    """Poses (x, y, heading) every ``step`` m along the middle of :func:`ring_world`'s
    corridor (2 m wide), anticlockwise from its south-west corner, ``laps`` times round."""
    half = 1.0
    corners = np.array(
        [
            [half, half],
            [world_length - half, half],
            [world_length - half, world_width - half],
            [half, world_width - half],
            [half, half],
        ]
    )
    points = []
    for a, b in itertools.pairwise(corners):
        n = int(np.hypot(*(b - a)) / step)
        points += [a + (b - a) * k / n for k in range(n)]
    lap = np.array(points)
    total = int(len(lap) * laps)
    positions = np.concatenate([lap] * int(np.ceil(laps)))[:total]
    heading = np.arctan2(np.gradient(positions[:, 1]), np.gradient(positions[:, 0]))
    return np.column_stack([positions, heading])
