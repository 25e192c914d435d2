"""Bringing maps to one lattice and fusing them (docs/design.md §5 step 7).

- :func:`resample_map` changes a grid's resolution (down-sampling keeps the most
  conservative class of each block: occupied over free over unknown).
- :func:`warp_map` expresses map 2 in map 1's frame by inverse nearest-neighbour mapping
  (:func:`mrslam_env.gridmap.resample_cells`): every output cell takes the class of the
  map-2 cell under its centre.
- :func:`fuse_maps` lays m1 and the warped m2 on one grid on m1's lattice, grown to cover
  both, with the rule *known beats unknown; where both are known and disagree, occupied
  wins*. Occupied-wins is the conservative choice for a robot that plans on the merged map:
  a wall seen by one robot and not the other (a door closed later, a dynamic obstacle, a
  residual misalignment of a cell) is kept rather than opened up.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap, resample_cells
from mrslam_env.merge.dissimilarity import check_same_resolution, check_transform

__all__ = [
    "at_resolution",
    "covering_grid",
    "fuse_all",
    "fuse_cells",
    "fuse_maps",
    "resample_map",
    "warp_map",
]

LATTICE_EPS = 1e-6
"""Tolerance, in cells, when snapping world bounds to a lattice (absorbs round-off so a
bound lying on a cell border does not gain a spurious extra cell)."""

_CLASS_OF_PRIORITY = np.array([UNKNOWN, FREE, OCCUPIED], dtype=np.int8)


def _priority(cells: NDArray[np.int8]) -> NDArray[np.int8]:
    """0 for UNKNOWN, 1 for FREE, 2 for OCCUPIED: the order in which classes win."""
    return ((cells == FREE) * 1 + (cells == OCCUPIED) * 2).astype(np.int8)


def fuse_cells(cells1: NDArray[np.int8], cells2: NDArray[np.int8]) -> NDArray[np.int8]:
    """Fuse two trinary arrays of one shape cell by cell: known beats unknown, occupied
    beats free. Returns a new int8 array."""
    return _CLASS_OF_PRIORITY[np.maximum(_priority(cells1), _priority(cells2))]


def _check_not_empty(grid: GridMap, name: str) -> None:
    if grid.cells.size == 0:
        raise ValueError(f"{name} is empty (shape {grid.shape})")


def _check_has_known(grid: GridMap, name: str) -> None:
    _check_not_empty(grid, name)
    if not (grid.free.any() or grid.occupied.any()):
        raise ValueError(f"{name} has no known (free or occupied) cell")


def at_resolution(grid: GridMap, resolution: float) -> GridMap:
    """``grid`` itself when its cells are already ``resolution`` m, else
    :func:`resample_map` of it."""
    if math.isclose(grid.resolution, resolution, rel_tol=1e-9):
        return grid
    return resample_map(grid, resolution)


def resample_map(grid: GridMap, resolution: float) -> GridMap:
    """The grid at another resolution, same origin, covering at least the same extent.

    Down-sampling (coarser cells) assigns each input cell to the output cell containing its
    centre and keeps the winning class per output cell: occupied over free over unknown,
    so thin walls survive. Up-sampling (finer cells) gives each output cell the class of
    the input cell under its centre. Output cells no input cell reaches are UNKNOWN.

    Parameters
    ----------
    grid : GridMap
        A non-empty grid.
    resolution : float
        The new cell size, metres (> 0).

    Returns
    -------
    GridMap
        ``ceil(rows * old / new)`` by ``ceil(cols * old / new)`` cells; a copy if the
        resolution is unchanged.

    Raises
    ------
    ValueError
        An empty grid or a resolution that is not a finite positive number.
    """
    _check_not_empty(grid, "map")
    if not (isinstance(resolution, int | float) and math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution must be a finite number > 0 m, got {resolution!r}")
    old = grid.resolution
    if math.isclose(resolution, old, rel_tol=1e-9):
        return GridMap(cells=grid.cells.copy(), resolution=old, origin=grid.origin)
    rows, cols = grid.shape
    out_rows = max(1, math.ceil(rows * old / resolution - LATTICE_EPS))
    out_cols = max(1, math.ceil(cols * old / resolution - LATTICE_EPS))
    if resolution > old:
        cells = _downsample(grid.cells, old / resolution, out_rows, out_cols)
    else:
        cells = _upsample(grid.cells, resolution / old, out_rows, out_cols)
    return GridMap(cells=cells, resolution=float(resolution), origin=grid.origin)


def _bin_axis(priority: NDArray[np.int8], ratio: float, size: int, axis: int) -> NDArray[np.int8]:
    """Max of ``priority`` over the input cells whose centres fall in each output cell
    along one axis (``ratio = old / new < 1``); output cells reached by none get 0."""
    n = priority.shape[axis]
    target = np.minimum(np.floor((np.arange(n) + 0.5) * ratio).astype(np.int64), size - 1)
    starts = np.flatnonzero(np.r_[True, target[1:] != target[:-1]])
    reduced = np.maximum.reduceat(priority, starts, axis=axis)
    out_shape = list(priority.shape)
    out_shape[axis] = size
    out = np.zeros(out_shape, dtype=np.int8)
    if axis == 0:
        out[target[starts], :] = reduced
    else:
        out[:, target[starts]] = reduced
    return out


def _downsample(
    cells: NDArray[np.int8], ratio: float, out_rows: int, out_cols: int
) -> NDArray[np.int8]:
    # The block maximum is separable: reduce the rows, then the columns.
    priority = _bin_axis(_priority(cells), ratio, out_rows, axis=0)
    priority = _bin_axis(priority, ratio, out_cols, axis=1)
    return _CLASS_OF_PRIORITY[priority]


def _upsample(
    cells: NDArray[np.int8], ratio: float, out_rows: int, out_cols: int
) -> NDArray[np.int8]:
    # ratio = new / old < 1: the input index under each output centre.
    source_rows = np.floor((np.arange(out_rows) + 0.5) * ratio).astype(np.int64)
    source_cols = np.floor((np.arange(out_cols) + 0.5) * ratio).astype(np.int64)
    rows, cols = cells.shape
    out = np.full((out_rows, out_cols), UNKNOWN, dtype=np.int8)
    keep_rows = source_rows < rows
    keep_cols = source_cols < cols
    source = cells[np.ix_(source_rows[keep_rows], source_cols[keep_cols])]
    out[np.ix_(keep_rows, keep_cols)] = source
    return out


def _image_bounds(m2: GridMap, map1_from_map2: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(xmin, ymin, xmax, ymax)`` in map 1's frame of m2's extent's four corners."""
    x0, y0, x1, y1 = m2.extent
    corners = transform_points(map1_from_map2, np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]]))
    return np.concatenate([corners.min(axis=0), corners.max(axis=0)])


