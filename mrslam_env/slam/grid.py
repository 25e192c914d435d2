"""A growing log-odds occupancy grid with exact beam integration (docs/design.md §2, §4).

:class:`OccupancyGrid` lives in a robot's map frame. It starts as one chunk around the
map origin and grows by whole chunks in whichever direction a scan needs; its origin stays
on the lattice of cell corners through the map origin (``origin = index * resolution``), so
a cell never changes its place in the map frame when the grid grows.

**Integration.** A scan updates the log-odds with an inverse sensor model (Thrun et al.,
*Probabilistic Robotics*, §9.2): every cell a beam passes (Amanatides & Woo traversal, as in
:mod:`mrslam_env.slam.raycast`) gets ``log_odds_miss`` once per beam, the cell the beam
ends in gets ``log_odds_hit``; values are clamped to ``[log_odds_min, log_odds_max]``. Three
refinements of the textbook model:

* a cell some beam of the scan ends in is not also cleared by the other beams of the same
  scan (beams grazing a wall would otherwise erase it; Cartographer does the same);
* a cell some beam has ended in since its log-odds were last clamped at ``log_odds_min``
  takes only ``log_odds_miss_held`` in the map (the surface layer below takes
  ``log_odds_miss``) from a returning beam that passes it near its end (``held_reach``
  along the beam, ``surface_margin`` across the surface it ends on): across scans, a wall
  seen along its length at a grazing angle is hit now and then in the cells of its face
  and passed several times as often by the beams ending further along it, and the full
  miss would erase the face (the ratio model of Karto keeps such cells occupied, see
  :class:`~mrslam_env.slam.config.GridConfig`);
* a beam with no return (range == max range) clears at most ``no_return_clear_distance``
  and stops at the first OCCUPIED cell: a dropout in front of a wall is not evidence that
  the wall is gone.

**Likelihood fields.** The grid keeps the scan matcher's fields current. A field is a sum
of integer-valued Gaussian kernels, one per *surface cell*, centred not on the cell centre
but on the cell's mean hit point (rounded to an eighth of a cell, :data:`SUBCELLS`), so
that a wall's ridge lies on its measured surface. The surface cells are those OCCUPIED in
a second log-odds layer that takes the same updates, except that every miss counts in full
(``log_odds_miss``: the matcher's fields stay as they were measured before the map's
weaker miss came in) and the misses *near the surface* a beam ends on are ignored (within
``surface_margin`` of it, see :class:`~mrslam_env.slam.config.GridConfig`): range noise
splits the hits on a wall that lies near a cell edge between two rows of cells, and the
beams ending on the wall clear the front row; without its kernel, the back row's mean hit
point (the noise's far half) would put the ridge millimetres behind the surface, and the
matcher would turn that into heading drift. The map itself (the first layer) still takes
those misses, but in a front row that holds hits only at its weaker rate, so such a row
can stay OCCUPIED and the map's wall a cell thicker than the surface layer's. Summing is
linear: a cell that becomes a surface cell adds its kernel, one that stops being one (or
whose mean point moves) subtracts it again, and the float32 sums stay exact. There are two
kinds:

* the *coarse* field (``coarse_sigma``), one for all cells, for the coarse search;
* the *fine* fields (``fine_sigma``), one per *facing sector*: a hit on a surface whose
  sensor-facing normal (from the scan, :func:`~mrslam_env.slam.scan.scan_normals`) lies
  within 67.5° of the sector's direction (0, 90, 180 or 270° in the map frame) makes its
  cell count in that sector. A scan point is scored in the sector of its own normal, so it
  only sees surfaces facing roughly the same way: the two faces of a thin wall, a cell or
  two apart, would otherwise blur into one ridge in the middle of the wall, and the walls
  of a corner into a blob.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import cell_to_world, world_to_cell
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.slam.config import GridConfig
from mrslam_env.slam.raycast import dda_start
from mrslam_env.slam.scan import scan_normals

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]

__all__ = [
    "HIT_AVERAGE_CAP",
    "KERNEL_SCALE",
    "PROVISIONAL",
    "SECTORS",
    "SUBCELLS",
    "SUBCELL_POINTS",
    "OccupancyGrid",
    "facing_sectors",
    "gaussian_kernels",
    "integrate_scan",
    "mark_newly_known",
    "scan_extent",
    "sector_of",
]

WRITTEN_CAPACITY = 1 << 16
"""Log-odds writes of one scan that :attr:`OccupancyGrid.last_written` lists (a scan of
360 beams writes a few thousand; more and every cell counts as possibly changed)."""

KERNEL_SCALE = 1024.0
"""Peak weight of a likelihood-field kernel; weights are rounded to integers."""

SUBCELLS = 8
"""A cell's mean hit point is rounded to the nearest point of a lattice with SUBCELLS steps
per cell edge, edges included (``(SUBCELLS + 1)**2`` points, ``k / SUBCELLS`` for ``k = 0 ..
SUBCELLS`` along each axis): at most 1/16 cell off, and exact on a cell edge. With points at
the sub-cell centres instead, a wall lying on a cell edge (every wall of a lattice-built
world seen from a lattice start) sits half a step behind its surface for good, and the
matcher turns that bias into heading drift."""

SUBCELL_POINTS = SUBCELLS + 1
"""Lattice points per axis (see :data:`SUBCELLS`)."""

SECTORS = 4
"""View sectors of the fine fields, centred on the directions ``k * 2 pi / SECTORS``."""

PROVISIONAL = 1 << SECTORS
"""Sector-mask flag: the cell's sectors come only from hits without a surface normal.

