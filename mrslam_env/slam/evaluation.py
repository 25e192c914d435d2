"""How good a robot's SLAM is: trajectory error and map agreement against ground truth.

Both compare a result in the robot's *map* frame with the ground truth in the *world*
frame, through ``world_from_map``: for onboard SLAM that is the robot's true start pose
(the map frame is the start pose, DESIGN §2), known to the evaluation only.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from mrslam_env.geometry import compose
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap

FloatArray = NDArray[np.float64]

__all__ = ["absolute_trajectory_error", "map_agreement"]


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
