"""The goal cells of frontier extraction's step 4: where a robot stands to see a frontier
(docs/design.md §6, building blocks).

Each frontier's goal is a reachable cell with no mapped wall between it and one of the
frontier's cells, the one closest to the frontier's middle (:func:`_goal_cells`); a
frontier with none within ``max_goal_offset`` is dropped. The nearest reachable cells come
from the exact Euclidean distance transform evaluated at the frontier cells only
(:func:`_nearest_feature_at`), the sight lines from an integer traversal
(:func:`_seen_from`), both numba. Used by :func:`agents.frontiers.extract_frontiers`.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__: list[str] = []  # the helpers of agents.frontiers.extract_frontiers

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def _goal_cells(
    labels: NDArray[np.int32],
    count: int,
    centroid_cells: FloatArray,
    reachable: BoolArray,
    occupied: BoolArray,
    resolution: float,
    max_goal_offset: float,
    offset: tuple[int, int],
    cells: IntArray,
) -> tuple[IntArray, BoolArray]:
    """Per frontier: a reachable cell that sees one of its cells, the one closest to its
    centroid that can be seen.

    A frontier cell is seen from a cell when no ``occupied`` cell lies on the segment
    between them (:func:`_seen_from`). Its goal is its nearest reachable cell when that is
    within ``max_goal_offset`` and sees it, else the nearest reachable cell within
    ``max_goal_offset`` that does; the frontier's cells are tried in order of distance to
    its centroid. A frontier with no such cell is invalid: the reachable space near it
    lies behind a wall (a frontier mapped through a gap in a wall, or behind a pillar),
    and a robot sent there would stand at the goal without ever seeing it. ``labels``,
    ``reachable`` and ``occupied`` may be a window of the map whose cell [0, 0] is the
    map's cell ``offset``; ``centroid_cells`` and the goal cells returned are in the map's
    cells; ``cells`` is ``np.argwhere(labels > 0)``.
    """
    goal_cells = np.zeros((count, 2), dtype=np.int64)
    valid = np.zeros(count, dtype=bool)
    if count == 0 or not reachable.any():
        return goal_cells, valid
    owner = (labels[cells[:, 0], cells[:, 1]] - 1).astype(np.int64)
    to_centroid = ((cells + np.asarray(offset) - centroid_cells[owner]) ** 2).sum(axis=1)
    # The nearest reachable cell at the frontier cells only (the transform scipy's
    # distance_transform_edt would compute everywhere, ties broken as it does).
    nearest = _nearest_feature_at(reachable, cells)
    steps = (nearest - cells).astype(np.float64)
    to_reachable = np.sqrt(steps[:, 0] * steps[:, 0] + steps[:, 1] * steps[:, 1]) * resolution
    # Cells closer to the middle first (the first in row-major order on a tie); cells
    # farther than max_goal_offset from reachable space are no candidates.
    key = np.where(to_reachable <= max_goal_offset, to_centroid, np.inf)
    order = np.lexsort((key, owner))  # stable: ties keep the row-major order
    order = order[np.isfinite(key[order])]
    reach = max_goal_offset / resolution
    disk = _disk_by_distance(reach)
    chosen = _first_seen(order, owner, cells, nearest, reachable, occupied, disk, reach)
    frontiers = np.flatnonzero(chosen[:, 0] >= 0)
    goal_cells[frontiers] = chosen[frontiers] + np.asarray(offset)
    valid[frontiers] = True
    return goal_cells, valid


def _disk_by_distance(radius_cells: float) -> IntArray:
    """Cell offsets (K, 2) within ``radius_cells`` of the centre, nearest first (row-major
    order on a tie)."""
    reach = math.floor(radius_cells)
    rows, cols = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    squared = (rows**2 + cols**2).ravel()
    inside = np.flatnonzero(squared <= radius_cells**2)
    inside = inside[np.argsort(squared[inside], kind="stable")]
    return np.stack([rows.ravel()[inside], cols.ravel()[inside]], axis=1).astype(np.int64)


@numba.njit(cache=True)
def _first_seen(
    order: IntArray,
    owner: IntArray,
    cells: IntArray,
    nearest: IntArray,
    reachable: BoolArray,
    occupied: BoolArray,
    disk: IntArray,
    reach: float,
) -> IntArray:
    """Per frontier (``owner.max() + 1`` rows), the goal cell of :func:`_goal_cells` or
    ``(-1, -1)``: ``order`` lists the candidate frontier cells (indices into ``cells``)
    frontier by frontier, best first."""
    count = 0
    for k in range(len(owner)):
        count = max(count, owner[k] + 1)
    out = np.full((count, 2), -1, dtype=np.int64)
    rows, cols = reachable.shape
    for k in order:
        frontier = owner[k]
        if out[frontier, 0] >= 0:
            continue
        r, c = cells[k, 0], cells[k, 1]
        nr, nc = nearest[k, 0], nearest[k, 1]
        if (nr - r) ** 2 + (nc - c) ** 2 <= reach * reach and _seen_from(occupied, nr, nc, r, c):
            out[frontier, 0], out[frontier, 1] = nr, nc
            continue
        for j in range(len(disk)):
            gr, gc = r + disk[j, 0], c + disk[j, 1]
            inside = 0 <= gr < rows and 0 <= gc < cols
            if inside and reachable[gr, gc] and _seen_from(occupied, gr, gc, r, c):
                out[frontier, 0], out[frontier, 1] = gr, gc
                break
    return out


@numba.njit(cache=True)
def _seen_from(occupied: BoolArray, r0: int, c0: int, r1: int, c1: int) -> bool:
    """Whether no ``occupied`` cell lies on the segment between cells ``(r0, c0)`` and
    ``(r1, c1)``, ends excluded: sampled twice per cell along its longer axis, so that a
    diagonal wall (cells touching at corners) blocks it too."""
    dr, dc = r1 - r0, c1 - c0
    n = 2 * max(abs(dr), abs(dc))
    for k in range(1, n):
        r = r0 + (2 * k * dr + n) // (2 * n)  # k dr / n, rounded
        c = c0 + (2 * k * dc + n) // (2 * n)
        if (r != r0 or c != c0) and (r != r1 or c != c1) and occupied[r, c]:
            return False
    return True


@numba.njit(cache=True)
def _nearest_feature_at(features: BoolArray, cells: IntArray) -> IntArray:
    """The nearest ``True`` cell ``(row, col)`` of each of ``cells`` (K, 2), row-major
    sorted, as ``ndimage.distance_transform_edt(~features, return_indices=True)`` gives
    it, ties included: the same exact algorithm (Maurer, Qi and Raghavan 2003), a pass
    along each column then one along each row, in integers, the row pass only on the
    rows of ``cells``. Needs one ``True`` cell at least."""
    rows, cols = features.shape
    # Per column, for each row: the nearest feature row in the column (ties: the lower
    # row), or -1 when the column has none; from the last feature at or above and the
    # first at or below.
    above = np.empty((rows, cols), dtype=np.int32)
    below = np.empty((rows, cols), dtype=np.int32)
    for c in range(cols):  # row by row, for the cache
        above[0, c] = 0 if features[0, c] else -1
        below[rows - 1, c] = rows - 1 if features[rows - 1, c] else -1
    for r in range(1, rows):
        for c in range(cols):
            above[r, c] = r if features[r, c] else above[r - 1, c]
    for r in range(rows - 2, -1, -1):
        for c in range(cols):
            below[r, c] = r if features[r, c] else below[r + 1, c]
    out = np.empty((len(cells), 2), dtype=np.int64)
    sites = np.empty(cols, dtype=np.int64)  # the columns of the envelope's sites
    site_row = np.empty(cols, dtype=np.int64)
    k = 0
    while k < len(cells):
        r = cells[k, 0]
        # The column pass's feature at (r, c) for every column c.
        top = -1
        for c in range(cols):
            up, down = np.int64(above[r, c]), np.int64(below[r, c])
            if up < 0:
                feature = down
            elif down < 0 or r - up <= down - r:
                feature = up
            else:
                feature = down
            if feature < 0:
                continue
            # Drop the sites the new one hides along this row (the lower envelope).
            w = (feature - r) ** 2
            while top >= 1:
                a = sites[top] - sites[top - 1]
                b = c - sites[top]
                u = (site_row[top - 1] - r) ** 2
                v = (site_row[top] - r) ** 2
                if (a + b) * v - b * u - a * w - a * b * (a + b) <= 0:
                    break
                top -= 1
            top += 1
            sites[top] = c
            site_row[top] = feature
        # Query the row's cells left to right: advance while the next site is closer.
        at = 0
        while k < len(cells) and cells[k, 0] == r:
            c = cells[k, 1]
            here = (site_row[at] - r) ** 2 + (sites[at] - c) ** 2
            while at < top:
                there = (site_row[at + 1] - r) ** 2 + (sites[at + 1] - c) ** 2
                if here <= there:
                    break
                here = there
                at += 1
            out[k, 0] = site_row[at]
            out[k, 1] = sites[at]
            k += 1
    return out
