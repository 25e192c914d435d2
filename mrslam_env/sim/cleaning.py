"""Cleaning a SLAM map before it becomes a simulator world.

Real SLAM maps carry artefacts that a map of a building should not: free *ray streaks* where
beams passed through glass or gaps and marked cells beyond the walls, free pockets no robot
could ever reach, and *speckle*, single occupied cells of range noise in open floor.
:func:`clean_for_simulation` removes them by one rule about the robot:

* the floor is the free space a robot of the given radius can reach from the largest
  region where it fits (centres with a clearance of at least the radius, grown back by
  the radius to the cells its footprint sweeps); every other free cell becomes UNKNOWN,
  which :func:`~mrslam_env.sim.mapworld.world_from_map` treats as wall;
* an occupied connected group (8-connected) no larger than ``speckle_area`` whose every
  neighbour is free becomes free.

Speckle goes first, so that a noise cell in a corridor does not cut the floor in two.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.validation import require

__all__ = ["clean_for_simulation"]

_EIGHT = np.ones((3, 3), dtype=bool)


def _remove_speckle(cells: np.ndarray, max_cells: int) -> np.ndarray:
    """OCCUPIED groups of at most ``max_cells`` cells surrounded by FREE become FREE."""
    occupied = cells == OCCUPIED
    labels, count = ndimage.label(occupied, structure=_EIGHT)
    if count == 0 or max_cells < 1:
        return cells
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    small = np.flatnonzero(sizes[1:] <= max_cells) + 1
    if small.size == 0:
        return cells
    candidate = np.isin(labels, small)
    # A group is speckle only if every cell around it is FREE (not unknown, not a wall).
    ring = ndimage.binary_dilation(candidate, structure=_EIGHT) & ~candidate
    not_free_ring = ring & (cells != FREE)
    touched = np.unique(labels[ndimage.binary_dilation(not_free_ring, structure=_EIGHT)])
    speckle = candidate & ~np.isin(labels, touched)
    out = cells.copy()
    out[speckle] = FREE
    return out


def _reachable_floor(cells: np.ndarray, resolution: float, radius: float) -> np.ndarray:
    """FREE cells a robot of ``radius`` can sweep from the largest region where it fits."""
    free = cells == FREE
    clearance = ndimage.distance_transform_edt(free) * resolution
    fits = free & (clearance >= radius)
    labels, count = ndimage.label(fits)
    if count == 0:
        return np.zeros_like(free)
    largest = int(np.argmax(np.bincount(labels.ravel())[1:])) + 1
    centres = labels == largest
    # Cells within the radius of a reachable centre: the footprint's sweep.
    swept = ndimage.distance_transform_edt(~centres) * resolution <= radius + 0.5 * resolution
    return swept & free


def clean_for_simulation(
    grid: GridMap, *, robot_radius: float = 0.2, speckle_area: float = 0.0025
) -> GridMap:
    """The map with ray streaks, unreachable free space and speckle removed (module
    docstring).

    Parameters
    ----------
    grid : GridMap
        A SLAM map with FREE, OCCUPIED and UNKNOWN cells.
    robot_radius : float
        Footprint radius of the robots that will drive in it, m.
    speckle_area : float
        Largest isolated occupied group removed as noise, m² (default one 5 cm cell).

    Returns
    -------
    GridMap
        Same shape, resolution and origin; FREE only where a robot can reach.

    Raises
    ------
    ValueError
        A non-positive radius, a negative speckle area, or a map with no floor a robot of
        that radius fits on.
    """
    require("clean_for_simulation", "robot_radius", robot_radius, robot_radius > 0, "> 0 m")
    require("clean_for_simulation", "speckle_area", speckle_area, speckle_area >= 0, ">= 0 m²")
    max_cells = int(np.floor(speckle_area / grid.resolution**2 + 1e-9))
    cells = _remove_speckle(grid.cells, max_cells)
    floor = _reachable_floor(cells, grid.resolution, robot_radius)
    if not floor.any():
        raise ValueError(f"the map has no floor where a robot of radius {robot_radius} m fits")
    cells = np.where((cells == FREE) & ~floor, UNKNOWN, cells).astype(np.int8)
    return GridMap(cells=cells, resolution=grid.resolution, origin=grid.origin)
