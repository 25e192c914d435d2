"""Step 3 of path planning: a cell path shortened by line of sight (docs/design.md §6,
building blocks).

:func:`shorten_path` prunes the cell path of a search ("string pulling") on the
:class:`~agents.planning_costs.CostGrid`, without giving up the clearance the soft cost
bought: a shortcut never crosses a cell much costlier than the costliest cell of the path
it replaces. :func:`line_is_clear` is the segment test (an exact grid traversal in
integers, numba). :mod:`agents.planning` re-exports both.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.planning_costs import CostGrid

__all__ = ["line_is_clear", "shorten_path"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@numba.njit(cache=True)
def _line_max_cost(cost: FloatArray, r0: int, c0: int, r1: int, c1: int) -> float:
    """Largest cell cost on the straight segment between two cell centres.

    An exact grid traversal in integer arithmetic: the segment crosses a row boundary at
    ``t = (i + 1/2) / |dr|`` and a column boundary at ``t = (j + 1/2) / |dc|``; where
    it passes exactly through a cell corner, both cells beside the corner count too (a
    closed supercover). Blocked cells give ``inf``.
    """
    rows_to_cross = abs(r1 - r0)
    cols_to_cross = abs(c1 - c0)
    step_r = 1 if r1 > r0 else -1
    step_c = 1 if c1 > c0 else -1
    r, c = r0, c0
    worst = cost[r, c]
    i = 0
    j = 0
    while i < rows_to_cross or j < cols_to_cross:
        # Compare the next crossings (i + 1/2) / rows and (j + 1/2) / cols exactly.
        row_key = (2 * i + 1) * cols_to_cross
        col_key = (2 * j + 1) * rows_to_cross
        if j >= cols_to_cross or (i < rows_to_cross and row_key < col_key):
            r += step_r
            i += 1
        elif i >= rows_to_cross or col_key < row_key:
            c += step_c
            j += 1
        else:
            worst = max(worst, cost[r + step_r, c], cost[r, c + step_c])
            r += step_r
            c += step_c
            i += 1
            j += 1
        worst = max(worst, cost[r, c])
        if not math.isfinite(worst):
            return worst
    return worst


def line_is_clear(grid: CostGrid, cell_a: ArrayLike, cell_b: ArrayLike) -> bool:
    """Whether the segment between two cell centres crosses only passable cells."""
    a = np.asarray(cell_a, dtype=np.int64)
    b = np.asarray(cell_b, dtype=np.int64)
    return bool(
        math.isfinite(_line_max_cost(grid.cost, int(a[0]), int(a[1]), int(b[0]), int(b[1])))
    )


@numba.njit(cache=True)
def _shorten_kernel(cost: FloatArray, cells: IntArray, tolerance: float) -> IntArray:
    count = len(cells)
    keep = np.zeros(count, dtype=np.bool_)
    keep[0] = True
    keep[count - 1] = True
    anchor = 0
    while anchor < count - 1:
        best = anchor + 1
        worst_on_path = cost[cells[anchor, 0], cells[anchor, 1]]
        for j in range(anchor + 1, count):
            on_path = cost[cells[j, 0], cells[j, 1]]
            if on_path > worst_on_path:
                worst_on_path = on_path
            line = _line_max_cost(
                cost, cells[anchor, 0], cells[anchor, 1], cells[j, 0], cells[j, 1]
            )
            if line <= worst_on_path * tolerance:
                best = j
            else:
                break
        keep[best] = True
        anchor = best
    return cells[keep]


def shorten_path(grid: CostGrid, cells: ArrayLike, *, tolerance: float = 1.05) -> IntArray:
    """Line-of-sight pruning of a cell path ("string pulling").

    From each kept cell, jump to the farthest later cell of the path reachable in a
    straight line whose cells are all passable and no costlier than ``tolerance`` times
    the costliest path cell it replaces: shortcuts never run closer to walls than the
    original path did.

    Parameters
    ----------
    grid : CostGrid
    cells : array_like of int, shape (P, 2)
        A connected cell path ``(row, col)``, e.g. from :meth:`DistanceField.path_to`.
    tolerance : float
        Allowed cost ratio of a shortcut's worst cell to the replaced path's worst cell.

    Returns
    -------
    ndarray of int64, shape (Q, 2)
        A subsequence of ``cells`` with the same first and last cell (Q <= P).
    """
    cells = np.ascontiguousarray(cells, dtype=np.int64).reshape(-1, 2)
    if len(cells) <= 2:
        return cells.copy()
    return _shorten_kernel(grid.cost, cells, float(tolerance))
