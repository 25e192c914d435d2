"""Scores against ground truth: SLAM trajectory error and map agreement, the error of a
merge transform, the true overlap and agreement of two maps, and how much of the world
maps cover. Evaluation only: nothing here is known to the robots.

The SLAM scores compare a result in the robot's *map* frame with the ground truth in the *world*
frame, through ``world_from_map``: for onboard SLAM that is the robot's true start pose
(the map frame is the start pose, docs/design.md §2), known to the evaluation only.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from mrslam_env.config import RobotConfig
from mrslam_env.geometry import compose, inverse, transform_points, wrap_scalar
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap, grid_footprint, resample_cells
from mrslam_env.sim.starts import reachable_floor
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from mrslam_env.slam.config import GridConfig

FloatArray = NDArray[np.float64]

PLANNER_MARGIN = 0.08
"""The frontier planner's safety margin beyond the robot radius, m
(``agents.planning.PlannerConfig.safety_margin``; mrslam_env does not import agents)."""

__all__ = [
    "PLANNER_MARGIN",
    "CoverageEvaluator",
    "absolute_trajectory_error",
    "cell_agreement",
    "map_agreement",
    "overlap_of_masks",
    "relative_transform_error",
    "true_overlap",
]


def absolute_trajectory_error(
    poses_in_map: ArrayLike, true_poses_in_world: ArrayLike, world_from_map: ArrayLike
) -> float:
    """Absolute trajectory error: RMSE (m) of the positions.

    Parameters
    ----------
    poses_in_map : array_like, shape (T, 3)
        Estimated poses in the map frame.
    true_poses_in_world : array_like, shape (T, 3)
        True poses at the same steps, world frame.
    world_from_map : array_like, shape (3,)
        The map frame in the world (not estimated: no alignment is fitted).

    Returns
    -------
    float
        ``sqrt(mean |p_est - p_true|^2)`` over the T positions, m.
    """
    estimated = np.asarray(poses_in_map, dtype=np.float64)
    truth = np.asarray(true_poses_in_world, dtype=np.float64)
    if estimated.shape != truth.shape or estimated.ndim != 2 or estimated.shape[1] != 3:
        raise ValueError(
            f"poses must both have shape (T, 3), got {estimated.shape} and {truth.shape}"
        )
    if len(estimated) == 0:
        raise ValueError("no poses to compare")
    in_world = compose(np.asarray(world_from_map, dtype=np.float64), estimated)
    squared = np.sum((in_world[:, :2] - truth[:, :2]) ** 2, axis=1)
    return float(np.sqrt(np.mean(squared)))


def map_agreement(estimate: GridMap, world_from_map: ArrayLike, ground_truth: GridMap) -> float:
    """Fraction of the known cells of an estimated map that agree with the ground truth.

    Each FREE or OCCUPIED cell of ``estimate`` is taken at its centre, moved into the world
    by ``world_from_map`` and looked up in ``ground_truth`` (a raster of the world, e.g.
    :func:`mrslam_env.sim.world.ground_truth_map` at the same resolution, in which a cell
    is OCCUPIED when it overlaps a wall at all):

    * a FREE cell agrees when the ground-truth cell is FREE (strict; centres beyond the
      raster count as FREE ground truth: the raster covers the world);
    * an OCCUPIED cell agrees when the ground-truth cell *or one of its 8 neighbours* is
      OCCUPIED. One cell of slack, because a wall surface seen by the lidar is a line: in
      a map rotated against the world lattice (the map frame is the start pose) its cells
      straddle the ground-truth cells, and a wall face on a cell boundary is hit from both
      sides of it.

    Parameters
    ----------
    estimate : GridMap
        The map, in its own frame.
    world_from_map : array_like, shape (3,)
        Where that frame is in the world.
    ground_truth : GridMap
        The world raster.

    Returns
    -------
    float
        In [0, 1]; 1.0 for a map with no known cell.
    """
    known = np.argwhere(estimate.cells != np.int8(-1))
    if len(known) == 0:
        return 1.0
    centres = estimate.cell_to_world(known)
    poses = np.column_stack([centres, np.zeros(len(centres))])
    in_world = compose(np.asarray(world_from_map, dtype=np.float64), poses)[:, :2]
    cells = ground_truth.world_to_cell(in_world)
    inside = ground_truth.contains(cells)
    rows, cols = ground_truth.shape
    cells = np.clip(cells, 0, [rows - 1, cols - 1])
    truth_free = np.where(inside, ground_truth.free[cells[:, 0], cells[:, 1]], True)
    near_occupied = ndimage.binary_dilation(ground_truth.occupied, np.ones((3, 3), dtype=bool))
    truth_near_occupied = inside & near_occupied[cells[:, 0], cells[:, 1]]
    values = estimate.cells[known[:, 0], known[:, 1]]
    agree = np.where(values == FREE, truth_free, truth_near_occupied)
    agree &= (values == FREE) | (values == OCCUPIED)
    return float(np.mean(agree))


def relative_transform_error(
    estimate: ArrayLike, truth: ArrayLike, pivot: ArrayLike | None = None
) -> tuple[float, float]:
    """Translation error (m) and absolute rotation error (rad, wrapped to [0, pi]) of a
    transform ``estimate`` against ``truth`` (both ``map1_from_map2``).

    The translation error is the distance between the two images of ``pivot``, a point of
    map 2 (default the origin of its frame: then it is the distance between the two
    translations), i.e. how far ``inverse(truth) ∘ estimate`` moves the pivot; the rotation
    error is the wrapped difference of the two angles. Measured at a point of the map (its
    known centroid, say), the translation error does not grow with the map's distance from
    its frame's origin.
    """
    e = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if pivot is None:
        dx, dy = e[0] - t[0], e[1] - t[1]
    else:
        point = np.asarray(pivot, dtype=np.float64).reshape(1, 2)
        dx, dy = transform_points(e, point)[0] - transform_points(t, point)[0]
    return math.hypot(dx, dy), abs(wrap_scalar(float(e[2] - t[2])))


def true_overlap(m1: GridMap, m2: GridMap, map1_from_map2: FloatArray) -> float:
    """Overlap of two maps under the true transform: the area known (FREE or OCCUPIED) in
    both, over the smaller of the two known areas, in [0, 1].

    Both maps are resampled onto one raster in map 1's frame at the finer resolution.
    Returns 0 when either map knows nothing.
    """
    transform = np.asarray(map1_from_map2, dtype=np.float64)
    resolution = min(m1.resolution, m2.resolution)
    corners = np.vstack([grid_footprint(m1, np.zeros(3)), grid_footprint(m2, transform)])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    shape = (
        math.ceil((hi[1] - lo[1]) / resolution),
        math.ceil((hi[0] - lo[0]) / resolution),
    )
    origin = (float(lo[0]), float(lo[1]))
    known1 = resample_cells(m1, np.zeros(3), origin, shape, resolution) != UNKNOWN
    known2 = resample_cells(m2, transform, origin, shape, resolution) != UNKNOWN
    return overlap_of_masks(known1, known2)


def overlap_of_masks(known1: NDArray[np.bool_], known2: NDArray[np.bool_]) -> float:
    smaller = min(int(known1.sum()), int(known2.sum()))
    return 0.0 if smaller == 0 else int(np.count_nonzero(known1 & known2)) / smaller


def cell_agreement(m1: GridMap, m2: GridMap, map1_from_map2: FloatArray) -> float:
    """Share of the cells known in both maps (m2 resampled onto m1's lattice) that have the
    same state, in [0, 1]; NaN when no cell is known in both.

    A diagnostic for wrong answers: a wrong transform that agrees as well as the truth
    means the two maps alone cannot tell them apart (symmetric or repetitive places).
    """
    transform = np.asarray(map1_from_map2, dtype=np.float64)
    warped = resample_cells(m2, transform, m1.origin, m1.shape, m1.resolution)
    both = (warped != UNKNOWN) & (m1.cells != UNKNOWN)
    return float(np.mean(warped[both] == m1.cells[both])) if both.any() else math.nan


class CoverageEvaluator:
    """How much of the free area maps cover, judged against the ground truth.

    The evaluation points are the free cells of a ground-truth raster of the world that a
    robot can get to from ``starts`` through passages its planner plans through, as world
    points: those with a cell of :func:`mrslam_env.sim.starts.reachable_floor` under them,
    computed at the planner's own figures (clearance ``radius + margin``, on a raster of
    ``reach_resolution``, the SLAM map's cell). Floor behind narrower gaps does not count,
    even where the lidar sees it through the gap. A map covers a point when the cell under
    it is known (FREE or OCCUPIED) once the map is put in the world by its true frame.

    Parameters
    ----------
    world : WorldSpec
    starts : ndarray, shape (n, 3)
        The robots' true start poses, world frame.
    resolution : float
        Cell size of the raster of evaluation points, m.
    radius : float
        The robots' radius, m (the default robot's by default).
    margin : float
        Clearance beyond the radius a passage needs, m: the frontier planner's
        ``PlannerConfig.safety_margin`` (agents/planning.py; a test keeps them equal).
    reach_resolution : float
        Cell size of the raster the reachable floor is found on, m: the SLAM map's
        (``GridConfig.resolution``), which the planner plans on.
    """

    def __init__(
        self,
        world: WorldSpec,
        starts: FloatArray,
        resolution: float = 0.1,
        *,
        radius: float = RobotConfig().radius,
        margin: float = PLANNER_MARGIN,
        reach_resolution: float = GridConfig().resolution,
    ) -> None:
        raster = ground_truth_map(world, resolution, margin=1.0)
        fine = ground_truth_map(world, reach_resolution, margin=1.0)
        poses = np.asarray(starts, dtype=np.float64).reshape(-1, 3)
        seeds = fine.world_to_cell(poses[:, :2])
        floor = reachable_floor(fine.free, fine.occupied, reach_resolution, radius, seeds, margin)
        points = raster.cell_to_world(np.argwhere(raster.free))
        # A point counts when the reachable floor holds any fine cell of its cell.
        keep = np.zeros(len(points), dtype=bool)
        # The centres of the fine cells in a point's cell (k x k of them).
        k = max(1, round(resolution / reach_resolution))
        offsets = ((np.arange(k) + 0.5) / k - 0.5) * resolution
        for dx in offsets:
            for dy in offsets:
                cells = fine.world_to_cell(points + np.array([dx, dy]))
                inside = fine.contains(cells)
                keep[inside] |= floor[cells[inside, 0], cells[inside, 1]]
        self.points = points[keep]
        self.resolution = resolution

    @property
    def area(self) -> float:
        """The reachable free area the coverage is a fraction of, m²."""
        return len(self.points) * self.resolution**2

    def known(self, grid: GridMap, world_from_map: ArrayLike) -> NDArray[np.bool_]:
        """Which evaluation points ``grid`` knows, (P,) bool."""
        cells = grid.world_to_cell(transform_points(inverse(world_from_map), self.points))
        inside = grid.contains(cells)
        known = np.zeros(len(self.points), dtype=bool)
        known[inside] = grid.cells[cells[inside, 0], cells[inside, 1]] != UNKNOWN
        return known

    def coverage(self, grids: list[GridMap], world_from_maps: list[FloatArray]) -> float:
        """Fraction of the free area known in any of the maps (each given with its true
        frame in the world), in [0, 1]; 0 when the world has no reachable free cell."""
        if len(self.points) == 0:
            return 0.0
        known = np.zeros(len(self.points), dtype=bool)
        for grid, frame in zip(grids, world_from_maps, strict=True):
            known |= self.known(grid, frame)
        return float(known.mean())