A return without a normal (:func:`~mrslam_env.slam.scan.scan_normals` gives none where the
neighbouring returns are too far apart, i.e. at grazing incidence) stands in the beam's
reverse direction for the surface's facing, which at grazing incidence is up to 90° off.
So such a hit picks the sectors only of a cell that has none yet, flagged provisional, and
the first hit with a normal replaces them. Otherwise grazing hits would add a wrong sector
to a wall for good, and in that sector the wall's field would blur into the other face of
a thin wall (10 cm behind) or a neighbouring wall: a bias of centimetres across it, which
the scan matcher turns into a steady heading drift."""

SURFACE_ZONE_CELLS = 4
"""Cap, in cells along the beam, on the near-surface zone of ``surface_margin``."""

HIT_AVERAGE_CAP = 1000
"""A cell's mean hit point is the mean of its hits since it last stopped being OCCUPIED,
over at most this many hits (then an exponential average)."""


def gaussian_kernels(sigma: float, resolution: float) -> tuple[Float32Array, float]:
    """The integer-valued blur kernels of a likelihood field and their normalisation.

    Parameters
    ----------
    sigma : float
        Standard deviation of the blur, m.
    resolution : float
        Cell size, m.

    Returns
    -------
    kernels : ndarray, shape (SUBCELL_POINTS**2, 2k+1, 2k+1), float32
        Kernel ``q = sy * SUBCELL_POINTS + sx`` is centred on the point ``(sx / SUBCELLS,
        sy / SUBCELLS)`` of its cell (cell units from the cell's corner) and holds
        ``round(KERNEL_SCALE * exp(-d^2 / (2 sigma^2)))``, ``d`` (m) from that point to the
        centres of the cells up to ``k = ceil(2 sigma / resolution + 0.5)`` cells away; index
        ``[q, k + dy, k + dx]``.
    line_sum : float
        The field value on a straight wall, ``KERNEL_SCALE * sqrt(2 pi) * sigma /
        resolution``: dividing a field by it makes a wall score about 1.
    """
    radius = max(1, math.ceil(2.0 * sigma / resolution + 0.5))
    offsets = np.arange(-radius, radius + 1, dtype=np.float64)
    sub = np.arange(SUBCELL_POINTS) / SUBCELLS - 0.5  # lattice point minus cell centre
    size = 2 * radius + 1
    kernels = np.empty((SUBCELL_POINTS * SUBCELL_POINTS, size, size), np.float32)
    for sy in range(SUBCELL_POINTS):
        for sx in range(SUBCELL_POINTS):
            dy = (offsets - sub[sy])[:, None] * resolution
            dx = (offsets - sub[sx])[None, :] * resolution
            weights = KERNEL_SCALE * np.exp(-(dx**2 + dy**2) / (2.0 * sigma**2))
            kernels[sy * SUBCELL_POINTS + sx] = np.round(weights)
    line_sum = KERNEL_SCALE * math.sqrt(2.0 * math.pi) * sigma / resolution
    return kernels, line_sum


@numba.njit(cache=True)
def sector_of(direction: float) -> int:
    """The view sector (0 .. SECTORS-1) whose centre is nearest to a direction (rad)."""
    width = 2.0 * math.pi / SECTORS
    return math.floor(direction / width + 0.5) % SECTORS


@numba.njit(cache=True)
def facing_sectors(direction: float) -> int:
    """Bit mask of the view sectors a hit on a surface facing ``direction`` (rad) counts
    in: those whose centre lies within 67.5° (1.5 half-widths) of it, one or two."""
    width = 2.0 * math.pi / SECTORS
    position = direction / width
    nearest = math.floor(position + 0.5)
    offset = position - nearest  # in [-0.5, 0.5)
    mask = 1 << (int(nearest) % SECTORS)
    if offset > 0.25:
        mask |= 1 << (int(nearest + 1) % SECTORS)
    elif offset < -0.25:
        mask |= 1 << (int(nearest - 1) % SECTORS)
    return mask


@numba.njit(cache=True)
def _stamp(field: Float32Array, kernel: Float32Array, iy: int, ix: int, sign: float) -> None:
    """Add ``sign * kernel`` (2-D, odd square) centred on cell (iy, ix), clipped to the
    field."""
    rows, cols = field.shape
    radius = kernel.shape[0] // 2
    for ky in range(kernel.shape[0]):
        y = iy + ky - radius
        if y < 0 or y >= rows:
            continue
        for kx in range(kernel.shape[1]):
            x = ix + kx - radius
            if 0 <= x < cols:
                field[y, x] += sign * kernel[ky, kx]


@numba.njit(cache=True)
def _restamp(
    fine_fields: Float32Array,
    coarse_field: Float32Array,
    fine_kernels: Float32Array,
    coarse_kernels: Float32Array,
    stamp_index: NDArray[np.int8],
    sector_mask: NDArray[np.uint8],
    iy: int,
    ix: int,
    new_index: int,
    new_mask: int,
) -> None:
    """Change cell (iy, ix)'s share of the fields to sub-cell kernel ``new_index`` in the
    sectors of ``new_mask`` (``new_index = -1``: no share at all).

    Kept out of line: it runs rarely, and inlining it into the traversal loop slows that
    loop tenfold.
    """
    old_index = int(stamp_index[iy, ix])
    old_mask = int(sector_mask[iy, ix]) if old_index >= 0 else 0
    if new_index < 0:
        new_mask = 0
    moved = new_index != old_index
    if moved:
        if old_index >= 0:
            _stamp(coarse_field, coarse_kernels[old_index], iy, ix, -1.0)
        if new_index >= 0:
            _stamp(coarse_field, coarse_kernels[new_index], iy, ix, 1.0)
    for k in range(SECTORS):
        bit = 1 << k
        had = (old_mask & bit) != 0
        has = (new_mask & bit) != 0
        if had and (moved or not has):
            _stamp(fine_fields[k], fine_kernels[old_index], iy, ix, -1.0)
        if has and (moved or not had):
            _stamp(fine_fields[k], fine_kernels[new_index], iy, ix, 1.0)
    stamp_index[iy, ix] = new_index
    sector_mask[iy, ix] = new_mask


@numba.njit(cache=True)
def _is_known(
    value: float | np.floating[Any], free_threshold: float, occupied_threshold: float
) -> int:
    # Compare in float32, as numpy does for the float32 grid against a Python float
    # (to_gridmap): a threshold such as -0.3 is not exact in float32.
    if value < np.float32(free_threshold) or value > np.float32(occupied_threshold):
        return 1
    return 0


@numba.njit(cache=True)
def scan_extent(
    x: float,
    y: float,
    heading: float,
    ranges: FloatArray,
    max_range: float,
    min_range: float,
    no_return_clear_distance: float,
) -> tuple[float, float, float, float]:
    """Bounding box ``(xmin, ymin, xmax, ymax)`` (m) of the sensor and every point a scan
    integrated at pose (x, y, heading) will touch."""
    n = ranges.shape[0]
    dtheta = 2.0 * math.pi / n
    xmin, xmax, ymin, ymax = x, x, y, y
    for i in range(n):
        r = ranges[i]
        if not r >= min_range:  # also skips NaN
            continue
        if r >= max_range:
            r = no_return_clear_distance
        a = heading - math.pi + i * dtheta
        ex, ey = x + r * math.cos(a), y + r * math.sin(a)
        xmin, xmax = min(xmin, ex), max(xmax, ex)
        ymin, ymax = min(ymin, ey), max(ymax, ey)
    return xmin, ymin, xmax, ymax


@numba.njit(cache=True)
def integrate_scan(
    log_odds: Float32Array,
    surface_odds: Float32Array,
    hit_marks: NDArray[np.int32],
    hit_mean: Float32Array,
    hit_count: NDArray[np.int32],
    hit_held: NDArray[np.bool_],
    stamp_index: NDArray[np.int8],
    sector_mask: NDArray[np.uint8],
    fine_fields: Float32Array,
    coarse_field: Float32Array,
    fine_kernels: Float32Array,
    coarse_kernels: Float32Array,
    scan_id: int,
    origin_x: float,
    origin_y: float,
    resolution: float,
    x: float,
    y: float,
    heading: float,
    ranges: FloatArray,
    normals: FloatArray,
    max_range: float,
    min_range: float,
    no_return_clear_distance: float,
    log_odds_hit: float,
    log_odds_miss: float,
    log_odds_miss_held: float,
    log_odds_min: float,
    log_odds_max: float,
    occupied_threshold: float,
    free_threshold: float,
    surface_margin: float,
    held_reach: float,
    written: NDArray[np.int64],
) -> tuple[int, int, int]:
    """Integrate one scan into a log-odds grid and its likelihood fields (in place).

    Parameters
    ----------
    log_odds : ndarray, shape (rows, cols), float32
        The grid.
    surface_odds : ndarray, shape (rows, cols), float32
        The surface layer: log-odds updated like ``log_odds``, except that it takes
        ``log_odds_miss`` in every cell and no miss near the surface a beam ends on
        (``surface_margin``); the cells where it exceeds
        ``occupied_threshold`` are the surface cells, which carry the kernels.
    hit_marks : ndarray, shape (rows, cols), int32
        Scratch: cells ending a beam of this scan are set to ``scan_id``, which must differ
        from every value already in it (the caller counts scans up from 1).
    hit_mean : ndarray, shape (rows, cols, 2), float32
        Per cell, the running mean ``(x, y)`` of the hit points inside it, in cell units
        from the cell's corner (in [0, 1)).
    hit_count : ndarray, shape (rows, cols), int32
        Hits in that mean (capped at ``HIT_AVERAGE_CAP``); reset to 0 when the cell stops
        being a surface cell, so that the mean starts afresh.
    hit_held : ndarray, shape (rows, cols), bool
        Per cell, whether a beam has ended in it since its log-odds were last at
        ``log_odds_min``: such a cell takes ``log_odds_miss_held`` in ``log_odds`` instead
        of ``log_odds_miss`` (the surface layer always takes ``log_odds_miss``).
    stamp_index : ndarray, shape (rows, cols), int8
        The sub-cell kernel each cell adds to the fields, -1 for none: >= 0 exactly for the
        surface cells (``surface_odds`` above ``occupied_threshold``).
    sector_mask : ndarray, shape (rows, cols), uint8
        The fine fields (bit k: sector k) a surface cell adds its kernel to, plus the
        :data:`PROVISIONAL` flag.
    fine_fields : ndarray, shape (SECTORS, rows, cols), float32
    coarse_field : ndarray, shape (rows, cols), float32
        The likelihood fields: sums of the stamped kernels.
    fine_kernels, coarse_kernels : ndarray, shape (SUBCELL_POINTS**2, K, K), float32
        From :func:`gaussian_kernels`.
    scan_id : int
    origin_x, origin_y, resolution : float
        Grid placement (docs/design.md §2), m.
    x, y, heading : float
        Sensor pose in the grid's frame, m, m, rad.
    ranges : ndarray, shape (N,), float64
        Beam i at ``heading - pi + i 2 pi / N``; ``>= max_range`` means no return; below
        ``min_range`` (or NaN) the beam is skipped.
    normals : ndarray, shape (N, 2), float64
        Sensor-facing surface normal of each return in the sensor frame
        (:func:`~mrslam_env.slam.scan.scan_normals`), ``(0, 0)`` where unknown: it picks
        the view sectors the hit counts in (the beam's reverse direction stands in for a
        missing normal, provisionally: see :data:`PROVISIONAL`).
    max_range, min_range, no_return_clear_distance : float
        m.
    log_odds_hit, log_odds_miss, log_odds_min, log_odds_max : float
    log_odds_miss_held : float
        The map's miss in a cell that holds a hit (see ``hit_held``).
    occupied_threshold, free_threshold : float
        The update and the trinary thresholds (see
        :class:`~mrslam_env.slam.config.GridConfig`).
    surface_margin : float
        m: misses of a returning beam within this distance of the surface it ends on
        (across the surface, from the return's normal; along the beam at most
        ``SURFACE_ZONE_CELLS`` cells) leave ``surface_odds`` alone in cells that hold hits.
    held_reach : float
        m: a returning beam's misses within ``surface_margin`` of the surface it ends on
        (across it, from the return's normal; along the beam at most this far) take
        ``log_odds_miss_held`` in ``log_odds`` in the cells ``hit_held`` marks.
    written : ndarray, shape (W,), int64
        Out: the flat indices (``row * cols + col``) of the cells whose log-odds were
        written, in order, repeats included; only the first W are stored.

    Returns
    -------
    flips : int
        How many cells turned OCCUPIED or stopped being OCCUPIED.
    newly_known : int
        The net change in the number of known cells (FREE or OCCUPIED in the trinary
        view): cells that became known minus cells that went back to UNKNOWN.
    n_written : int
        How many log-odds writes there were (all of them listed in ``written`` when at
        most W).
    """
    rows, cols = log_odds.shape
    n = ranges.shape[0]
    dtheta = 2.0 * math.pi / n
    flips = 0
    newly_known = 0
    n_written = 0
    capacity = written.shape[0]
    # Pass 1: mark the end cell of every returning beam.
    for i in range(n):
        r = ranges[i]
        if not (min_range <= r < max_range):
            continue
        a = heading - math.pi + i * dtheta
        ix = math.floor((x + r * math.cos(a) - origin_x) / resolution)
        iy = math.floor((y + r * math.sin(a) - origin_y) / resolution)
        if 0 <= iy < rows and 0 <= ix < cols:
            hit_marks[iy, ix] = scan_id
    # Pass 2: misses along every beam (Amanatides & Woo), skipping this scan's hit cells.
    for i in range(n):
        r = ranges[i]
        if not r >= min_range:
            continue
        returned = r < max_range
        if not returned:
            r = no_return_clear_distance
            if r <= 0.0:
                continue
        a = heading - math.pi + i * dtheta
        # Where the beam comes within surface_margin of the surface it ends on (as a
        # fraction of the beam): its misses there leave the surface layer alone.
        # Likewise, up to held_reach along it, where the map's miss in a cell that holds
        # hits is the weaker log_odds_miss_held. A return without a normal is a grazing
        # one (its neighbours are too far apart along the surface): the whole reach.
        zone_start = 2.0
        held_start = 2.0
        if returned and surface_margin > 0.0:
            incidence = abs(normals[i, 0] * math.cos(i * dtheta - math.pi) +
                            normals[i, 1] * math.sin(i * dtheta - math.pi))  # fmt: skip
            along = SURFACE_ZONE_CELLS * resolution
            if incidence * along > surface_margin:
                along = surface_margin / incidence
            zone_start = 1.0 - along / r
            along = held_reach
            if incidence * along > surface_margin:
                along = surface_margin / incidence
            held_start = 1.0 - along / r
        # The same set-up as raycast.traverse, so both visit the very same cells.
        ix, iy, step_x, step_y, t_max_x, t_max_y, t_delta_x, t_delta_y, n_steps = dda_start(
            x, y, x + r * math.cos(a), y + r * math.sin(a), origin_x, origin_y, resolution
        )
        t_entry = 0.0
        for k in range(n_steps + 1):
            if k > 0:
                if t_max_x < t_max_y:
                    ix += step_x
                    t_entry = t_max_x
                    t_max_x += t_delta_x
                else:
                    iy += step_y
                    t_entry = t_max_y
                    t_max_y += t_delta_y
            if not (0 <= iy < rows and 0 <= ix < cols):
                continue
            before = log_odds[iy, ix]
            surface_before = surface_odds[iy, ix]
            # Both layers clamped: a miss changes nothing (most cells a beam crosses are
            # known free), so skip them before touching ``hit_marks``.
            cleared = surface_before <= log_odds_min and before <= log_odds_min
            near_surface = False
            if returned:
                if cleared or hit_marks[iy, ix] == scan_id:
                    continue
                near_surface = t_entry >= zone_start and hit_count[iy, ix] > 0
            elif hit_marks[iy, ix] == scan_id or before > occupied_threshold:
                break
            elif cleared:
                continue
            miss = log_odds_miss
            if hit_held[iy, ix] and t_entry >= held_start:
                miss = log_odds_miss_held
            after = np.float32(max(before + miss, log_odds_min))
            if after <= log_odds_min:
                hit_held[iy, ix] = False
            log_odds[iy, ix] = after
            if n_written < capacity:
                written[n_written] = iy * cols + ix
            n_written += 1
            newly_known += _is_known(after, free_threshold, occupied_threshold) - _is_known(
                before, free_threshold, occupied_threshold
            )
            if near_surface:
                continue  # the map clears the cell, the surface layer keeps it
            surface_after = np.float32(max(surface_before + log_odds_miss, log_odds_min))
            surface_odds[iy, ix] = surface_after
            if surface_before > occupied_threshold >= surface_after:
                _restamp(
                    fine_fields, coarse_field, fine_kernels, coarse_kernels, stamp_index,
                    sector_mask, iy, ix, -1, 0,
                )  # fmt: skip
                hit_count[iy, ix] = 0
                flips += 1
    # Pass 3: one hit per returning beam at its end cell; the cell's mean hit point decides
    # where its kernel sits, the surface's facing which fine fields it counts in.
    for i in range(n):
        r = ranges[i]
        if not (min_range <= r < max_range):
            continue
        a = heading - math.pi + i * dtheta
        gx = (x + r * math.cos(a) - origin_x) / resolution
        gy = (y + r * math.sin(a) - origin_y) / resolution
        ix, iy = math.floor(gx), math.floor(gy)
        if not (0 <= iy < rows and 0 <= ix < cols):
            continue
        count = min(hit_count[iy, ix] + 1, HIT_AVERAGE_CAP)
        hit_count[iy, ix] = count
        mean_x = hit_mean[iy, ix, 0] + (gx - ix - hit_mean[iy, ix, 0]) / count
        mean_y = hit_mean[iy, ix, 1] + (gy - iy - hit_mean[iy, ix, 1]) / count
        hit_mean[iy, ix, 0] = mean_x
        hit_mean[iy, ix, 1] = mean_y
        hit_held[iy, ix] = True
        # Round to float32 before comparing: the stored value decides the cell's state.
        before = log_odds[iy, ix]
        after = np.float32(min(max(before + log_odds_hit, log_odds_min), log_odds_max))
        log_odds[iy, ix] = after
        if n_written < capacity:
            written[n_written] = iy * cols + ix
        n_written += 1
        newly_known += _is_known(after, free_threshold, occupied_threshold) - _is_known(
            before, free_threshold, occupied_threshold
        )
        surface_after = np.float32(
            min(max(surface_odds[iy, ix] + log_odds_hit, log_odds_min), log_odds_max)
        )
        surface_odds[iy, ix] = surface_after
        if surface_after > occupied_threshold:
            sub_x = min(max(round(mean_x * SUBCELLS), 0), SUBCELLS)
            sub_y = min(max(round(mean_y * SUBCELLS), 0), SUBCELLS)
            new_index = sub_y * SUBCELL_POINTS + sub_x
            old_index = stamp_index[iy, ix]
            old_mask = int(sector_mask[iy, ix]) if old_index >= 0 else 0
            if normals[i, 0] != 0.0 or normals[i, 1] != 0.0:
                mask = facing_sectors(heading + math.atan2(normals[i, 1], normals[i, 0]))
                if not old_mask & PROVISIONAL:
                    mask |= old_mask
            elif old_mask:
                mask = old_mask
            else:
                mask = facing_sectors(a + math.pi) | PROVISIONAL
            if new_index != old_index or mask != sector_mask[iy, ix]:
                if old_index < 0:
                    flips += 1
                _restamp(
                    fine_fields, coarse_field, fine_kernels, coarse_kernels, stamp_index,
                    sector_mask, iy, ix, new_index, mask,
                )  # fmt: skip
    return flips, newly_known, n_written


class OccupancyGrid:
    """A log-odds occupancy grid that grows as the robot explores.

    Coordinates are in the grid's own frame (for onboard SLAM: the robot's map frame).
    Cell conventions are those of docs/design.md §2 (``[iy, ix]``, row 0 at the lowest y,
    ``origin`` the corner of cell [0, 0]).

    Parameters
    ----------
    config : GridConfig, optional
        Resolution, log-odds update, likelihood-field widths, growth chunk.
    fields : bool
        Keep the likelihood fields (:attr:`fine_fields`, :attr:`coarse_field`) current;
        False leaves them zero (a map nothing is matched against), which saves about a third
        of :meth:`integrate_scan`'s time. Everything else is the same either way.
    around : (float, float)
        Frame point ``(x, y)`` the first chunk is centred on (to the nearest cell corner):
        a grid for scans far from the frame's origin then does not grow to cover it. The
        cells are those of any grid of the frame at the same resolution.
    """

    def __init__(
        self,
        config: GridConfig | None = None,
        *,
        fields: bool = True,
        around: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        self.config = config if config is not None else GridConfig()
        self.resolution = self.config.resolution
        self.fine_kernels, fine_sum = gaussian_kernels(self.config.fine_sigma, self.resolution)
        self.coarse_kernels, coarse_sum = gaussian_kernels(
            self.config.coarse_sigma, self.resolution
        )
        # Empty kernels stamp nothing: the fields stay zero.
        self._stamped = (
            (self.fine_kernels, self.coarse_kernels)
            if fields
            else (
                np.zeros((len(self.fine_kernels), 0, 0), dtype=np.float32),
                np.zeros((len(self.coarse_kernels), 0, 0), dtype=np.float32),
            )
        )
        self.fine_scale = 1.0 / fine_sum
        """Multiply a fine field by this to get a likelihood of about 1 on a wall."""
        self.coarse_scale = 1.0 / coarse_sum
        """Multiply the coarse field by this to get a likelihood of about 1 on a wall."""
        radius = max(self.fine_kernels.shape[1], self.coarse_kernels.shape[1]) // 2
        self._margin = radius + 2
        self._scan_id = 0
        self.known_cells = 0
        """Cells FREE or OCCUPIED in the trinary view (:meth:`to_gridmap`), kept current
        by :meth:`integrate_scan`; times ``resolution**2``, the mapped area."""
        chunk = self.config.growth_chunk
        # Cell index (iy, ix) of the origin on the lattice through the frame's (0, 0).
        self._origin_index = (
            round(around[1] / self.resolution) - chunk // 2,
            round(around[0] / self.resolution) - chunk // 2,
        )
        shape = (chunk, chunk)
        self._log_odds = np.zeros(shape, dtype=np.float32)
        self._surface_odds = np.zeros(shape, dtype=np.float32)
        self._hit_marks = np.zeros(shape, dtype=np.int32)
        self._hit_mean = np.zeros((*shape, 2), dtype=np.float32)
        self._hit_count = np.zeros(shape, dtype=np.int32)
        self._hit_held = np.zeros(shape, dtype=np.bool_)
        self._stamp_index = np.full(shape, -1, dtype=np.int8)
        self._sector_mask = np.zeros(shape, dtype=np.uint8)
        self._fine_fields = np.zeros((SECTORS, *shape), dtype=np.float32)
        self._coarse_field = np.zeros((1, *shape), dtype=np.float32)
        # The cells the last scan wrote (flat indices), and the trinary view kept current
        # from them once :meth:`to_gridmap` has built it (None before).
        self._written = np.empty(WRITTEN_CAPACITY, dtype=np.int64)
        self._n_written = 0
        self._cells: NDArray[np.int8] | None = None

    # --- placement ----------------------------------------------------------------------

    @property
    def origin(self) -> tuple[float, float]:
        """Frame ``(x, y)`` of the outer corner of cell [0, 0], m (always a whole number of
        cells from the frame's origin)."""
        return (self._origin_index[1] * self.resolution, self._origin_index[0] * self.resolution)

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)``."""
        return (int(self._log_odds.shape[0]), int(self._log_odds.shape[1]))

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """Frame bounds ``(xmin, ymin, xmax, ymax)``, m."""
        x0, y0 = self.origin
        rows, cols = self.shape
        return (x0, y0, x0 + cols * self.resolution, y0 + rows * self.resolution)

    def world_to_cell(self, points: ArrayLike) -> NDArray[np.int64]:
        """Cell indices ``(iy, ix)`` (..., 2) of frame points ``(x, y)`` (..., 2), not
        clipped."""
        return world_to_cell(points, self.origin, self.resolution)

    def cell_to_world(self, cells: ArrayLike) -> FloatArray:
        """Frame coordinates ``(x, y)`` (..., 2) of the centres of cells ``(iy, ix)``."""
        return cell_to_world(cells, self.origin, self.resolution)

    # --- contents -----------------------------------------------------------------------

    @staticmethod
    def _read_only(array: NDArray[Any]) -> NDArray[Any]:
        view = array.view()
        view.flags.writeable = False
        return view

    @property
    def log_odds(self) -> Float32Array:
        """Log-odds (rows, cols), float32, read-only view (positive = occupied)."""
        return self._read_only(self._log_odds)

    @property
    def fine_fields(self) -> Float32Array:
        """Fine likelihood fields (SECTORS, rows, cols), float32, read-only: per view
        sector, the sum over the surface cells hit from that sector of a Gaussian
        (``fine_sigma``) centred on the cell's mean hit point, sampled at cell centres;
        times :attr:`fine_scale` about 1 on a wall."""
        return self._read_only(self._fine_fields)

    @property
    def coarse_field(self) -> Float32Array:
        """Coarse likelihood field (1, rows, cols), float32, read-only: as a fine field
        with ``coarse_sigma`` over every surface cell; times :attr:`coarse_scale` about 1
        on a wall."""
        return self._read_only(self._coarse_field)

    @property
    def stamp_index(self) -> NDArray[np.int8]:
        """Per cell, the kernel (``sy * SUBCELL_POINTS + sx``) it adds to the fields, -1
        for cells that are not surface cells (see the module notes); read-only."""
        return self._read_only(self._stamp_index)

    @property
    def sector_mask(self) -> NDArray[np.uint8]:
        """Per surface cell (see the module notes), the fine fields it counts in (bit k:
        sector k), and the :data:`PROVISIONAL` flag (bit ``SECTORS``); read-only."""
        return self._read_only(self._sector_mask)

    def probability(self) -> FloatArray:
        """Occupancy probability per cell (rows, cols), 0.5 where nothing is known."""
        return 1.0 / (1.0 + np.exp(-self._log_odds.astype(np.float64)))

    def occupied(self) -> NDArray[np.bool_]:
        """Cells whose log-odds exceed ``occupied_threshold`` (rows, cols)."""
        return self._log_odds > self.config.occupied_threshold

    @property
    def last_written(self) -> NDArray[np.int64] | None:
        """Flat indices (``row * cols + col``, repeats included) of the cells whose
        log-odds the last :meth:`integrate_scan` wrote: the only cells whose trinary
        value can have changed since the call before. None when there were too many to
        list (then any cell may have changed), empty before the first scan."""
        if self._n_written > len(self._written):
            return None
        return self._read_only(self._written[: self._n_written])

    def copy(self, *, fields: bool) -> OccupancyGrid:
        """An independent copy; ``fields=False`` gives a grid that keeps no likelihood
        fields from now on (as one built with ``fields=False``: its fields are zero)."""
        new = OccupancyGrid.__new__(OccupancyGrid)
        for name, value in vars(self).items():
            setattr(new, name, value.copy() if isinstance(value, np.ndarray) else value)
        if not fields:
            new._stamped = (
                np.zeros((len(self.fine_kernels), 0, 0), dtype=np.float32),
                np.zeros((len(self.coarse_kernels), 0, 0), dtype=np.float32),
            )
            new._fine_fields = np.zeros_like(self._fine_fields)
            new._coarse_field = np.zeros_like(self._coarse_field)
        return new

    def forget_written(self) -> None:
        """Make :attr:`last_written` None (any cell may have changed) until the next
        :meth:`integrate_scan`: for a grid rebuilt from its scans."""
        self._n_written = len(self._written) + 1

    def to_gridmap(self) -> GridMap:
        """The trinary view: OCCUPIED above ``occupied_threshold``, FREE below
        ``free_threshold``, else UNKNOWN, placed in the grid's frame (a copy)."""
        # A teammate reads its map every step: the view is built once (one pass) and
        # then kept current from the cells each scan writes, so a read is a copy. The
        # cells hold the three values by construction: GridMap's value check is skipped.
        if self._cells is None:
            self._cells = self._trinary_of(self._log_odds)
        return GridMap.trusted(self._cells.copy(), self.resolution, self.origin)

    def _trinary_of(self, log_odds: Float32Array) -> NDArray[np.int8]:
        # The thresholds go in as float32, as numpy compares the float32 log-odds with them.
        config = self.config
        return _trinary(
            log_odds, np.float32(config.free_threshold), np.float32(config.occupied_threshold)
        )

    # --- growth -------------------------------------------------------------------------

    def ensure_contains(self, xmin: float, ymin: float, xmax: float, ymax: float) -> bool:
        """Grow (by whole chunks per side) until the box plus a margin of cells lies inside.

        The margin covers the likelihood kernels, so stamps are never clipped and the fields
        stay exact through growth. Returns True if the grid grew.
        """
        res = self.resolution
        x0, y0 = self.origin
        rows, cols = self.shape
        m = self._margin
        lo_x = math.floor((xmin - x0) / res) - m
        lo_y = math.floor((ymin - y0) / res) - m
        hi_x = math.floor((xmax - x0) / res) + m
        hi_y = math.floor((ymax - y0) / res) + m
        if lo_x >= 0 and lo_y >= 0 and hi_x < cols and hi_y < rows:
            return False
        chunk = self.config.growth_chunk
        add_left = chunk * math.ceil(-lo_x / chunk) if lo_x < 0 else 0
        add_bottom = chunk * math.ceil(-lo_y / chunk) if lo_y < 0 else 0
        add_right = chunk * math.ceil((hi_x - cols + 1) / chunk) if hi_x >= cols else 0
        add_top = chunk * math.ceil((hi_y - rows + 1) / chunk) if hi_y >= rows else 0
        new_rows = rows + add_bottom + add_top
        new_cols = cols + add_left + add_right
        rows_window = slice(add_bottom, add_bottom + rows)
        cols_window = slice(add_left, add_left + cols)

        def grown(old: NDArray[Any], fill: float = 0, leading: int = 0) -> NDArray[Any]:
            """``old`` placed in a larger array; axes ``leading`` and ``leading + 1`` are
            rows and columns."""
            shape = (*old.shape[:leading], new_rows, new_cols, *old.shape[leading + 2 :])
            new = np.full(shape, fill, dtype=old.dtype)
            new[(slice(None),) * leading + (rows_window, cols_window)] = old
            return new

        self._log_odds = grown(self._log_odds)
        self._surface_odds = grown(self._surface_odds)
        self._hit_marks = grown(self._hit_marks)
        self._hit_mean = grown(self._hit_mean)
        self._hit_count = grown(self._hit_count)
        self._hit_held = grown(self._hit_held)
        self._stamp_index = grown(self._stamp_index, -1)
        self._sector_mask = grown(self._sector_mask)
        self._fine_fields = grown(self._fine_fields, leading=1)
        self._coarse_field = grown(self._coarse_field, leading=1)
        if self._cells is not None:
            self._cells = grown(self._cells, -1)  # UNKNOWN
        self._origin_index = (
            self._origin_index[0] - add_bottom,
            self._origin_index[1] - add_left,
        )
        return True

    # --- integration --------------------------------------------------------------------

    def integrate_scan(
        self,
        pose: ArrayLike,
        ranges: ArrayLike,
        max_range: float,
        normals: FloatArray | None = None,
    ) -> int:
        """Integrate one scan taken at ``pose`` (x, y, theta in the grid's frame).

        Parameters
        ----------
        pose : array_like, shape (3,)
            Sensor pose, m, m, rad.
        ranges : array_like, shape (N,)
            Beam i at ``theta - pi + i 2 pi / N`` (as
            :func:`mrslam_env.sim.lidar.beam_angles`); ``>= max_range`` means no return.
        max_range : float
            The lidar's maximum range, m.
        normals : ndarray, shape (N, 2), optional
            The scan's normals (:func:`~mrslam_env.slam.scan.scan_normals`), if already
            known.

        Returns
        -------
        int
            How many cells turned OCCUPIED or stopped being OCCUPIED.
        """
        x, y, heading = (float(v) for v in np.asarray(pose, dtype=np.float64))
        scan = np.asarray(ranges, dtype=np.float64)
        if scan.ndim != 1 or len(scan) == 0:
            raise ValueError(f"ranges must have shape (N,) with N > 0, got {scan.shape}")
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(heading)):
            raise ValueError(f"pose must be finite, got {(x, y, heading)}")
        config = self.config
        clear = min(config.no_return_clear_distance, max_range)
        self.ensure_contains(*scan_extent(x, y, heading, scan, max_range, config.min_range, clear))
        self._scan_id += 1
        x0, y0 = self.origin
        flips, newly_known, self._n_written = integrate_scan(
            self._log_odds,
            self._surface_odds,
            self._hit_marks,
            self._hit_mean,
            self._hit_count,
            self._hit_held,
            self._stamp_index,
            self._sector_mask,
            self._fine_fields,
            self._coarse_field[0],
            *self._stamped,
            self._scan_id,
            x0,
            y0,
            self.resolution,
            x,
            y,
            heading,
            scan,
            scan_normals(scan, max_range, config.min_range) if normals is None else normals,
            float(max_range),
            config.min_range,
            clear,
            config.log_odds_hit,
            config.log_odds_miss,
            config.log_odds_miss
            if config.log_odds_miss_held is None
            else config.log_odds_miss_held,
            config.log_odds_min,
            config.log_odds_max,
            config.occupied_threshold,
            config.free_threshold,
            config.surface_margin,
            config.held_reach,
            self._written,
        )
        self.known_cells += int(newly_known)
        if self._cells is not None:
            written = self.last_written
            if written is None:
                self._cells = self._trinary_of(self._log_odds)
            else:
                _update_trinary(
                    self._cells,
                    self._log_odds,
                    written,
                    np.float32(config.free_threshold),
                    np.float32(config.occupied_threshold),
                )
        return flips