def _lattice_grid(anchor: ArrayLike, resolution: float, bounds: NDArray[np.float64]) -> GridMap:
    """The smallest all-UNKNOWN grid whose cell corners lie on the lattice through
    ``anchor`` (x, y) with spacing ``resolution`` and which covers ``bounds``."""
    anchor = np.asarray(anchor, dtype=np.float64)
    low = np.floor((bounds[:2] - anchor) / resolution + LATTICE_EPS)
    high = np.ceil((bounds[2:] - anchor) / resolution - LATTICE_EPS)
    cols, rows = (np.maximum(high - low, 1)).astype(np.int64)
    origin = anchor + low * resolution
    return GridMap(
        cells=np.full((int(rows), int(cols)), UNKNOWN, dtype=np.int8),
        resolution=resolution,
        origin=(float(origin[0]), float(origin[1])),
    )


def covering_grid(m1: GridMap, m2: GridMap, map1_from_map2: ArrayLike) -> GridMap:
    """An all-UNKNOWN grid on m1's lattice covering m1 and the image of m2 in map 1's frame.

    Parameters
    ----------
    m1, m2 : GridMap
        Non-empty maps of one resolution.
    map1_from_map2 : array_like, shape (3,)
        Metres and radians.

    Returns
    -------
    GridMap
        Same resolution as m1, origin on m1's lattice (m1's origin plus whole cells).
    """
    transform = check_transform(map1_from_map2)
    _check_not_empty(m1, "map 1")
    _check_not_empty(m2, "map 2")
    resolution = check_same_resolution(m1, m2)
    image = _image_bounds(m2, transform)
    own = np.asarray(m1.extent)
    bounds = np.concatenate([np.minimum(own[:2], image[:2]), np.maximum(own[2:], image[2:])])
    return _lattice_grid(m1.origin, resolution, bounds)


