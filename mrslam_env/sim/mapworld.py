"""Simulator worlds built from occupancy grids (ROS map files, docs/design.md §3).

:func:`world_from_map` turns a :class:`~mrslam_env.gridmap.GridMap` into a
:class:`~mrslam_env.sim.world.WorldSpec`:

* **Wall cells** are the OCCUPIED cells (and the UNKNOWN ones unless
  ``unknown_as_wall=False``), plus a one-cell frame around the grid so that robots cannot
  leave the map.
* **Walls for physics** cover the wall cells with few axis-aligned rectangles: each row is
  run-length encoded and identical runs in consecutive rows are merged (a greedy
  rectangle cover, :func:`cover_rectangles`), not one box per pixel.
* **Lidar segments** are the traced outline of the same union of cells: the cell edges
  between wall and non-wall cells merged into maximal straight runs
  (:func:`outline_segments`). Interior edges between rectangles are not in it.
* **Starts** are chosen automatically by the start clearance rule
  (:mod:`mrslam_env.sim.starts`) in the largest region it can plan through, far apart,
  unless given (then they are checked).

Everything is vectorised numpy: a 1000 x 1000 map builds in a fraction of a second (see
:func:`_bench_world_from_map`).
"""

from __future__ import annotations

import math
import time

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import wrap_angle
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.sim.starts import START_MARGIN, start_cells
from mrslam_env.sim.world import WorldSpec

__all__ = [
    "MAX_WORLD_CELLS",
    "check_world_extent",
    "cover_rectangles",
    "outline_segments",
    "wall_mask",
    "world_from_map",
]

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

_START_SAMPLE = 512  # candidate cells compared pairwise when choosing far-apart starts

MAX_WORLD_CELLS = 25_000_000
"""The largest world a run simulates, as its extent in cells at the grid resolution the
run maps it with (0.05 m: the SLAM maps, the ground truth and the coverage reach are
grids over the world's extent). 25 M cells is 250 x 250 m at 0.05 m: 13 times a large
80 x 60 m floor (1.92 M cells; a 100-step run of it peaked at 0.44 GB, one of
160 x 120 m, 7.7 M cells, at 0.8 GB: about 60 bytes a cell)."""


def check_world_extent(bounds: tuple[float, float, float, float], resolution: float) -> None:
    """Refuse, before anything is allocated, a world whose extent ``bounds`` (xmin, ymin,
    xmax, ymax, m) at ``resolution`` (m/cell) is over :data:`MAX_WORLD_CELLS` cells.

    Raises
    ------
    ValueError
        One line with the world's size, its cells and the limit.
    """
    width, height = bounds[2] - bounds[0], bounds[3] - bounds[1]
    cells = math.ceil(width / resolution - 1e-9) * math.ceil(height / resolution - 1e-9)
    if cells > MAX_WORLD_CELLS:
        raise ValueError(
            f"world of {width:,.0f} x {height:,.0f} m is {cells:,} cells at {resolution:g} m; "
            f"the limit is {MAX_WORLD_CELLS:,} cells (e.g. 250 x 250 m): use a map with a "
            "smaller extent (check its resolution)"
        )


def wall_mask(grid: GridMap, *, unknown_as_wall: bool = True) -> BoolArray:
    """Cells that are walls: OCCUPIED, and UNKNOWN when ``unknown_as_wall``.

    Parameters
    ----------
    grid : GridMap
    unknown_as_wall : bool

    Returns
    -------
    ndarray of bool, shape (rows, cols)
        Same indexing as ``grid.cells`` (row 0 = lowest y).
    """
    mask = grid.cells == OCCUPIED
    if unknown_as_wall:
        mask |= grid.cells == UNKNOWN
    return mask