@numba.njit(cache=True)
def _trinary(
    log_odds: Float32Array, free_below: np.float32, occupied_above: np.float32
) -> NDArray[np.int8]:
    """The trinary cells of log-odds: OCCUPIED above ``occupied_above``, FREE below
    ``free_below``, else UNKNOWN."""
    rows, cols = log_odds.shape
    cells = np.empty((rows, cols), dtype=np.int8)
    for r in range(rows):
        for c in range(cols):
            value = log_odds[r, c]
            if value > occupied_above:
                cells[r, c] = OCCUPIED
            elif value < free_below:
                cells[r, c] = FREE
            else:
                cells[r, c] = UNKNOWN
    return cells


@numba.njit(cache=True)
def _update_trinary(
    cells: NDArray[np.int8],
    log_odds: Float32Array,
    flat: NDArray[np.int64],
    free_below: np.float32,
    occupied_above: np.float32,
) -> None:
    """``cells`` (the trinary view, as :func:`_trinary`) made current at the flat indices."""
    cols = log_odds.shape[1]
    for index in flat:
        row, col = index // cols, index % cols
        value = log_odds[row, col]
        if value > occupied_above:
            cells[row, col] = OCCUPIED
        elif value < free_below:
            cells[row, col] = FREE
        else:
            cells[row, col] = UNKNOWN


