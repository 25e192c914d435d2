"""Partial maps with a known relative pose, shared by the map-merging tests.

A map is made the way a robot with perfect poses would make it: exact lidar scans of a
world (:func:`mrslam_env.sim.lidar.cast_scan`) from poses along a path, integrated into an
:class:`~mrslam_env.slam.grid.OccupancyGrid` whose frame is an arbitrary pose in the world
(``world_from_map``). Two such maps of the same world in different frames are a merge
problem whose answer is ``map1_from_map2 = inverse(world_from_map1) ∘ world_from_map2``.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import ndimage

from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap, grid_footprint, resample_cells
from mrslam_env.registry import build_world
from mrslam_env.sim.lidar import cast_scan
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from mrslam_env.slam.config import GridConfig
from mrslam_env.slam.grid import OccupancyGrid

NO_DISCS = np.zeros((0, 3))


def scan_map(
    world: WorldSpec,
    poses_in_world: np.ndarray,
    world_from_map: np.ndarray,
    *,
    resolution: float = 0.05,
    n_beams: int = 360,
    max_range: float = 8.0,
) -> GridMap:
    """The trinary map a robot with perfect poses makes scanning from ``poses_in_world``
    (K, 3), expressed in the frame ``world_from_map`` (3,). The grid takes the full miss in
    every cell (``log_odds_miss_held=None``): the merge tests' cases were built on those
    maps, before the SLAM default kept cells that hold hits (issue 20)."""
    grid = OccupancyGrid(GridConfig(resolution=resolution, log_odds_miss_held=None))
    map_from_world = inverse(world_from_map)
    for pose in np.atleast_2d(poses_in_world):
        ranges = cast_scan(pose[0], pose[1], pose[2], n_beams, max_range, world.segments, NO_DISCS)
        grid.integrate_scan(compose(map_from_world, pose), ranges, max_range)
    return grid.to_gridmap()


def reachable_points(world: WorldSpec, clearance: float = 0.35, resolution: float = 0.1):
    """World (x, y) of cell centres with at least ``clearance`` m to any wall, in the free
    space connected to ``world.starts[0]``; shape (N, 2)."""
    gt = ground_truth_map(world, resolution)
    distance = ndimage.distance_transform_edt(gt.free) * resolution
    labels, _ = ndimage.label(distance >= clearance)
    start = gt.world_to_cell(world.starts[:1, :2])[0]
    label = labels[start[0], start[1]]
    assert label > 0, "the world's first start has too little clearance"
    cells = np.argwhere(labels == label)
    return gt.cell_to_world(cells)


def poses_near(
    world: WorldSpec, centre: tuple[float, float], radius: float, count: int, rng
) -> np.ndarray:
    """``count`` reachable poses (K, 3) within ``radius`` m of ``centre``, random headings."""
    points = reachable_points(world)
    near = points[np.hypot(*(points - np.asarray(centre)).T) <= radius]
    assert len(near) >= count, f"only {len(near)} reachable points near {centre}"
    chosen = near[rng.choice(len(near), size=count, replace=False)]
    return np.column_stack([chosen, rng.uniform(-np.pi, np.pi, count)])


def map_pair(
    scenario: str,
    centre1: tuple[float, float],
    centre2: tuple[float, float],
    map1_from_map2: np.ndarray,
    *,
    radius: float = 4.0,
    scans: int = 12,
    seed: int = 0,
    resolution: float = 0.05,
) -> tuple[GridMap, GridMap]:
    """Two partial maps of ``scenario``: map 1 scanned around ``centre1`` in a frame at
    world pose ``(centre1, 0.3 rad)``, map 2 around ``centre2`` in the frame placed so that
    the true relative pose is ``map1_from_map2``."""
    rng = np.random.default_rng(seed)
    world = build_world(scenario)
    world_from_map1 = np.array([centre1[0], centre1[1], 0.3])
    world_from_map2 = compose(world_from_map1, map1_from_map2)
    m1 = scan_map(
        world,
        poses_near(world, centre1, radius, scans, rng),
        world_from_map1,
        resolution=resolution,
    )
    m2 = scan_map(
        world,
        poses_near(world, centre2, radius, scans, rng),
        world_from_map2,
        resolution=resolution,
    )
    return m1, m2


def room_map(rows: int = 60, cols: int = 80, resolution: float = 0.05) -> GridMap:
    """A fully known walled rectangle with an inner wall stub, origin at (0, 0)."""
    cells = np.full((rows, cols), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[: rows // 2, cols // 3] = OCCUPIED
    return GridMap(cells=cells, resolution=resolution, origin=(0.0, 0.0))


def in_frame(grid: GridMap, frame: np.ndarray, resolution: float | None = None) -> GridMap:
    """``grid`` expressed in a frame whose pose in grid's frame is ``frame``."""
    res = grid.resolution if resolution is None else resolution
    corners = grid_footprint(grid, inverse(frame))
    lo = np.floor(corners.min(axis=0) / res) * res
    hi = corners.max(axis=0)
    shape = (math.ceil((hi[1] - lo[1]) / res), math.ceil((hi[0] - lo[0]) / res))
    origin = (float(lo[0]), float(lo[1]))
    return GridMap(
        cells=resample_cells(grid, inverse(frame), origin, shape, res),
        resolution=res,
        origin=origin,
    )


@functools.cache
def corridor_maps() -> tuple[list[GridMap], list[np.ndarray]]:
    """Three overlapping partial maps along the office corridor, each in its own frame
    (its start, turned 0.3 rad more each), and the true ``map0_from_map_i``."""
    world = build_world("office")
    rng = np.random.default_rng(3)
    centres = [(5.0, 4.0), (8.0, 4.0), (11.0, 4.0)]
    world_from_maps = [np.array([c[0], c[1], 0.3 * k]) for k, c in enumerate(centres)]
    own = [
        scan_map(world, poses_near(world, c, 4.0, 12, rng), w)
        for c, w in zip(centres, world_from_maps, strict=True)
    ]
    return own, [compose(inverse(world_from_maps[0]), w) for w in world_from_maps]
