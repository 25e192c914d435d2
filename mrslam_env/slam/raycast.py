"""Exact beam traversal on a grid (Amanatides & Woo, 1987), as numba kernels.

Every cell a beam passes through is visited exactly once, in order from the sensor to the
endpoint. Grid conventions are those of docs/design.md §2: ``[iy, ix]`` indexing, ``origin`` the
world corner of cell [0, 0], ``resolution`` metres per cell.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["dda_start", "mark_scan_observed", "traverse"]


@numba.njit(cache=True)
def dda_start(
    x0: float, y0: float, x1: float, y1: float, origin_x: float, origin_y: float, resolution: float
) -> tuple[int, int, int, int, float, float, float, float, int]:
    """Amanatides–Woo initial state for the segment (x0, y0)–(x1, y1): start cell
    ``(ix, iy)``, steps, parametric distances to the first cell borders and between borders
    (in units of the whole segment), and the number of cell steps to the end cell."""
    gx0, gy0 = (x0 - origin_x) / resolution, (y0 - origin_y) / resolution
    gx1, gy1 = (x1 - origin_x) / resolution, (y1 - origin_y) / resolution
    ix, iy = math.floor(gx0), math.floor(gy0)
    dx, dy = gx1 - gx0, gy1 - gy0
    step_x = 1 if dx > 0 else -1
    step_y = 1 if dy > 0 else -1
    t_delta_x = abs(1.0 / dx) if dx != 0.0 else math.inf
    t_delta_y = abs(1.0 / dy) if dy != 0.0 else math.inf
    if dx > 0:
        t_max_x = (ix + 1 - gx0) / dx
    elif dx < 0:
        t_max_x = (gx0 - ix) / -dx
    else:
        t_max_x = math.inf
    if dy > 0:
        t_max_y = (iy + 1 - gy0) / dy
    elif dy < 0:
        t_max_y = (gy0 - iy) / -dy
    else:
        t_max_y = math.inf
    n_steps = abs(math.floor(gx1) - ix) + abs(math.floor(gy1) - iy)
    return ix, iy, step_x, step_y, t_max_x, t_max_y, t_delta_x, t_delta_y, n_steps


@numba.njit(cache=True)
def traverse(
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
    cells: NDArray[np.int64],
) -> int:
    """Cells crossed by the segment (x0, y0)–(x1, y1), in order.

    Parameters
    ----------
    x0, y0, x1, y1 : float
        Segment end points in metres (world frame of the grid).
    origin_x, origin_y, resolution : float
        Grid placement.
    cells : ndarray, shape (capacity, 2), int64
        Output buffer for ``(iy, ix)``; needs
        ``capacity >= floor(|dx| / res) + floor(|dy| / res) + 3`` (dx, dy in metres).

    Returns
    -------
    int
        Number of cells written; they are not clipped to any grid bounds.
    """
    ix, iy, step_x, step_y, t_max_x, t_max_y, t_delta_x, t_delta_y, n_steps = dda_start(
        x0, y0, x1, y1, origin_x, origin_y, resolution
    )
    count = 0
    cells[count, 0], cells[count, 1] = iy, ix
    count += 1
    for _ in range(n_steps):
        if t_max_x < t_max_y:
            ix += step_x
            t_max_x += t_delta_x
        else:
            iy += step_y
            t_max_y += t_delta_y
        cells[count, 0], cells[count, 1] = iy, ix
        count += 1
    return count


@numba.njit(cache=True)
def _mark_segment(
    observed: NDArray[np.bool_],
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
) -> int:
    """:func:`traverse` fused with marking, for speed: marks in-grid cells on the segment,
    returns how many were unmarked before."""
    rows, cols = observed.shape
    ix, iy, step_x, step_y, t_max_x, t_max_y, t_delta_x, t_delta_y, n_steps = dda_start(
        x0, y0, x1, y1, origin_x, origin_y, resolution
    )
    newly = 0
    for k in range(n_steps + 1):
        if k > 0:
            if t_max_x < t_max_y:
                ix += step_x
                t_max_x += t_delta_x
            else:
                iy += step_y
                t_max_y += t_delta_y
        if 0 <= iy < rows and 0 <= ix < cols and not observed[iy, ix]:
            observed[iy, ix] = True
            newly += 1
    return newly


@numba.njit(cache=True)
def mark_scan_observed(
    observed: NDArray[np.bool_],
    origin_x: float,
    origin_y: float,
    resolution: float,
    x: float,
    y: float,
    heading: float,
    ranges: NDArray[np.float64],
) -> int:
    """Mark every in-grid cell swept by a scan (sensor to each endpoint, inclusive).

    Beam angles follow :func:`mrslam_env.sim.lidar.beam_angles`. Returns how many cells
    became observed (were ``False`` before).
    """
    n = ranges.shape[0]
    dtheta = 2.0 * math.pi / n
    newly = 0
    for i in range(n):
        a = heading - math.pi + i * dtheta
        ex, ey = x + ranges[i] * math.cos(a), y + ranges[i] * math.sin(a)
        newly += _mark_segment(observed, x, y, ex, ey, origin_x, origin_y, resolution)
    return newly