@numba.njit(cache=True)
def _mark_newly_known(
    log_odds: NDArray[np.float32],
    ever: NDArray[np.bool_],
    free_threshold: float,
    occupied_threshold: float,
    rows_out: NDArray[np.int64],
    cols_out: NDArray[np.int64],
) -> int:
    count = 0
    for row in range(log_odds.shape[0]):
        for col in range(log_odds.shape[1]):
            value = log_odds[row, col]
            if (value < free_threshold or value > occupied_threshold) and not ever[row, col]:
                ever[row, col] = True
                rows_out[count] = row
                cols_out[count] = col
                count += 1
    return count


@numba.njit(cache=True)
def _mark_newly_known_at(
    log_odds: NDArray[np.float32],
    ever: NDArray[np.bool_],
    free_threshold: float,
    occupied_threshold: float,
    candidates: NDArray[np.int64],
    flat_out: NDArray[np.int64],
) -> int:
    """:func:`_mark_newly_known` over the flat indices ``candidates`` only: marks in
    ``ever`` the known cells not yet in it, writes their flat indices to ``flat_out``
    (first occurrence only) and returns their count."""
    cols = log_odds.shape[1]
    count = 0
    for index in candidates:
        row, col = index // cols, index % cols
        value = log_odds[row, col]
        if (value < free_threshold or value > occupied_threshold) and not ever[row, col]:
            ever[row, col] = True
            flat_out[count] = index
            count += 1
    return count


