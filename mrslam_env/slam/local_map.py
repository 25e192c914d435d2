"""The egocentric local map: a fixed-size crop of a robot's own map around its pose.

This is what a learned policy sees of the map (the env's ``local_map`` observation). The
crop is centred on the robot and turned with it: the robot looks along +x (increasing
column), +y (increasing row) is to its left, row 0 is the lowest local y, as everywhere
in the project (docs/design.md §2).

Channels (uint8, 0 or 1):

=======  ==========  ===========================================================
channel  name        1 when
=======  ==========  ===========================================================
0        free        some part of the cell is FREE in the robot's map
1        occupied    some part of the cell is OCCUPIED in the robot's map
=======  ==========  ===========================================================

Both 0 means unknown (or outside the map). Both 1 happens on a wall's edge. Each output
cell is sampled at ``pool × pool`` points spaced finer than the map's cells, so a wall one
map cell thick is never lost between samples.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.slam.grid import OccupancyGrid

__all__ = ["FREE_CHANNEL", "OCCUPIED_CHANNEL", "egocentric_crop", "local_map"]

FREE_CHANNEL = 0
OCCUPIED_CHANNEL = 1


@numba.njit(cache=True)
def egocentric_crop(
    log_odds: NDArray[np.float32],
    origin_x: float,
    origin_y: float,
    resolution: float,
    x: float,
    y: float,
    heading: float,
    cells: int,
    cell_size: float,
    pool: int,
    free_threshold: float,
    occupied_threshold: float,
) -> NDArray[np.uint8]:
    """Sample the crop.

    Parameters
    ----------
    log_odds : ndarray, shape (rows, cols), float32
        The map (docs/design.md §2 placement given by ``origin_x, origin_y, resolution``, m).
    x, y, heading : float
        The robot's pose in the map frame, m, m, rad.
    cells : int
        Output side, cells.
    cell_size : float
        Output cell edge, m.
    pool : int
        Samples per output cell and axis.
    free_threshold, occupied_threshold : float
        The trinary thresholds on log-odds.

    Returns
    -------
    ndarray, shape (2, cells, cells), uint8
        The channels of the module docstring.
    """
    rows, cols = log_odds.shape
    out = np.zeros((2, cells, cells), dtype=np.uint8)
    c, s = math.cos(heading), math.sin(heading)
    half = cells / 2.0
    step = cell_size / pool
    # Thresholds in float32, as numpy compares the float32 grid (GridMap's trinary view).
    free = np.float32(free_threshold)
    occupied = np.float32(occupied_threshold)
    # The samples' offsets along each axis and their rotated parts, once (the same
    # products and sums, in the same order, as sample by sample); then a row of samples
    # at a time, the cell indices first (a loop that vectorises), the lookups after.
    n = cells * pool
    along_x = np.empty(n)  # x + c * lx
    along_y = np.empty(n)  # y + s * lx
    across_x = np.empty(n)  # s * ly
    across_y = np.empty(n)  # c * ly
    for k in range(cells):
        for b in range(pool):
            offset = (k - half) * cell_size + (b + 0.5) * step
            along_x[k * pool + b] = x + c * offset
            along_y[k * pool + b] = y + s * offset
            across_x[k * pool + b] = s * offset
            across_y[k * pool + b] = c * offset
    column = np.arange(n) // pool  # the output column of each sample
    gx = np.empty(n)
    gy = np.empty(n)
    for i in range(n):
        sy = across_x[i]
        cy = across_y[i]
        for j in range(n):
            gx[j] = (along_x[j] - sy - origin_x) / resolution
            gy[j] = (along_y[j] + cy - origin_y) / resolution
        r = i // pool
        for j in range(n):
            # Below 0 is outside the map; from 0 up, truncation is the floor.
            if 0.0 <= gx[j] < cols and 0.0 <= gy[j] < rows:
                value = log_odds[int(gy[j]), int(gx[j])]
                if value > occupied:
                    out[OCCUPIED_CHANNEL, r, column[j]] = 1
                elif value < free:
                    out[FREE_CHANNEL, r, column[j]] = 1
    return out


def local_map(
    grid: OccupancyGrid, pose: ArrayLike, cells: int = 64, cell_size: float = 0.1
) -> NDArray[np.uint8]:
    """The egocentric crop (2, cells, cells) of ``grid`` around ``pose`` (x, y, theta in
    the grid's frame); see the module docstring for the channels."""
    if not (isinstance(cells, int) and cells >= 1):
        raise ValueError(f"cells must be an int >= 1, got {cells!r}")
    if not (math.isfinite(cell_size) and cell_size > 0):
        raise ValueError(f"cell_size must be > 0 m, got {cell_size!r}")
    x, y, heading = (float(v) for v in np.asarray(pose, dtype=np.float64))
    pool = max(1, math.ceil(cell_size / grid.resolution - 1e-9)) + 1
    origin_x, origin_y = grid.origin
    config = grid.config
    return egocentric_crop(
        grid.log_odds,
        origin_x,
        origin_y,
        grid.resolution,
        x,
        y,
        heading,
        cells,
        cell_size,
        pool,
        config.free_threshold,
        config.occupied_threshold,
    )