def warp_map(m2: GridMap, map1_from_map2: ArrayLike, *, like: GridMap | None = None) -> GridMap:
    """m2 expressed in map 1's frame by inverse nearest-neighbour mapping.

    Each output cell takes the class of the m2 cell under the pre-image of its centre
    (UNKNOWN outside m2), by :func:`mrslam_env.gridmap.resample_cells` onto the output
    lattice. Lattice-exact transforms (quarter turns, whole-cell shifts) are reproduced
    exactly.

    Parameters
    ----------
    m2 : GridMap
        The map to warp; non-empty with at least one known cell.
    map1_from_map2 : array_like, shape (3,)
        Metres and radians.
    like : GridMap, optional
        The output grid's lattice and extent (its cells are ignored); it must have m2's
        resolution. Use :func:`covering_grid` for m1's lattice grown to cover m2's image.
        Without it, the output covers exactly m2's image on the lattice through the image
        of m2's origin corner, so the identity returns m2 itself.

    Returns
    -------
    GridMap
        m2 in map 1's frame.

    Raises
    ------
    ValueError
        An empty or all-unknown m2, a non-finite transform, or ``like`` of another
        resolution.
    """
    transform = check_transform(map1_from_map2)
    _check_has_known(m2, "map 2")
    if like is None:
        anchor = transform_points(transform, np.asarray([m2.origin]))[0]
        like = _lattice_grid(anchor, m2.resolution, _image_bounds(m2, transform))
    else:
        _check_not_empty(like, "like")
        check_same_resolution(like, m2)
    out = resample_cells(m2, transform, like.origin, like.shape, like.resolution)
    return GridMap(cells=out, resolution=like.resolution, origin=like.origin)


def fuse_maps(m1: GridMap, m2: GridMap, map1_from_map2: ArrayLike) -> GridMap:
    """Fuse m2 into m1's frame (docs/design.md §5 step 7).

    Parameters
    ----------
    m1, m2 : GridMap
        Maps of one resolution (see :func:`resample_map`), each with a known cell.
    map1_from_map2 : array_like, shape (3,)
        The relative pose, metres and radians.

    Returns
    -------
    GridMap
        On m1's lattice, grown to cover m1 and the image of m2. Rule per cell: known beats
        unknown; where both maps are known and disagree, occupied wins.

    Raises
    ------
    ValueError
        Different resolutions, an empty or all-unknown map, or a non-finite transform.
    """
    transform = check_transform(map1_from_map2)
    _check_has_known(m1, "map 1")
    _check_has_known(m2, "map 2")
    canvas = covering_grid(m1, m2, transform)
    row0, col0 = np.rint(
        (np.asarray(m1.origin)[::-1] - np.asarray(canvas.origin)[::-1]) / canvas.resolution
    ).astype(np.int64)
    rows1, cols1 = m1.shape
    cells1 = canvas.cells.copy()
    cells1[row0 : row0 + rows1, col0 : col0 + cols1] = m1.cells
    warped2 = warp_map(m2, transform, like=canvas)
    return GridMap(
        cells=fuse_cells(cells1, warped2.cells),
        resolution=canvas.resolution,
        origin=canvas.origin,
    )


def fuse_all(base: GridMap, others: Iterable[tuple[GridMap, ArrayLike]]) -> GridMap:
    """``base`` with every other map fused into its frame, in order (:func:`fuse_maps`):
    each ``(map, base_from_map)``, a map of another resolution resampled to the fused
    map's first (:func:`resample_map`)."""
    fused = base
    for other, transform in others:
        fused = fuse_maps(fused, at_resolution(other, fused.resolution), transform)
    return fused