def mark_newly_known(
    log_odds: NDArray[Any],
    ever: NDArray[np.bool_],
    free_threshold: float,
    occupied_threshold: float,
    candidates: NDArray[np.int64] | None = None,
) -> NDArray[np.int64]:
    """Cells known (log-odds beyond a threshold) that ``ever`` has not marked yet; marks them.

    One pass, no temporaries the size of the grid (the env calls it every step).

    Parameters
    ----------
    log_odds : ndarray (rows, cols)
    ever : ndarray of bool (rows, cols)
        Updated in place.
    free_threshold, occupied_threshold : float
        Known means ``< free_threshold`` or ``> occupied_threshold``.
    candidates : ndarray of int64, optional
        Flat indices (``row * cols + col``, repeats allowed) of the only cells that can
        be known and unmarked, e.g. :attr:`OccupancyGrid.last_written` when ``ever``
        marked every known cell before that scan; only they are looked at. None: the
        whole grid.

    Returns
    -------
    ndarray of int64, shape (k, 2)
        ``[row, col]`` of the newly known cells, row-major order.
    """
    if candidates is not None:
        flat = np.empty(len(candidates), dtype=np.int64)
        count = _mark_newly_known_at(
            log_odds, ever, float(free_threshold), float(occupied_threshold), candidates, flat
        )
        rows, cols = np.divmod(np.sort(flat[:count]), log_odds.shape[1])
        return np.column_stack([rows, cols])
    size = log_odds.size
    rows, cols = np.empty(size, dtype=np.int64), np.empty(size, dtype=np.int64)
    count = _mark_newly_known(
        log_odds, ever, float(free_threshold), float(occupied_threshold), rows, cols
    )
    return np.column_stack([rows[:count], cols[:count]])
