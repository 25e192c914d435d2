"""How well two occupancy grids agree under a relative pose (docs/design.md §5 step 6).

Birk & Carpin, "Merging occupancy grid maps from multiple robots" (Proc. IEEE 94(7), 2006),
score a candidate ``map1_from_map2`` with the *dissimilarity*

    psi(m1, m2) = sum over c in {free, occupied} of d(m1, m2, c) + d(m2, m1, c),

where ``d(m1, m2, c)`` is the mean, over the class-c cells of m1, of the Manhattan (L1)
distance in cells to the nearest class-c cell of m2 (eqs. 11–13 of the virtual-robot paper).
The distance to the nearest class-c cell is read from a precomputed *distance map*
(:func:`distance_maps`, the paper's Algorithm 1), so one evaluation of psi is a gather per
cell (a numba kernel here), cheap enough for the hundreds of evaluations of a random walk
(:mod:`mrslam_env.merge.refine`).

Two variants of psi (:class:`DissimilarityConfig`):

- ``restrict_to_overlap=False`` — the paper's psi over *all* class-c cells. Cells whose
  image falls outside the other grid are charged the exact L1 distance to it (clamped
  lookup plus the distance to the grid's border). On *partial* maps this version is
  dominated by the parts the other map never saw: those cells are far from everything in
  the other map whatever the transform, and their cost pulls the minimum towards
  transforms that pile the two maps' known areas on top of each other instead of the true
  one. On the fixture pair ``map_pair("office", (5, 4), (9, 4), ...)`` (74% overlap) its
  minimum over a ±0.5 m grid of offsets lies at the edge of the grid, (-0.5, +0.15) m from
  the truth, and psi *falls* moving away from the truth.
- ``restrict_to_overlap=True`` (default) — only cells whose image lands on a *known* cell of
  the other map count, and the means are taken over those. The non-overlapping parts then
  carry no weight, and psi measures how well the shared part agrees, which is what the
  random walk needs to settle on the true transform of two partial maps. A transform with
  fewer than ``min_overlap_cells`` overlapping cells in either direction gets ``inf`` so
  the walk cannot escape into "no overlap, nothing to disagree about". On the same pair
  its minimum is exactly at the truth and it grows steadily with the offset (0.64 at the
  truth, 1.1–1.4 one cell off, 3–4 three cells off, 7–8 six cells off).

The *acceptance index* (:func:`acceptance_index`) is Birk & Carpin's
``ai = agree / (agree + disagree)`` over the cells known in both maps, with the overlap
size and the count of tolerant free-versus-occupied conflicts, the evidence that a merge is
wrong.

Distances and psi are in cells (all maps of one comparison share one resolution; bring
them there with :func:`mrslam_env.merge.fuse.resample_map`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from mrslam_env.geometry import inverse, transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.validation import check_fields, require

__all__ = [
    "Agreement",
    "DissimilarityConfig",
    "DistanceMaps",
    "WallMatch",
    "acceptance_index",
    "check_same_resolution",
    "check_transform",
    "dissimilarity",
    "distance_maps",
    "largest_conflict",
    "wall_match",
]

RESOLUTION_RTOL = 1e-6
"""Two resolutions closer than this relative tolerance count as equal."""

SIDE_BINS = 8
"""Direction bins of a wall cell's seen side (``DissimilarityConfig.wall_sides``), centred
on multiples of 45 degrees (where the sides of straight and diagonal walls lie, sums of
whole-cell offsets); cells match when their bins differ by at most one: sides less
than 45 degrees apart always match, more than 90 degrees apart never."""

SIDE_DISTANCE_CAP = 3
"""Cells: the most a wall cell with a side is charged for its distance to the nearest
wall cell seen from that side. A face of a thick wall that the other map saw only from
behind has its nearest match far away; uncapped, such cells make psi jump at every small
move and the random walk stalls."""


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class DistanceMaps:
    """Manhattan distance maps of one grid, with the cells of each class (psi's inputs).

    Attributes
    ----------
    free, occupied : ndarray of int32, shape (rows, cols)
        L1 distance in cells from every cell to the nearest FREE / OCCUPIED cell of the
        grid (0 on cells of that class). A grid with no cell of a class holds ``sentinel``
        everywhere in that class's map.
    free_cells, occupied_cells : ndarray of int64, shape (N, 2)
        ``(iy, ix)`` of the grid's FREE / OCCUPIED cells, row-major order.
    known : ndarray of bool, shape (rows, cols)
        Cells that are FREE or OCCUPIED.
    sentinel : int
        ``rows + cols``: larger than any L1 distance between two cells of the grid.
    occupied_sides : ndarray of float64, shape (N,), or None
        With ``distance_maps(grid, sides=True)``: for each of ``occupied_cells``, the
        direction (rad, in the grid's frame) from the cell towards its FREE 8-neighbours,
        the side of the wall the robot saw; NaN where it has none.
    occupied_by_side : ndarray of int32, shape (SIDE_BINS + 1, rows, cols), or None
        With ``sides=True``: layer k is the L1 distance to the nearest OCCUPIED cell whose
        side lies in direction bin k or a neighbouring one (or has no side); the last
        layer is ``occupied``, for source cells without a side.
    """

    free: NDArray[np.int32]
    occupied: NDArray[np.int32]
    free_cells: NDArray[np.int64]
    occupied_cells: NDArray[np.int64]
    known: NDArray[np.bool_]
    sentinel: int
    occupied_sides: NDArray[np.float64] | None = None
    occupied_by_side: NDArray[np.int32] | None = None
    origin: tuple[float, float] | None = None
    """The grid's origin (set by :func:`distance_maps`): the cell centres below are in its
    frame."""
    resolution: float | None = None
    """The grid's cell size (set by :func:`distance_maps`)."""
    free_centres: NDArray[np.float64] | None = None
    """(2, N) x and y (m) of the centres of ``free_cells``, computed as psi's kernel would."""
    occupied_centres: NDArray[np.float64] | None = None
    """(2, N) x and y (m) of the centres of ``occupied_cells``."""
    free_in_known: NDArray[np.int32] | None = None
    """``free`` where the cell is known, -1 elsewhere (one lookup for the overlap psi)."""
    occupied_in_known: NDArray[np.int32] | None = None
    """``occupied`` where the cell is known, -1 elsewhere."""

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.free.shape[0]), int(self.free.shape[1]))