def _runs_along_rows(code: NDArray[np.int8]) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    """Maximal runs of equal non-zero values along each row of ``code``.

    Returns
    -------
    row, start, stop, value : ndarray of int64, shape (N,)
        Run ``k`` covers ``code[row[k], start[k]:stop[k]]``, all equal to ``value[k]``;
        runs are in row-major order.
    """
    padded = np.zeros((code.shape[0], code.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = code
    change = padded[:, 1:] != padded[:, :-1]  # (rows, cols + 1), boundary k before column k
    row, start = np.nonzero(change & (padded[:, 1:] != 0))
    _, stop = np.nonzero(change & (padded[:, :-1] != 0))
    value = padded[row, start + 1].astype(np.int64)
    return row.astype(np.int64), start.astype(np.int64), stop.astype(np.int64), value


def cover_rectangles(mask: ArrayLike) -> IntArray:
    """Cover the True cells of a mask with axis-aligned rectangles (greedy, exact).

    Each row is run-length encoded; runs with the same column span in consecutive rows
    are merged into one rectangle. The rectangles are disjoint and their union is exactly
    the True cells. Not a minimum cover, but large blocks and straight walls become a
    handful of rectangles instead of one per cell.

    Parameters
    ----------
    mask : array_like of bool, shape (rows, cols)

    Returns
    -------
    ndarray of int64, shape (K, 4)
        ``(row0, col0, row1, col1)``, half-open: the rectangle covers
        ``mask[row0:row1, col0:col1]``. Sorted by ``col0``, then ``col1``, then ``row0``.
    """
    cells = np.asarray(mask, dtype=bool)
    if cells.ndim != 2:
        raise ValueError(f"mask must be 2-D, got shape {cells.shape}")
    row, start, stop, _ = _runs_along_rows(cells.view(np.int8))
    if len(row) == 0:
        return np.zeros((0, 4), dtype=np.int64)
    order = np.lexsort((row, stop, start))
    row, start, stop = row[order], start[order], stop[order]
    new = np.ones(len(row), dtype=bool)
    new[1:] = (start[1:] != start[:-1]) | (stop[1:] != stop[:-1]) | (row[1:] != row[:-1] + 1)
    first = np.flatnonzero(new)
    last = np.append(first[1:], len(row)) - 1
    return np.stack([row[first], start[first], row[last] + 1, stop[first]], axis=1)


def outline_segments(mask: ArrayLike) -> IntArray:
    """The boundary of the union of True cells, as maximal straight lattice segments.

    Cells outside the mask count as False, so the outline is closed. Each segment runs
    along cell edges that separate a True cell from a False one, and is oriented with the
    True side on its left (counter-clockwise around wall regions, clockwise around holes).
    Collinear edges are merged while the True side stays the same.

    Parameters
    ----------
    mask : array_like of bool, shape (rows, cols)

    Returns
    -------
    ndarray of int64, shape (M, 4)
        ``(x0, y0, x1, y1)`` in lattice units: corner ``(x, y)`` is the corner between
        columns ``x - 1, x`` and rows ``y - 1, y`` (cell ``[iy, ix]`` spans
        ``[ix, ix + 1] x [iy, iy + 1]``). Horizontal segments first, then vertical.
    """
    cells = np.asarray(mask, dtype=bool)
    if cells.ndim != 2:
        raise ValueError(f"mask must be 2-D, got shape {cells.shape}")
    padded = np.pad(cells, 1).view(np.int8)
    # Horizontal lattice lines y = 0..rows: +1 where the True cell is above (its bottom
    # edge, traversed +x), -1 where it is below (its top edge, traversed -x).
    horizontal = (padded[1:, 1:-1] - padded[:-1, 1:-1]).astype(np.int8)
    line, start, stop, value = _runs_along_rows(horizontal)
    forward = value > 0
    h_segments = np.stack(
        [
            np.where(forward, start, stop),
            line,
            np.where(forward, stop, start),
            line,
        ],
        axis=1,
    )
    # Vertical lattice lines x = 0..cols: +1 where the True cell is to the right (its left
    # edge, traversed -y), -1 where it is to the left (its right edge, traversed +y).
    vertical = (padded[1:-1, 1:] - padded[1:-1, :-1]).astype(np.int8)
    line, start, stop, value = _runs_along_rows(np.ascontiguousarray(vertical.T))
    upward = value < 0
    v_segments = np.stack(
        [
            line,
            np.where(upward, start, stop),
            line,
            np.where(upward, stop, start),
        ],
        axis=1,
    )
    return np.concatenate([h_segments, v_segments]).astype(np.int64)


def _rectangles_to_quads(rectangles: IntArray, origin: FloatArray, resolution: float) -> FloatArray:
    """Rectangles ``(row0, col0, row1, col1)`` (K, 4) to ccw quads (K, 4, 2) in metres."""
    x0 = origin[0] + rectangles[:, 1] * resolution
    x1 = origin[0] + rectangles[:, 3] * resolution
    y0 = origin[1] + rectangles[:, 0] * resolution
    y1 = origin[1] + rectangles[:, 2] * resolution
    return np.stack(
        [
            np.stack([x0, y0], 1),
            np.stack([x1, y0], 1),
            np.stack([x1, y1], 1),
            np.stack([x0, y1], 1),
        ],
        axis=1,
    )


def _choose_starts(
    walls: BoolArray,
    free: BoolArray,
    origin: FloatArray,
    resolution: float,
    n_starts: int,
    robot_radius: float,
    rng: np.random.Generator,
) -> FloatArray:
    """Pick ``n_starts`` far-apart poses in free cells with clearance.

    Candidates are the FREE cells among the :func:`~mrslam_env.sim.starts.start_cells`
    of the wall mask (the start clearance rule, in the largest region a robot of
    ``robot_radius`` can plan through, so every start can reach every other). Of a random sample of
    them, the two farthest apart are chosen, then greedily the cell farthest from those
    chosen. Headings are evenly spread from a random first one.

    Returns
    -------
    ndarray, shape (n_starts, 3)
        ``(x, y, theta)`` at cell centres, metres and radians.
    """
    if not free.any():
        raise ValueError("map has no free space: no FREE cell to start a robot in")
    candidates = np.flatnonzero(start_cells(walls, resolution, robot_radius) & free)
    if len(candidates) < n_starts:
        raise ValueError(
            f"map has room for only {len(candidates)} of {n_starts} starts for a robot of "
            f"radius {robot_radius} m (clearance >= radius + {START_MARGIN} m) in its "
            "largest free region"
        )
    if len(candidates) > _START_SAMPLE:
        candidates = np.sort(rng.choice(candidates, size=_START_SAMPLE, replace=False))
    rows, cols = np.unravel_index(candidates, walls.shape)
    points = np.stack(
        [origin[0] + (cols + 0.5) * resolution, origin[1] + (rows + 0.5) * resolution], axis=1
    )
    distance = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    first, second = np.unravel_index(int(np.argmax(distance)), distance.shape)
    chosen = [int(first), int(second)]
    nearest = np.minimum(distance[first], distance[second])
    while len(chosen) < n_starts:
        nearest[chosen] = -1.0
        pick = int(np.argmax(nearest))
        chosen.append(pick)
        nearest = np.minimum(nearest, distance[pick])
    chosen = chosen[:n_starts]
    heading0 = rng.uniform(-np.pi, np.pi)
    headings = wrap_angle(heading0 + 2.0 * np.pi * np.arange(n_starts) / n_starts)
    return np.column_stack([points[chosen], headings])


def _check_starts(
    world: WorldSpec,
    walls: BoolArray,
    origin: FloatArray,
    resolution: float,
    robot_radius: float,
) -> None:
    """Raise ValueError naming the first start that is off the map, in a wall or too close."""
    cells = np.floor((world.starts[:, :2] - origin) / resolution).astype(np.int64)
    rows, cols = walls.shape
    clearance = world.clearance(world.starts[:, :2])
    for index, (start, (ix, iy)) in enumerate(zip(world.starts, cells, strict=True)):
        where = f"start {index} at (x, y, theta) = ({start[0]:g}, {start[1]:g}, {start[2]:g})"
        if not (1 <= ix < cols - 1 and 1 <= iy < rows - 1):
            raise ValueError(f"{where} lies outside the map")
        if walls[iy, ix] or clearance[index] < 0.0:
            raise ValueError(f"{where} lies inside a wall")
        if clearance[index] < robot_radius:
            raise ValueError(
                f"{where} is {clearance[index]:.3f} m from a wall, closer than the robot "
                f"radius {robot_radius} m"
            )


def _world_geometry(
    grid: GridMap, unknown_as_wall: bool
) -> tuple[
    BoolArray, BoolArray, FloatArray, FloatArray, FloatArray, tuple[float, float, float, float]
]:
    """Framed wall and free masks, frame origin (2,), quads (K, 4, 2), segments (M, 4), bounds."""
    resolution = grid.resolution
    inner = wall_mask(grid, unknown_as_wall=unknown_as_wall)
    if inner.all():
        raise ValueError("map has no free space: every cell is a wall")
    walls = np.pad(inner, 1, constant_values=True)
    free = np.pad(grid.cells == FREE, 1, constant_values=False)
    origin = np.asarray(grid.origin, dtype=np.float64) - resolution
    quads = _rectangles_to_quads(cover_rectangles(walls), origin, resolution)
    segments = outline_segments(walls).astype(np.float64) * resolution
    segments[:, 0::2] += origin[0]
    segments[:, 1::2] += origin[1]
    rows, cols = walls.shape
    bounds = (
        float(origin[0]),
        float(origin[1]),
        float(origin[0] + cols * resolution),
        float(origin[1] + rows * resolution),
    )
    return walls, free, origin, quads, segments, bounds


def world_from_map(
    grid: GridMap,
    *,
    name: str,
    starts: ArrayLike | None = None,
    n_starts: int = 2,
    unknown_as_wall: bool = True,
    robot_radius: float = 0.2,
    rng: np.random.Generator | None = None,
    description: str = "",
) -> WorldSpec:
    """Build a simulator world whose walls are a map's occupied cells.

    Parameters
    ----------
    grid : GridMap
        The map; its cells keep their world position (``origin``, ``resolution``).
    name : str
        The world's name (e.g. ``"map:plant.yaml"``).
    starts : array_like, shape (S, 3), optional
        Start poses ``(x, y, theta)`` (m, rad). Each must lie on the map, outside every
        wall, at least ``robot_radius`` from the nearest wall. Default: ``n_starts`` poses
        chosen automatically (see Notes).
    n_starts : int
        How many starts to choose when ``starts`` is None (>= 1).
    unknown_as_wall : bool
        Whether UNKNOWN cells are walls (default) or open space.
    robot_radius : float
        Robot footprint radius (m), for the start clearance.
    rng : numpy.random.Generator, optional
        Randomness for the automatic starts; default ``np.random.default_rng(0)``.
    description : str
        One line for ``mrslam scenarios``; a default names the map size.

    Returns
    -------
    WorldSpec
        ``walls`` (K, 4, 2): ccw rectangles from :func:`cover_rectangles`; ``segments``
        (M, 4): the outline from :func:`outline_segments` in metres; ``bounds``: the grid
        extent grown by one cell on every side (the wall frame).

    Raises
    ------
    ValueError
        The map has no free space, no room for the automatic starts, or a given start is
        off the map, inside a wall or closer than ``robot_radius`` to one (the message
        names the start's index and pose).

    Notes
    -----
    Automatic starts lie at the centres of FREE cells where the robot can start by the
    start clearance rule (:mod:`mrslam_env.sim.starts`: clearance estimate at least
    ``robot_radius + START_MARGIN``, inside the largest 4-connected region of cells where
    the robot fits), as far apart as a random sample of 512 candidate cells allows, with
    headings spread evenly around the circle. They are deterministic given ``rng``.
    """
    if not name:
        raise ValueError("name must be a non-empty string")
    if not (math.isfinite(robot_radius) and robot_radius >= 0.0):
        raise ValueError(f"robot_radius must be >= 0 m, got {robot_radius}")
    if starts is None and n_starts < 1:
        raise ValueError(f"n_starts must be >= 1, got {n_starts}")
    rng = np.random.default_rng(0) if rng is None else rng
    resolution = grid.resolution
    walls, free, origin, quads, segments, bounds = _world_geometry(grid, unknown_as_wall)
    if starts is None:
        start_poses = _choose_starts(walls, free, origin, resolution, n_starts, robot_radius, rng)
    else:
        start_poses = np.asarray(starts, dtype=np.float64)
        if start_poses.ndim == 1:
            start_poses = start_poses[None, :]
        if start_poses.ndim != 2 or start_poses.shape[1] != 3 or len(start_poses) == 0:
            raise ValueError(f"starts must have shape (S>0, 3), got {start_poses.shape}")
        if not np.all(np.isfinite(start_poses)):
            raise ValueError(f"starts must be finite, got {start_poses.tolist()}")
    if not description:
        description = f"built from a {grid.shape[0]} x {grid.shape[1]} map at {resolution:g} m/cell"
    world = WorldSpec(
        name=name,
        walls=quads,
        starts=start_poses,
        segments=segments,
        bounds=bounds,
        description=description,
    )
    if starts is not None:
        _check_starts(world, walls, origin, resolution, robot_radius)
    return world


def _random_rooms_map(size: int, rng: np.random.Generator, resolution: float = 0.05) -> GridMap:
    """A ``size`` x ``size`` test map: rooms with doors, furniture and speckle (~10% walls)."""
    occupied = np.zeros((size, size), dtype=bool)
    thickness = 3
    occupied[:thickness], occupied[-thickness:] = True, True
    occupied[:, :thickness], occupied[:, -thickness:] = True, True
    for axis in (0, 1):
        position = int(rng.integers(40, 120))
        while position < size - 40:
            if axis == 0:
                occupied[position : position + thickness] = True
            else:
                occupied[:, position : position + thickness] = True
            for door in range(int(rng.integers(20, 60)), size - 30, 100):
                if axis == 0:
                    occupied[position : position + thickness, door : door + 20] = False
                else:
                    occupied[door : door + 20, position : position + thickness] = False
            position += int(rng.integers(40, 120))
    for _ in range(size // 4):
        r, c = rng.integers(0, size - 20, size=2)
        h, w = rng.integers(3, 16, size=2)
        occupied[r : r + h, c : c + w] = True
    occupied |= rng.random((size, size)) < 0.005
    cells = np.where(occupied, OCCUPIED, FREE).astype(np.int8)
    cells[rng.random((size, size)) < 0.002] = UNKNOWN
    return GridMap(cells=cells, resolution=resolution, origin=(-size * resolution / 2, 0.0))


def _bench_world_from_map(size: int = 1000, repeats: int = 5, seed: int = 0) -> dict[str, float]:
    """Time :func:`world_from_map` on a random ``size`` x ``size`` rooms map.

    Returns the median and minimum wall time (s) over ``repeats`` runs after one warm-up,
    the median time of this module's own work (geometry and starts, without
    ``WorldSpec``'s validation of each quad), the map's wall fraction and the number of
    rectangles and segments. Run with
    ``python -m mrslam_env.sim.mapworld``.
    """
    grid = _random_rooms_map(size, np.random.default_rng(seed))
    world = world_from_map(grid, name="bench")
    times, geometry_times = [], []
    for _ in range(repeats):
        begin = time.perf_counter()
        world_from_map(grid, name="bench")
        times.append(time.perf_counter() - begin)
        begin = time.perf_counter()
        walls, free, origin, *_ = _world_geometry(grid, True)
        _choose_starts(walls, free, origin, grid.resolution, 2, 0.2, np.random.default_rng(0))
        geometry_times.append(time.perf_counter() - begin)
    return {
        "size": float(size),
        "wall_fraction": float(wall_mask(grid).mean()),
        "wall_cells": float(wall_mask(grid).sum()),
        "rectangles": float(len(world.walls)),
        "segments": float(len(world.segments)),
        "median_s": float(np.median(times)),
        "min_s": float(np.min(times)),
        "geometry_and_starts_median_s": float(np.median(geometry_times)),
    }


if __name__ == "__main__":
    for key, value in _bench_world_from_map().items():
        print(f"{key:>30}: {value:g}")