@dataclass(frozen=True, slots=True, kw_only=True)
class DissimilarityConfig:
    """Which psi to evaluate, and how much of the free space to sample.

    The default is the overlap-restricted psi; see the module docstring for why.
    """

    restrict_to_overlap: bool = True
    """Count only cells whose image lands on a known cell of the other map (True), or
    every cell as in the paper (False)."""
    max_free_cells: int = 20_000
    """At most this many FREE cells per map enter psi: above it, every k-th free cell in
    row-major order is used, ``k = ceil(count / max_free_cells)``. Deterministic. Free
    cells far from walls contribute 0 at any small misalignment, so a regular subsample
    changes psi little and keeps its evaluation well under a millisecond. Occupied cells
    are never subsampled."""
    min_overlap_cells: int = 20
    """With ``restrict_to_overlap``, psi is ``inf`` when fewer than this many (sampled)
    cells of either map land on known cells of the other. Ignored otherwise."""
    wall_sides: bool = False
    """Match an occupied cell only with occupied cells seen from the same side (their free
    neighbours in the same direction, within one of :data:`SIDE_BINS` bins either way).
    A wall two or three cells thick that one robot saw from one side and the other from
    the other side otherwise pulls psi's minimum onto the two faces laid over each other,
    a wall's thickness from the truth. Needs ``distance_maps(grid, sides=True)``."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        for attr in ("restrict_to_overlap", "wall_sides"):
            value = getattr(self, attr)
            require(name, attr, value, isinstance(value, bool), "a bool")
        check_fields(self, counts=("max_free_cells", "min_overlap_cells"))


@dataclass(frozen=True, slots=True, kw_only=True)
class Agreement:
    """Cell-by-cell agreement of two maps under a transform (Birk & Carpin's ai).

    Counted on map 1's lattice: each known cell of m1 is compared with the cell of m2
    under its centre.

    Attributes
    ----------
    agree : int
        Cells known in both maps with the same class (free/free or occupied/occupied).
    disagree : int
        Cells known in both maps with different classes (free/occupied either way).
    conflicts : int
        The disagreements no small misalignment explains: a cell occupied in one map and
        free in the other where the free map has no occupied cell within
        ``tolerance_cells`` (L1) of that place. Walls displaced by a cell or two are not
        conflicts; a wall of one map crossing open floor of the other is.
    overlap : int
        Cells known in both maps, ``agree + disagree``.
    known1, known2 : int
        Known cells of m1 and of m2.
    index : float
        ``agree / (agree + disagree)`` in [0, 1]; 0.0 when nothing overlaps (no evidence
        of agreement).
    overlap_fraction : float
        ``overlap / min(known1, known2)`` in [0, 1]; 0.0 if a map has no known cell.
    conflict_fraction : float
        ``conflicts / overlap``; 0.0 when nothing overlaps.
    """

    agree: int
    disagree: int
    conflicts: int
    overlap: int
    known1: int
    known2: int
    index: float
    overlap_fraction: float
    conflict_fraction: float


def check_transform(map1_from_map2: ArrayLike) -> NDArray[np.float64]:
    """Return ``map1_from_map2`` as a float64 (3,) array, or raise a one-line ValueError
    when it has the wrong shape or a non-finite entry."""
    transform = np.asarray(map1_from_map2, dtype=np.float64)
    if transform.shape != (3,):
        raise ValueError(f"map1_from_map2 must be (x, y, theta), got shape {transform.shape}")
    if not np.all(np.isfinite(transform)):
        raise ValueError(f"map1_from_map2 must be finite, got {transform.tolist()}")
    return transform


def check_same_resolution(m1: GridMap, m2: GridMap) -> float:
    """The shared resolution of two maps; a ValueError if they differ."""
    if not math.isclose(m1.resolution, m2.resolution, rel_tol=RESOLUTION_RTOL):
        raise ValueError(
            f"maps have different resolutions ({m1.resolution} m and {m2.resolution} m); "
            "bring them to one with mrslam_env.merge.fuse.resample_map"
        )
    return m1.resolution


def _check_has_known(grid: GridMap, name: str) -> None:
    if grid.cells.size == 0:
        raise ValueError(f"{name} is empty (shape {grid.shape})")
    if not (grid.free.any() or grid.occupied.any()):
        raise ValueError(f"{name} has no known (free or occupied) cell")


def _l1_distance_to(mask: NDArray[np.bool_], sentinel: int) -> NDArray[np.int32]:
    """L1 distance in cells from every cell to the nearest True cell of ``mask``.

    scipy's chamfer transform with the 4-neighbour ("taxicab") structuring element is the
    two-pass algorithm of the paper's Algorithm 1, exact for the L1 metric on a grid.
    """
    if not mask.any():
        return np.full(mask.shape, sentinel, dtype=np.int32)
    distance = ndimage.distance_transform_cdt(~mask, metric="taxicab")
    return np.ascontiguousarray(distance, dtype=np.int32)


def distance_maps(grid: GridMap, *, sides: bool = False) -> DistanceMaps:
    """Manhattan distance maps of a grid, one per class (paper's Algorithm 1, eq. 13).

    Parameters
    ----------
    grid : GridMap
        A trinary grid with at least one known cell.
    sides : bool, default False
        Also the wall-side distance maps that ``DissimilarityConfig.wall_sides`` needs
        (:data:`SIDE_BINS` more distance transforms).

    Returns
    -------
    DistanceMaps
        ``free`` and ``occupied`` (rows, cols) int32 L1 distances in cells to the nearest
        cell of that class (``sentinel = rows + cols`` where the class is absent), the
        cells of each class and the known mask.

    Raises
    ------
    ValueError
        If the grid is empty or has no known cell.
    """
    _check_has_known(grid, "map")
    rows, cols = grid.shape
    sentinel = rows + cols
    free = grid.free
    occupied = grid.occupied
    occupied_cells = np.argwhere(occupied).astype(np.int64)
    occupied_distance = _l1_distance_to(occupied, sentinel)
    occupied_sides = by_side = None
    if sides:
        occupied_sides = _wall_sides(free, occupied_cells)
        by_side = _distances_by_side(occupied_cells, occupied_sides, grid.shape, sentinel)
        by_side = np.ascontiguousarray(np.concatenate([by_side, occupied_distance[None]]))
    free_distance = _l1_distance_to(free, sentinel)
    free_cells = np.argwhere(free).astype(np.int64)
    known = np.ascontiguousarray(free | occupied)
    origin = (float(grid.origin[0]), float(grid.origin[1]))
    resolution = float(grid.resolution)
    return DistanceMaps(
        free=free_distance,
        occupied=occupied_distance,
        free_cells=free_cells,
        occupied_cells=occupied_cells,
        known=known,
        sentinel=sentinel,
        occupied_sides=occupied_sides,
        occupied_by_side=by_side,
        origin=origin,
        resolution=resolution,
        free_centres=_cell_centres(free_cells, origin, resolution),
        occupied_centres=_cell_centres(occupied_cells, origin, resolution),
        free_in_known=np.where(known, free_distance, np.int32(-1)).astype(np.int32),
        occupied_in_known=np.where(known, occupied_distance, np.int32(-1)).astype(np.int32),
    )


def _cell_centres(
    cells: NDArray[np.int64], origin: tuple[float, float], resolution: float
) -> NDArray[np.float64]:
    """(2, N) x, y of cell centres, the same float operations as :func:`_distance_sum`."""
    centres = np.empty((2, len(cells)))
    centres[0] = origin[0] + (cells[:, 1] + 0.5) * resolution
    centres[1] = origin[1] + (cells[:, 0] + 0.5) * resolution
    return centres


def _wall_sides(free: NDArray[np.bool_], cells: NDArray[np.int64]) -> NDArray[np.float64]:
    """For each cell, the direction (rad) of the sum of the offsets to its FREE
    8-neighbours; NaN for a cell with no free neighbour (or neighbours that cancel)."""
    padded = np.pad(free, 1)
    sum_x = np.zeros(len(cells))
    sum_y = np.zeros(len(cells))
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dx or dy:
                neighbour = padded[cells[:, 0] + 1 + dy, cells[:, 1] + 1 + dx]
                sum_x += dx * neighbour
                sum_y += dy * neighbour
    sides = np.arctan2(sum_y, sum_x)
    sides[(sum_x == 0) & (sum_y == 0)] = np.nan
    return sides


def _side_bins(sides: NDArray[np.float64]) -> NDArray[np.int64]:
    """Direction bin of each side (-1 for NaN)."""
    width = 2 * math.pi / SIDE_BINS
    bins = np.floor(np.nan_to_num(sides) / width + 0.5).astype(np.int64) % SIDE_BINS
    bins[np.isnan(sides)] = -1
    return bins


def _distances_by_side(
    cells: NDArray[np.int64],
    sides: NDArray[np.float64],
    shape: tuple[int, int],
    sentinel: int,
) -> NDArray[np.int32]:
    """(SIDE_BINS, rows, cols): layer k, the L1 distance to the nearest cell whose side
    bin is k or a neighbour of k, or which has no side."""
    bins = _side_bins(sides)
    layers = np.empty((SIDE_BINS, *shape), dtype=np.int32)
    for k in range(SIDE_BINS):
        near = (bins < 0) | ((bins - k) % SIDE_BINS <= 1) | ((k - bins) % SIDE_BINS <= 1)
        mask = np.zeros(shape, dtype=bool)
        mask[cells[near, 0], cells[near, 1]] = True
        layers[k] = _l1_distance_to(mask, sentinel)
    return layers


def _checked_distances(
    grid: GridMap, distances: DistanceMaps | None, name: str, *, sides: bool = False
) -> DistanceMaps:
    if distances is None:
        return distance_maps(grid, sides=sides)
    if distances.shape != grid.shape:
        raise ValueError(
            f"{name} has shape {distances.shape} but its map has shape {grid.shape}; "
            "compute it with distance_maps(map)"
        )
    return distances


@numba.njit(cache=True)
def directed_distance_sum(
    cells: NDArray[np.int64],
    stride: int,
    source_origin_x: float,
    source_origin_y: float,
    cos_theta: float,
    sin_theta: float,
    translation_x: float,
    translation_y: float,
    target_origin_x: float,
    target_origin_y: float,
    resolution: float,
    distance: NDArray[np.int32],
    known: NDArray[np.bool_],
    restrict_to_overlap: bool,
) -> tuple[float, int]:
    """Sum and count of target distance-map values at the images of source cells.

    The numerator and denominator of ``d(source, target, c)`` (paper eq. 12, Algorithm 2).

    Parameters
    ----------
    cells : ndarray of int64, shape (N, 2)
        ``(iy, ix)`` of the source map's class-c cells; every ``stride``-th one is used.
    source_origin_x, source_origin_y, target_origin_x, target_origin_y : float
        Grid origins, metres, each in its own map's frame.
    cos_theta, sin_theta, translation_x, translation_y : float
        ``target_from_source``: ``p_t = R p_s + t``.
    resolution : float
        Shared cell size, metres.
    distance : ndarray of int32, shape (rows, cols)
        The target's class-c distance map.
    known : ndarray of bool, shape (rows, cols)
        The target's known cells.
    restrict_to_overlap : bool
        Skip images outside the target or on its unknown cells. Otherwise images outside
        the target are charged the clamped lookup plus their L1 distance to the grid,
        which is the exact L1 distance to the nearest class-c cell for an outside point.

    Returns
    -------
    (float, int)
        Sum of distances (cells) and number of cells counted.
    """
    rows, cols = distance.shape
    return _distance_sum(
        cells,
        stride,
        np.empty(0),
        0.0,
        source_origin_x,
        source_origin_y,
        cos_theta,
        sin_theta,
        translation_x,
        translation_y,
        target_origin_x,
        target_origin_y,
        resolution,
        np.ascontiguousarray(distance).reshape((1, rows, cols)),
        known,
        restrict_to_overlap,
        0,
    )


@numba.njit(cache=True)
def directed_side_distance_sum(
    cells: NDArray[np.int64],
    sides: NDArray[np.float64],
    source_origin_x: float,
    source_origin_y: float,
    theta: float,
    translation_x: float,
    translation_y: float,
    target_origin_x: float,
    target_origin_y: float,
    resolution: float,
    by_side: NDArray[np.int32],
    known: NDArray[np.bool_],
    restrict_to_overlap: bool,
    cap: int,
) -> tuple[float, int]:
    """:func:`directed_distance_sum` for occupied cells matched by wall side: each cell's
    image reads the target layer of its side turned by ``theta`` (``target_from_source``
    rotation), at most ``cap``; or the last layer (any occupied cell), uncapped, when it
    has no side."""
    return _distance_sum(
        cells,
        1,
        sides,
        theta,
        source_origin_x,
        source_origin_y,
        math.cos(theta),
        math.sin(theta),
        translation_x,
        translation_y,
        target_origin_x,
        target_origin_y,
        resolution,
        by_side,
        known,
        restrict_to_overlap,
        cap,
    )


@numba.njit(cache=True)
def _distance_sum(
    cells: NDArray[np.int64],
    stride: int,
    sides: NDArray[np.float64],
    theta: float,
    source_origin_x: float,
    source_origin_y: float,
    cos_theta: float,
    sin_theta: float,
    translation_x: float,
    translation_y: float,
    target_origin_x: float,
    target_origin_y: float,
    resolution: float,
    layers: NDArray[np.int32],
    known: NDArray[np.bool_],
    restrict_to_overlap: bool,
    cap: int,
) -> tuple[float, int]:
    """The loop of both kernels. ``layers`` (L, rows, cols); a cell reads the last layer,
    or with ``sides`` given and its side known, layer ``bin(side + theta)`` capped."""
    n_bins = layers.shape[0] - 1
    width = 2.0 * math.pi / max(n_bins, 1)
    with_sides = sides.shape[0] > 0
    rows, cols = layers.shape[1], layers.shape[2]
    total = 0.0
    count = 0
    for k in range(0, cells.shape[0], stride):
        layer = n_bins
        if with_sides and not math.isnan(sides[k]):
            layer = math.floor((sides[k] + theta) / width + 0.5) % n_bins
        x = source_origin_x + (cells[k, 1] + 0.5) * resolution
        y = source_origin_y + (cells[k, 0] + 0.5) * resolution
        u = cos_theta * x - sin_theta * y + translation_x
        v = sin_theta * x + cos_theta * y + translation_y
        jx = math.floor((u - target_origin_x) / resolution)
        jy = math.floor((v - target_origin_y) / resolution)
        if restrict_to_overlap:
            if jx < 0 or jx >= cols or jy < 0 or jy >= rows or not known[jy, jx]:
                continue
            value = layers[layer, jy, jx]
        else:
            outside = 0
            if jx < 0:
                outside -= jx
                jx = 0
            elif jx >= cols:
                outside += jx - cols + 1
                jx = cols - 1
            if jy < 0:
                outside -= jy
                jy = 0
            elif jy >= rows:
                outside += jy - rows + 1
                jy = rows - 1
            value = layers[layer, jy, jx] + outside
        if layer != n_bins and value > cap:
            value = cap
        total += value
        count += 1
    return total, count


@numba.njit(cache=True)
def _overlap_distance_sum(
    centres: NDArray[np.float64],
    stride: int,
    cos_theta: float,
    sin_theta: float,
    translation_x: float,
    translation_y: float,
    target_origin_x: float,
    target_origin_y: float,
    resolution: float,
    in_known: NDArray[np.int32],
) -> tuple[float, int]:
    """:func:`directed_distance_sum` with ``restrict_to_overlap`` from precomputed source
    cell centres (``DistanceMaps.free_centres``) and the target's distances on its known
    cells (-1 elsewhere, ``DistanceMaps.free_in_known``): the same float operations, so
    the same cells are counted; the sum of integers is exact in any order."""
    rows, cols = in_known.shape
    flat = in_known.ravel()
    total = 0  # integers: exact in any order, and below 2**53 as a float
    count = 0
    for k in range(0, centres.shape[1], stride):
        x = centres[0, k]
        y = centres[1, k]
        u = cos_theta * x - sin_theta * y + translation_x
        v = sin_theta * x + cos_theta * y + translation_y
        jx = math.floor((u - target_origin_x) / resolution)
        jy = math.floor((v - target_origin_y) / resolution)
        # Branch-free (about twice as fast): an image outside reads cell 0, not counted.
        inside = (jx >= 0) & (jx < cols) & (jy >= 0) & (jy < rows)
        value = flat[jy * cols + jx if inside else 0]
        counted = inside & (value >= 0)
        total += value if counted else 0
        count += 1 if counted else 0
    return float(total), count


def _has_overlap_tables(distances: DistanceMaps, grid: GridMap, resolution: float) -> bool:
    """Whether :func:`_overlap_distance_sum` may use the precomputed tables of
    ``distances`` for ``grid`` (made by :func:`distance_maps` of a grid with this origin
    and cell size)."""
    origin = distances.origin
    return (
        origin is not None
        and distances.resolution == resolution
        and origin[0] == grid.origin[0]
        and origin[1] == grid.origin[1]
        and distances.free_centres is not None
        and distances.occupied_centres is not None
        and distances.free_in_known is not None
        and distances.occupied_in_known is not None
    )


def _side_maps(distances: DistanceMaps) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """``(occupied_sides, occupied_by_side)``, or a ValueError if they were not computed."""
    if distances.occupied_sides is None or distances.occupied_by_side is None:
        raise ValueError("DissimilarityConfig.wall_sides needs distance_maps(grid, sides=True)")
    return distances.occupied_sides, distances.occupied_by_side


def _free_stride(count: int, max_free_cells: int) -> int:
    return max(1, -(-count // max_free_cells))


class _MapTables(NamedTuple):
    """One map's inputs of :func:`_psi` (its :class:`DistanceMaps`; empty where unused)."""

    origin_x: float
    origin_y: float
    stride: int
    free_cells: NDArray[np.int64]
    occupied_cells: NDArray[np.int64]
    free: NDArray[np.int32]
    occupied: NDArray[np.int32]
    known: NDArray[np.bool_]
    free_centres: NDArray[np.float64]
    occupied_centres: NDArray[np.float64]
    free_in_known: NDArray[np.int32]
    occupied_in_known: NDArray[np.int32]
    sides: NDArray[np.float64]
    by_side: NDArray[np.int32]


class _PsiTables(NamedTuple):
    """Both maps' tables and the psi variant: what :func:`_psi` needs to score any
    ``map1_from_map2`` of one pair (made once a pair by :func:`_psi_tables`)."""

    one: _MapTables
    two: _MapTables
    resolution: float
    fast: bool
    """From the overlap tables (:func:`_overlap_distance_sum`)."""
    sides: bool
    restrict: bool
    min_overlap_cells: int


def _map_tables(grid: GridMap, d: DistanceMaps, config: DissimilarityConfig) -> _MapTables:
    empty_centres, empty_table = np.empty((2, 0)), np.empty((0, 0), dtype=np.int32)
    sides, by_side = np.empty(0), np.empty((1, 0, 0), dtype=np.int32)
    if config.wall_sides:
        sides, by_side = _side_maps(d)
    return _MapTables(
        origin_x=float(grid.origin[0]),
        origin_y=float(grid.origin[1]),
        stride=_free_stride(len(d.free_cells), config.max_free_cells),
        free_cells=d.free_cells,
        occupied_cells=d.occupied_cells,
        free=d.free,
        occupied=d.occupied,
        known=d.known,
        free_centres=empty_centres if d.free_centres is None else d.free_centres,
        occupied_centres=empty_centres if d.occupied_centres is None else d.occupied_centres,
        free_in_known=empty_table if d.free_in_known is None else d.free_in_known,
        occupied_in_known=empty_table if d.occupied_in_known is None else d.occupied_in_known,
        sides=sides,
        by_side=by_side,
    )


def _psi_tables(
    m1: GridMap,
    m2: GridMap,
    distances1: DistanceMaps,
    distances2: DistanceMaps,
    config: DissimilarityConfig,
) -> _PsiTables:
    """The inputs of :func:`_psi` for validated maps and their distance maps."""
    resolution = m1.resolution
    fast = (
        config.restrict_to_overlap
        and _has_overlap_tables(distances1, m1, resolution)
        and _has_overlap_tables(distances2, m2, resolution)
    )
    return _PsiTables(
        one=_map_tables(m1, distances1, config),
        two=_map_tables(m2, distances2, config),
        resolution=float(resolution),
        fast=bool(fast),
        sides=config.wall_sides,
        restrict=config.restrict_to_overlap,
        min_overlap_cells=config.min_overlap_cells,
    )


@numba.njit(cache=True)
def _term(
    source: _MapTables,
    target: _MapTables,
    occupied: bool,
    fast: bool,
    cos_theta: float,
    sin_theta: float,
    translation_x: float,
    translation_y: float,
    resolution: float,
    restrict: bool,
) -> tuple[float, int]:
    """One of psi's directed terms: ``source``'s free (or occupied) cells into ``target``."""
    if fast:
        return _overlap_distance_sum(
            source.occupied_centres if occupied else source.free_centres,
            1 if occupied else source.stride,
            cos_theta, sin_theta, translation_x, translation_y,
            target.origin_x, target.origin_y, resolution,
            target.occupied_in_known if occupied else target.free_in_known,
        )  # fmt: skip
    return directed_distance_sum(
        source.occupied_cells if occupied else source.free_cells,
        1 if occupied else source.stride,
        source.origin_x, source.origin_y, cos_theta, sin_theta, translation_x, translation_y,
        target.origin_x, target.origin_y, resolution,
        target.occupied if occupied else target.free, target.known, restrict,
    )  # fmt: skip


@numba.njit(cache=True)
def _side_term(
    source: _MapTables,
    target: _MapTables,
    rotation: float,
    cos_theta: float,
    sin_theta: float,
    translation_x: float,
    translation_y: float,
    resolution: float,
    restrict: bool,
) -> tuple[float, int]:
    """psi's occupied term matched by wall side (a sentinel when ``target`` has no wall)."""
    if target.occupied_cells.shape[0] == 0:
        return directed_distance_sum(
            source.occupied_cells, 1, source.origin_x, source.origin_y, cos_theta, sin_theta,
            translation_x, translation_y, target.origin_x, target.origin_y, resolution,
            target.occupied, target.known, restrict,
        )  # fmt: skip
    return directed_side_distance_sum(
        source.occupied_cells, source.sides, source.origin_x, source.origin_y, rotation,
        translation_x, translation_y, target.origin_x, target.origin_y, resolution,
        target.by_side, target.known, restrict, SIDE_DISTANCE_CAP,
    )  # fmt: skip


@numba.njit(cache=True)
def _psi(x: float, y: float, theta: float, tables: _PsiTables) -> float:
    """psi of ``map1_from_map2 = (x, y, theta)``: the one kernel behind
    :func:`dissimilarity` and the random walk (:mod:`mrslam_env.merge.refine`)."""
    one, two, resolution = tables.one, tables.two, tables.resolution
    fast, restrict = tables.fast, tables.restrict
    c, s = math.cos(theta), math.sin(theta)
    # map2_from_map1 = (R^T, -R^T t)
    inv_x, inv_y = -(c * x + s * y), -(-s * x + c * y)
    psi = 0.0
    count1 = 0
    count2 = 0
    # d(m1, m2, c): m1's cells into m2's frame through map2_from_map1, and back; without
    # wall sides in the order free, occupied of m1, then of m2; with them, the free terms
    # first, then the occupied terms by side.
    for term in range(4):
        direction = term // 2 if not tables.sides else term % 2
        occupied = term % 2 == 1 if not tables.sides else term >= 2
        if tables.sides and occupied:
            if direction == 0:
                total, count = _side_term(
                    one, two, -theta, c, -s, inv_x, inv_y, resolution, restrict
                )
            else:
                total, count = _side_term(two, one, theta, c, s, x, y, resolution, restrict)
        elif direction == 0:
            total, count = _term(
                one, two, occupied, fast, c, -s, inv_x, inv_y, resolution, restrict
            )
        else:
            total, count = _term(two, one, occupied, fast, c, s, x, y, resolution, restrict)
        if direction == 0:
            count1 += count
        else:
            count2 += count
        if count:
            psi += total / count
    if restrict and min(count1, count2) < tables.min_overlap_cells:
        return math.inf
    return psi


def dissimilarity(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: ArrayLike,
    *,
    distances1: DistanceMaps | None = None,
    distances2: DistanceMaps | None = None,
    config: DissimilarityConfig | None = None,
) -> float:
    """Birk & Carpin's dissimilarity psi of m1 and m2 placed by ``map1_from_map2``
    (paper eqs. 11–12, docs/design.md §5 step 6).

    Parameters
    ----------
    m1, m2 : GridMap
        Two maps of one resolution, each with a known cell; each grid's frame is its map
        frame (origins honoured).
    map1_from_map2 : array_like, shape (3,)
        ``(x, y, theta)`` in metres and radians, mapping map 2's frame into map 1's.
    distances1, distances2 : DistanceMaps, optional
        ``distance_maps(m1)`` and ``distance_maps(m2)``; pass them when psi is evaluated
        many times for one pair.
    config : DissimilarityConfig, optional
        The psi variant (overlap-restricted by default) and free-cell subsampling.

    Returns
    -------
    float
        psi >= 0 in cells (sum of four mean L1 distances); ``inf`` for the overlap-restricted
        psi when the maps barely overlap under this transform. A class absent from a map
        contributes 0 for its cells; a class absent from the *other* map charges every
        cell the sentinel distance (the unrestricted psi adds, for a cell whose image falls
        outside the other grid, the L1 distance to that grid, as for any class).

    Raises
    ------
    ValueError
        Different resolutions, an empty or all-unknown map, distance maps of the wrong
        shape, or a non-finite transform.
    """
    transform = check_transform(map1_from_map2)
    check_same_resolution(m1, m2)
    _check_has_known(m1, "map 1")
    _check_has_known(m2, "map 2")
    config = config or DissimilarityConfig()
    d1 = _checked_distances(m1, distances1, "distances1", sides=config.wall_sides)
    d2 = _checked_distances(m2, distances2, "distances2", sides=config.wall_sides)
    x, y, theta = (float(v) for v in transform)
    return _psi(x, y, theta, _psi_tables(m1, m2, d1, d2, config))


def acceptance_index(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: ArrayLike,
    *,
    tolerance_cells: int = 2,
    distances1: DistanceMaps | None = None,
    distances2: DistanceMaps | None = None,
) -> Agreement:
    """Agreement of m1 and m2 under ``map1_from_map2`` (Birk & Carpin's acceptance index).

    Parameters
    ----------
    m1, m2 : GridMap
        Two maps of one resolution, each with a known cell.
    map1_from_map2 : array_like, shape (3,)
        Metres and radians.
    tolerance_cells : int, default 2
        L1 distance in cells within which an occupied cell of one map may sit on free
        space of the other without counting as a conflict (see :class:`Agreement`).
    distances1, distances2 : DistanceMaps, optional
        Precomputed ``distance_maps`` of m1 and m2.

    Returns
    -------
    Agreement
        Counts over m1's known cells whose centre lands on a known cell of m2.

    Raises
    ------
    ValueError
        Different resolutions, empty or all-unknown maps, a non-finite transform, or a
        negative tolerance.
    """
    d1, d2, (_, values1, values2, conflict) = _checked_overlap(
        m1, m2, map1_from_map2, tolerance_cells, distances1, distances2
    )
    overlap = len(values1)
    agree = int(np.count_nonzero(values1 == values2))
    disagree = overlap - agree
    conflicts = int(np.count_nonzero(conflict))
    known1 = int(np.count_nonzero(d1.known))
    known2 = int(np.count_nonzero(d2.known))
    return Agreement(
        agree=agree,
        disagree=disagree,
        conflicts=conflicts,
        overlap=overlap,
        known1=known1,
        known2=known2,
        index=agree / overlap if overlap else 0.0,
        overlap_fraction=overlap / min(known1, known2),
        conflict_fraction=conflicts / overlap if overlap else 0.0,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class WallMatch:
    """How the walls of two maps meet under a transform, counted from each map's walls
    (:func:`wall_match`), so that a wall drawn thicker or doubled in one map costs nothing.

    Attributes
    ----------
    walls1 : int
        m1's OCCUPIED cells that land on a known cell of m2.
    matched1 : int
        Those of ``walls1`` with an OCCUPIED cell of m2 within ``near_cells`` (L1).
    walls2, matched2 : int
        The same for m2's walls against m1.
    """

    walls1: int
    matched1: int
    walls2: int
    matched2: int

    @property
    def missed(self) -> float:
        """The larger of the two maps' shares of walls *not* matched, each counted as
        ``(walls - matched + 1) / (walls + 1)`` (one unmatched wall added, so that a
        placement is never perfect on little evidence: a map with 20 wall cells all
        matched misses 1/21, one with 1,000 misses 1/1001): a placement must explain the
        walls of both maps, not only of the one that saw less."""
        return max(
            (self.walls1 - self.matched1 + 1) / (self.walls1 + 1),
            (self.walls2 - self.matched2 + 1) / (self.walls2 + 1),
        )


def _walls_against(
    source: GridMap,
    target: GridMap,
    target_from_source: NDArray[np.float64],
    target_distances: DistanceMaps,
    near_cells: int,
) -> tuple[int, int]:
    """``source``'s walls on known cells of ``target``: how many, and how many matched
    (see :class:`WallMatch`)."""
    walls = np.argwhere(source.cells == OCCUPIED)
    landed = target.world_to_cell(transform_points(target_from_source, source.cell_to_world(walls)))
    landed = landed[target.contains(landed)]
    landed = landed[target_distances.known[landed[:, 0], landed[:, 1]]]
    to_wall = target_distances.occupied[landed[:, 0], landed[:, 1]]
    return len(landed), int(np.count_nonzero(to_wall <= near_cells))


def wall_match(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: ArrayLike,
    *,
    near_cells: int = 1,
    distances1: DistanceMaps | None = None,
    distances2: DistanceMaps | None = None,
) -> WallMatch:
    """Each map's walls against the other map under ``map1_from_map2`` (:class:`WallMatch`).

    Unlike :func:`acceptance_index`, which compares m1's cells with m2's cell by cell (a
    wall two cells thick in m1 and one in m2 leaves a cell of "disagreement"), this
    counts from the walls, in both directions, with the distance maps: a wall cell is
    matched when the other map has a wall within ``near_cells`` of it.

    Raises
    ------
    ValueError
        Different resolutions, a map without a known cell, a non-finite transform, or a
        negative ``near_cells``.
    """
    transform = check_transform(map1_from_map2)
    check_same_resolution(m1, m2)
    _check_has_known(m1, "map 1")
    _check_has_known(m2, "map 2")
    if not (isinstance(near_cells, int) and near_cells >= 0):
        raise ValueError(f"near_cells must be an int >= 0, got {near_cells!r}")
    d1 = _checked_distances(m1, distances1, "distances1")
    d2 = _checked_distances(m2, distances2, "distances2")
    walls1, matched1 = _walls_against(m1, m2, inverse(transform), d2, near_cells)
    walls2, matched2 = _walls_against(m2, m1, transform, d1, near_cells)
    return WallMatch(walls1=walls1, matched1=matched1, walls2=walls2, matched2=matched2)


def _checked_overlap(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: ArrayLike,
    tolerance_cells: int,
    distances1: DistanceMaps | None,
    distances2: DistanceMaps | None,
) -> tuple[
    DistanceMaps,
    DistanceMaps,
    tuple[NDArray[np.int64], NDArray[np.int8], NDArray[np.int8], NDArray[np.bool_]],
]:
    """Validate the inputs of :func:`acceptance_index` / :func:`largest_conflict`, then
    :func:`_overlap_and_conflicts`; returns the distance maps used, and its result."""
    transform = check_transform(map1_from_map2)
    check_same_resolution(m1, m2)
    _check_has_known(m1, "map 1")
    _check_has_known(m2, "map 2")
    if not (isinstance(tolerance_cells, int) and tolerance_cells >= 0):
        raise ValueError(f"tolerance_cells must be an int >= 0, got {tolerance_cells!r}")
    d1 = _checked_distances(m1, distances1, "distances1")
    d2 = _checked_distances(m2, distances2, "distances2")
    return d1, d2, _overlap_and_conflicts(m1, m2, transform, d1, d2, tolerance_cells)


def _overlap_and_conflicts(
    m1: GridMap,
    m2: GridMap,
    transform: NDArray[np.float64],
    d1: DistanceMaps,
    d2: DistanceMaps,
    tolerance_cells: int,
) -> tuple[NDArray[np.int64], NDArray[np.int8], NDArray[np.int8], NDArray[np.bool_]]:
    """m1's known cells that land on known cells of m2 (``(K, 2)`` ``(iy, ix)``), both
    maps' values there, and which of them are conflicts (see :class:`Agreement`)."""
    cells1 = np.argwhere(d1.known)
    cells2 = m2.world_to_cell(transform_points(inverse(transform), m1.cell_to_world(cells1)))
    inside = m2.contains(cells2)
    cells1, cells2 = cells1[inside], cells2[inside]
    known_in_2 = d2.known[cells2[:, 0], cells2[:, 1]]
    cells1, cells2 = cells1[known_in_2], cells2[known_in_2]
    values1 = m1.cells[cells1[:, 0], cells1[:, 1]]
    values2 = m2.cells[cells2[:, 0], cells2[:, 1]]
    wall1_on_floor2 = (values1 == OCCUPIED) & (values2 == FREE)
    wall2_on_floor1 = (values1 == FREE) & (values2 == OCCUPIED)
    far_from_wall2 = d2.occupied[cells2[:, 0], cells2[:, 1]] > tolerance_cells
    far_from_wall1 = d1.occupied[cells1[:, 0], cells1[:, 1]] > tolerance_cells
    conflict = (wall1_on_floor2 & far_from_wall2) | (wall2_on_floor1 & far_from_wall1)
    return cells1, values1, values2, conflict


def largest_conflict(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: ArrayLike,
    *,
    tolerance_cells: int = 2,
    distances1: DistanceMaps | None = None,
    distances2: DistanceMaps | None = None,
) -> int:
    """Cells in the largest 8-connected group of conflicts (:class:`Agreement`) on m1's
    lattice: the longest stretch of wall of one map lying on open floor of the other.

    Scattered conflict cells come from drift and sensor noise and appear under the true
    transform too; a long unbroken line of them is a wall the other map saw straight
    through, evidence that the placement is wrong (docs/design.md §5 step 6, the judge).

    Parameters
    ----------
    m1, m2 : GridMap
        Two maps of one resolution, each with a known cell.
    map1_from_map2 : array_like, shape (3,)
        Metres and radians.
    tolerance_cells : int, default 2
        As in :func:`acceptance_index`.
    distances1, distances2 : DistanceMaps, optional
        Precomputed ``distance_maps`` of m1 and m2.

    Returns
    -------
    int
        Size in cells of the largest group (0 when there is no conflict).

    Raises
    ------
    ValueError
        As :func:`acceptance_index`.
    """
    _, _, (cells1, _, _, conflict) = _checked_overlap(
        m1, m2, map1_from_map2, tolerance_cells, distances1, distances2
    )
    if not conflict.any():
        return 0
    mask = np.zeros(m1.shape, dtype=bool)
    hits = cells1[conflict]
    mask[hits[:, 0], hits[:, 1]] = True
    labels, count = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    return int(np.bincount(labels.ravel())[1:].max()) if count else 0
