"""The growing log-odds grid (mrslam_env.slam.grid).

Oracles: the integration kernel against a slow reference built on
:func:`mrslam_env.slam.raycast.traverse` (itself tested against dense sampling); the
incrementally kept likelihood fields against a from-scratch sum of their kernels; a box room
mapped with true poses against the ground-truth raster.
"""

from __future__ import annotations

import math
from dataclasses import replace
from itertools import pairwise

import numpy as np
import pytest
from slam_worlds import room_walls

from mrslam_env.evaluation import map_agreement
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.sim.lidar import cast_scan
from mrslam_env.sim.world import WorldSpec, box, ground_truth_map
from mrslam_env.slam.config import GridConfig, SlamConfig
from mrslam_env.slam.grid import (
    HIT_AVERAGE_CAP,
    KERNEL_SCALE,
    PROVISIONAL,
    SECTORS,
    SUBCELL_POINTS,
    SUBCELLS,
    SURFACE_ZONE_CELLS,
    OccupancyGrid,
    facing_sectors,
    gaussian_kernels,
    mark_newly_known,
    sector_of,
)
from mrslam_env.slam.matcher import interpolate
from mrslam_env.slam.raycast import traverse
from mrslam_env.slam.scan import scan_normals
from mrslam_env.slam.slam import RobotSlam

NO_DISCS = np.zeros((0, 3))


def box_room(width: float = 6.0, height: float = 4.0) -> WorldSpec:
    """A closed room with 0.1 m walls and two pieces of furniture."""
    walls = [*room_walls(width, height), box(1.0, 1.0, 1.6, 1.4), box(4.2, 2.5, 4.6, 3.3)]
    return WorldSpec.from_walls("box", walls, [[3.0, 2.0, 0.0]])


def noisy_scan(world: WorldSpec, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    ranges = cast_scan(pose[0], pose[1], pose[2], 360, 8.0, world.segments, NO_DISCS)
    noisy = np.clip(ranges + rng.normal(0.0, 0.01, ranges.shape), 0.0, 8.0)
    return np.where(ranges < 8.0, noisy, 8.0)


def fields_from_scratch(grid: OccupancyGrid) -> tuple[np.ndarray, np.ndarray]:
    """The fields recomputed from each OCCUPIED cell's stamp index and sector mask."""
    rows, cols = grid.shape
    fine = np.zeros((SECTORS, rows, cols))
    coarse = np.zeros((rows, cols))
    for (iy, ix), q in zip(
        np.argwhere(grid.stamp_index >= 0), grid.stamp_index[grid.stamp_index >= 0], strict=True
    ):
        for kernels, targets in (
            (
                grid.fine_kernels,
                [fine[k] for k in range(SECTORS) if grid.sector_mask[iy, ix] >> k & 1],
            ),
            (grid.coarse_kernels, [coarse]),
        ):
            r = kernels.shape[1] // 2
            for target in targets:
                target[iy - r : iy + r + 1, ix - r : ix + r + 1] += kernels[q]
    return fine, coarse


def assert_fields_consistent(grid: OccupancyGrid) -> None:
    # The surface cells: not the map's OCCUPIED cells (the layers take different misses).
    surface = grid.stamp_index >= 0
    assert np.array_equal(surface, grid._surface_odds > grid.config.occupied_threshold)
    assert np.all(grid.sector_mask[surface] & (1 << SECTORS) - 1 > 0)
    assert np.all(grid.sector_mask[~surface] == 0)
    fine, coarse = fields_from_scratch(grid)
    np.testing.assert_array_equal(grid.fine_fields, fine)
    np.testing.assert_array_equal(grid.coarse_field[0], coarse)


# --- kernels and sectors ------------------------------------------------------------------


def test_kernels_are_integer_gaussians_centred_on_their_lattice_point() -> None:
    kernels, line_sum = gaussian_kernels(0.05, 0.05)
    assert kernels.shape[0] == SUBCELL_POINTS**2
    assert np.all(kernels == np.round(kernels)) and kernels.max() <= KERNEL_SCALE
    radius = kernels.shape[1] // 2
    offsets = np.arange(-radius, radius + 1)
    for q in range(SUBCELL_POINTS**2):
        weights = kernels[q].astype(np.float64)
        centre_x = (weights.sum(axis=0) @ offsets) / weights.sum()
        centre_y = (weights.sum(axis=1) @ offsets) / weights.sum()
        expected = np.array([q % SUBCELL_POINTS, q // SUBCELL_POINTS]) / SUBCELLS - 0.5
        np.testing.assert_allclose([centre_x, centre_y], expected, atol=0.03)
    # A straight wall (a long row of stamps) scores about 1 after dividing by line_sum.
    centre = SUBCELLS // 2 * SUBCELL_POINTS + SUBCELLS // 2  # the kernel at the cell centre
    row = sum(kernels[centre][:, k] for k in range(kernels.shape[2]))
    assert row.max() / line_sum == pytest.approx(1.0, abs=0.05)


def test_sectors_overlap_by_a_quarter_sector_each_side() -> None:
    assert sector_of(0.0) == 0 and sector_of(math.pi / 2) == 1 and sector_of(-math.pi / 2) == 3
    assert sector_of(math.pi) == 2 and sector_of(-math.pi + 1e-9) == 2
    assert facing_sectors(0.0) == 0b0001
    assert facing_sectors(math.radians(30)) == 0b0011
    assert facing_sectors(math.radians(-30)) == 0b1001
    # Every facing counts in the sector the query for that same facing reads.
    for direction in np.linspace(-7.0, 7.0, 1001):
        assert facing_sectors(direction) >> sector_of(direction) & 1


# --- integration against a slow reference ---------------------------------------------------


def reference_integrate(
    log_odds: np.ndarray,
    surface: np.ndarray,
    hit_mean: np.ndarray,
    hit_count: np.ndarray,
    held: np.ndarray,
    masks: np.ndarray,
    origin: tuple[float, float],
    resolution: float,
    pose: np.ndarray,
    ranges: np.ndarray,
    normals: np.ndarray,
    max_range: float,
    config: GridConfig,
) -> None:
    """The documented update, beam by beam with plain Python and ``traverse``."""
    x, y, heading = pose
    n = len(ranges)
    buffer = np.zeros((100_000, 2), dtype=np.int64)

    def end_point(i: int, r: float) -> tuple[float, float, float]:
        a = heading - math.pi + i * 2.0 * math.pi / n
        return x + r * math.cos(a), y + r * math.sin(a), a

    def cell_of(px: float, py: float) -> tuple[int, int]:
        return math.floor((py - origin[1]) / resolution), math.floor((px - origin[0]) / resolution)

    def entry_fraction(ex: float, ey: float, iy: int, ix: int) -> float:
        """Where the beam (x, y)-(ex, ey) enters cell (iy, ix), as a fraction of it."""
        t_in = 0.0
        for start, delta, low in ((x, ex - x, origin[0] + ix * resolution),
                                  (y, ey - y, origin[1] + iy * resolution)):  # fmt: skip
            if delta != 0.0:
                t_in = max(t_in, min((low - start) / delta, (low + resolution - start) / delta))
        return t_in

    def miss(value: np.float32, weight: float = config.log_odds_miss) -> np.float32:
        return np.float32(max(float(value) + weight, config.log_odds_min))

    held_miss = (
        config.log_odds_miss if config.log_odds_miss_held is None else config.log_odds_miss_held
    )

    returned = (ranges >= config.min_range) & (ranges < max_range)
    hit_cells = {cell_of(*end_point(i, ranges[i])[:2]) for i in np.flatnonzero(returned)}
    clear = min(config.no_return_clear_distance, max_range)
    for i in range(n):
        if ranges[i] < config.min_range:
            continue
        length = ranges[i] if returned[i] else clear
        ex, ey, a = end_point(i, length)
        # The near-surface zone: the last stretch of a returning beam within
        # surface_margin of its surface (across it), at most SURFACE_ZONE_CELLS cells.
        zone_start = held_start = 2.0
        if returned[i] and config.surface_margin > 0:
            incidence = abs(normals[i] @ [math.cos(a - heading), math.sin(a - heading)])
            along = SURFACE_ZONE_CELLS * resolution
            if incidence * along > config.surface_margin:
                along = config.surface_margin / incidence
            zone_start = 1.0 - along / length
            # ... and the stretch where the map's miss in a cell holding hits is weaker.
            along = config.held_reach
            if incidence * along > config.surface_margin:
                along = config.surface_margin / incidence
            held_start = 1.0 - along / length
        count = traverse(x, y, ex, ey, origin[0], origin[1], resolution, buffer)
        for k, (iy, ix) in enumerate(buffer[:count]):
            if (iy, ix) in hit_cells or (
                not returned[i] and log_odds[iy, ix] > config.occupied_threshold
            ):
                if returned[i]:
                    continue
                break
            entry = entry_fraction(ex, ey, iy, ix) if k > 0 else 0.0
            weaker = returned[i] and held[iy, ix] and entry >= held_start
            log_odds[iy, ix] = miss(log_odds[iy, ix], held_miss if weaker else config.log_odds_miss)
            if log_odds[iy, ix] <= config.log_odds_min:
                held[iy, ix] = False
            near_surface = returned[i] and hit_count[iy, ix] > 0 and entry >= zone_start
            if near_surface:
                continue  # the surface layer ignores it
            surface[iy, ix] = miss(surface[iy, ix])
            if surface[iy, ix] <= config.occupied_threshold:
                if masks[iy, ix]:  # no longer a surface cell
                    hit_count[iy, ix] = 0
                masks[iy, ix] = 0
    for i in np.flatnonzero(returned):
        ex, ey, a = end_point(i, ranges[i])
        iy, ix = cell_of(ex, ey)
        hit_count[iy, ix] = min(hit_count[iy, ix] + 1, HIT_AVERAGE_CAP)
        held[iy, ix] = True
        offset = np.array([(ex - origin[0]) / resolution - ix, (ey - origin[1]) / resolution - iy])
        hit_mean[iy, ix] += ((offset - hit_mean[iy, ix]) / hit_count[iy, ix]).astype(np.float32)
        log_odds[iy, ix] = np.float32(
            min(float(log_odds[iy, ix]) + config.log_odds_hit, config.log_odds_max)
        )
        surface[iy, ix] = np.float32(
            min(float(surface[iy, ix]) + config.log_odds_hit, config.log_odds_max)
        )
        if surface[iy, ix] > config.occupied_threshold:
            if normals[i].any():
                facing = heading + math.atan2(normals[i, 1], normals[i, 0])
                if masks[iy, ix] & PROVISIONAL:
                    masks[iy, ix] = 0  # the first real normal replaces the guess
                masks[iy, ix] |= facing_sectors(facing)
            elif not masks[iy, ix]:
                masks[iy, ix] = facing_sectors(a + math.pi) | PROVISIONAL


def test_integration_matches_the_slow_reference() -> None:
    rng = np.random.default_rng(1)
    world = box_room()
    config = GridConfig(no_return_clear_distance=2.5)
    grid = OccupancyGrid(config)
    grid.ensure_contains(-3.0, -3.0, 9.0, 7.0)
    log_odds = grid.log_odds.copy()
    surface = grid._surface_odds.copy()
    hit_mean = grid._hit_mean.copy()
    hit_count = grid._hit_count.copy()
    held = grid._hit_held.copy()
    masks = grid.sector_mask.copy()
    for step in range(25):
        pose = np.array([rng.uniform(0.5, 5.5), rng.uniform(0.5, 3.5), rng.uniform(-4, 4)])
        if world.clearance(pose[:2])[0] < 0.3:
            continue
        ranges = noisy_scan(world, pose, rng)
        ranges[rng.random(360) < 0.05] = 8.0  # dropouts: no-return beams inside the room
        ranges[rng.random(360) < 0.02] = 0.01  # below min_range: skipped
        normals = scan_normals(ranges, 8.0, config.min_range)
        reference_integrate(
            log_odds, surface, hit_mean, hit_count, held, masks, grid.origin, grid.resolution, pose,
            ranges, normals, 8.0, config,
        )  # fmt: skip
        grid.integrate_scan(pose, ranges, 8.0, normals)
        assert grid.shape == log_odds.shape, "the room fits: no growth expected"
        np.testing.assert_array_equal(grid.log_odds, log_odds, err_msg=f"step {step}")
        np.testing.assert_array_equal(grid._surface_odds, surface, err_msg=f"step {step}")
        np.testing.assert_array_equal(grid._hit_held, held)
        np.testing.assert_allclose(grid._hit_mean, hit_mean, atol=1e-6)
        np.testing.assert_array_equal(grid._hit_count, hit_count)
        np.testing.assert_array_equal(grid.sector_mask, masks)
        known = (log_odds < config.free_threshold) | (log_odds > config.occupied_threshold)
        assert grid.known_cells == known.sum(), f"step {step}"
        expected_index = np.where(
            surface > config.occupied_threshold,
            np.clip(np.round(hit_mean[..., 1] * SUBCELLS), 0, SUBCELLS).astype(int) * SUBCELL_POINTS
            + np.clip(np.round(hit_mean[..., 0] * SUBCELLS), 0, SUBCELLS).astype(int),
            -1,
        )
        np.testing.assert_array_equal(grid.stamp_index, expected_index)
    assert_fields_consistent(grid)
    assert (grid.log_odds > 0.5).sum() > 300 and (grid.log_odds < -0.5).sum() > 5000


def grazing_wall_face(config: GridConfig) -> np.ndarray:
    """Log-odds of the cells a wall's face lies in (halfway across them), 3-6 m ahead of
    a robot that drives 2 m along the wall 1 m from it: it sees them only at 9-18° of
    incidence, each hit by the beams ending there and passed by those ending further on."""
    face = 1.025
    world = WorldSpec.from_walls("wall", [box(-30.0, face, 30.0, face + 0.1)], [[0, 0, 0]])
    rng = np.random.default_rng(3)
    grid = OccupancyGrid(config)
    for x in np.arange(-3.0, -1.0, 0.05):
        pose = np.array([x, 0.013, 0.3])
        grid.integrate_scan(pose, noisy_scan(world, pose, rng), 8.0)
    iy, start = grid.world_to_cell([2.0, face])
    stop = grid.world_to_cell([5.0, face])[1]
    return grid.log_odds[iy, start:stop]


def test_a_wall_seen_at_a_grazing_angle_stays_occupied() -> None:
    config = GridConfig()
    face = grazing_wall_face(config)
    assert (face > config.occupied_threshold).mean() >= 0.9
    # With the full miss in cells that hold hits (the textbook update), the passes outvote
    # the hits and most of the face reads FREE.
    textbook = grazing_wall_face(replace(config, log_odds_miss_held=None))
    assert (textbook > config.occupied_threshold).mean() < 0.3
    assert (textbook < config.free_threshold).mean() > 0.5


def test_beams_without_return_clear_only_so_far_and_stop_at_walls() -> None:
    grid = OccupancyGrid(GridConfig(no_return_clear_distance=2.0))
    wall = np.full(360, 8.0)
    wall[180] = 1.0  # beam 180 points straight ahead (heading 0): a wall at x = 1 m
    for _ in range(3):
        grid.integrate_scan([0.025, 0.025, 0.0], wall, 8.0)
    iy, ix = grid.world_to_cell([1.02, 0.025])
    assert grid.log_odds[iy, ix] > 0.5
    # Now nothing returns (a dropout): the beam ahead clears up to the wall, not past it.
    grid.integrate_scan([0.025, 0.025, 0.0], np.full(360, 8.0), 8.0)
    assert grid.log_odds[iy, ix] > 0.5
    iy, ix = grid.world_to_cell([-1.5, 0.025])  # behind the robot, within 2 m: cleared
    assert grid.log_odds[iy, ix] < 0.0
    iy, ix = grid.world_to_cell([-2.5, 0.025])  # beyond the clearing distance: untouched
    assert grid.log_odds[iy, ix] == 0.0


# --- clamping, growth, trinary view -----------------------------------------------------------


def test_log_odds_stay_clamped() -> None:
    rng = np.random.default_rng(2)
    world = box_room()
    config = GridConfig(log_odds_min=-1.5, log_odds_max=2.0)
    grid = OccupancyGrid(config)
    pose = np.array([3.0, 2.0, 0.3])
    for _ in range(60):
        grid.integrate_scan(pose, noisy_scan(world, pose, rng), 8.0)
    values = grid.log_odds
    assert values.min() == pytest.approx(-1.5) and values.max() == pytest.approx(2.0)
    assert np.all((values >= np.float32(-1.5)) & (values <= np.float32(2.0)))
    assert_fields_consistent(grid)


@pytest.mark.parametrize("direction", [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1)])
def test_the_grid_grows_without_moving_cells(direction: tuple[int, int]) -> None:
    rng = np.random.default_rng(3)
    world = box_room()
    grid = OccupancyGrid(GridConfig(growth_chunk=16))
    pose = np.array([3.0, 2.0, 0.0])
    in_map = compose(inverse(pose), pose)  # the map frame is the first pose
    grid.integrate_scan(in_map, noisy_scan(world, pose, rng), 8.0)
    occupied = np.argwhere(grid.occupied())
    before_world = grid.cell_to_world(occupied)
    before_values = grid.log_odds[grid.occupied()].copy()
    shape = grid.shape
    far = 20.0 * np.array(direction, dtype=np.float64)
    assert grid.ensure_contains(far[0] - 0.1, far[1] - 0.1, far[0] + 0.1, far[1] + 0.1)
    assert grid.ensure_contains(far[0], far[1], far[0], far[1]) is False
    rows, cols = grid.shape
    assert rows >= shape[0] and cols >= shape[1] and (rows, cols) != shape
    assert rows % 16 == 0 and cols % 16 == 0
    for value in grid.origin:  # the origin stays on the lattice through the map origin
        assert value / grid.resolution == pytest.approx(round(value / grid.resolution), abs=1e-9)
    # The same world points hold the same values, and the far box is inside.
    cells = grid.world_to_cell(before_world)
    np.testing.assert_array_equal(grid.log_odds[cells[:, 0], cells[:, 1]], before_values)
    np.testing.assert_allclose(grid.cell_to_world(cells), before_world, atol=1e-9)
    assert grid.occupied().sum() == len(occupied)
    far_cell = grid.world_to_cell(far)
    assert 0 <= far_cell[0] < rows and 0 <= far_cell[1] < cols
    assert_fields_consistent(grid)
    # Integration still works after growing.
    grid.integrate_scan(in_map, noisy_scan(world, pose, rng), 8.0)
    assert_fields_consistent(grid)
    assert grid.known_cells == (grid.to_gridmap().cells != UNKNOWN).sum()


@pytest.mark.parametrize("capacity", [None, 50])
def test_the_written_cells_keep_the_view_and_the_newly_known_cells_exact(
    capacity: int | None,
) -> None:
    # Scans that grow the grid, with the kept trinary view and the newly known cells from
    # the written cells against a full pass each step; capacity 50: too many writes to
    # list, so every cell counts as possibly changed.
    rng = np.random.default_rng(5)
    world = box_room(9.0, 5.0)
    grid = OccupancyGrid(GridConfig(growth_chunk=32))
    if capacity is not None:
        grid._written = np.empty(capacity, dtype=np.int64)
    config = grid.config
    ever_full = np.zeros(grid.shape, dtype=bool)
    ever_listed = np.zeros(grid.shape, dtype=bool)
    grid.to_gridmap()  # from now on the view is kept current
    start = np.array([1.0, 1.0, 0.0])
    for step in range(30):
        pose = np.array([1.0 + 0.25 * step, 1.0 + 0.08 * step, 0.2 * step])
        shape, origin = grid.shape, grid.origin
        grid.integrate_scan(compose(inverse(start), pose), noisy_scan(world, pose, rng), 8.0)
        if grid.shape != shape:  # grow the masks with the grid, as the env does
            dy = round((origin[1] - grid.origin[1]) / grid.resolution)
            dx = round((origin[0] - grid.origin[0]) / grid.resolution)
            for name, mask in (("full", ever_full), ("listed", ever_listed)):
                grown = np.zeros(grid.shape, dtype=bool)
                grown[dy : dy + shape[0], dx : dx + shape[1]] = mask
                if name == "full":
                    ever_full = grown
                else:
                    ever_listed = grown
        written = grid.last_written
        assert (written is None) == (capacity is not None)
        thresholds = (config.free_threshold, config.occupied_threshold)
        full = mark_newly_known(grid.log_odds, ever_full, *thresholds)
        listed = mark_newly_known(grid.log_odds, ever_listed, *thresholds, written)
        np.testing.assert_array_equal(listed, full, err_msg=f"step {step}")
        np.testing.assert_array_equal(ever_listed, ever_full)
        expected = np.full(grid.shape, UNKNOWN, dtype=np.int8)
        expected[grid.log_odds < np.float32(config.free_threshold)] = FREE
        expected[grid.log_odds > np.float32(config.occupied_threshold)] = OCCUPIED
        view = grid.to_gridmap()
        np.testing.assert_array_equal(view.cells, expected, err_msg=f"step {step}")
        assert view.origin == grid.origin
    assert grid.shape != (32, 32) and ever_full.sum() > 1000


def test_to_gridmap_is_the_trinary_view() -> None:
    grid = OccupancyGrid()
    grid._log_odds[3, 4] = 2.0
    grid._log_odds[5, 6] = -1.0
    grid._log_odds[7, 8] = 0.2
    gridmap = grid.to_gridmap()
    assert gridmap.cells[3, 4] == OCCUPIED and gridmap.cells[5, 6] == FREE
    assert gridmap.cells[7, 8] == UNKNOWN and gridmap.cells[0, 0] == UNKNOWN
    assert gridmap.origin == grid.origin and gridmap.resolution == grid.resolution
    with pytest.raises(ValueError):
        grid.log_odds[0, 0] = 1.0  # read-only view


def test_to_gridmap_thresholds_as_numpy_does_and_makes_a_valid_map() -> None:
    # The one-pass kernel against the three-mask numpy view, with log-odds on and next to
    # the (float32) thresholds, whose comparison numpy makes in float32.
    config = GridConfig()
    grid = OccupancyGrid(config)
    rng = np.random.default_rng(3)
    rows, cols = grid.shape
    values = rng.normal(0.0, 1.0, (rows, cols)).astype(np.float32)
    for threshold in (config.free_threshold, config.occupied_threshold):
        on = np.float32(threshold)
        values[0, :3] = (np.nextafter(on, np.float32(-9)), on, np.nextafter(on, np.float32(9)))
        values = values[::-1].copy()
    grid._log_odds[:] = values
    expected = np.full((rows, cols), UNKNOWN, dtype=np.int8)
    expected[values < config.free_threshold] = FREE
    expected[values > config.occupied_threshold] = OCCUPIED
    gridmap = grid.to_gridmap()
    np.testing.assert_array_equal(gridmap.cells, expected)
    assert gridmap.cells.dtype == np.int8 and set(np.unique(gridmap.cells)) == {-1, 0, 100}
    checked = GridMap(cells=gridmap.cells, resolution=grid.resolution, origin=grid.origin)
    assert (checked.origin, checked.resolution) == (gridmap.origin, gridmap.resolution)
    assert type(gridmap.resolution) is float and all(type(v) is float for v in gridmap.origin)


@pytest.mark.parametrize("bad", [1, 99, -2, 127, -128])
@pytest.mark.parametrize("where", [(0, 0), (4, 6), (2, 3)])
def test_gridmap_finds_a_bad_value_anywhere_also_in_a_strided_view(
    bad: int, where: tuple[int, int]
) -> None:
    cells = np.full((5, 7), UNKNOWN, dtype=np.int8)
    cells[1, 1], cells[3, 2] = FREE, OCCUPIED
    GridMap(cells=cells, resolution=0.1)  # valid
    cells[where] = bad
    with pytest.raises(ValueError, match=rf"other than 0, 100, -1 \(e.g. {bad}\)"):
        GridMap(cells=cells, resolution=0.1)
    with pytest.raises(ValueError, match=rf"other than 0, 100, -1 \(e.g. {bad}\)"):
        GridMap(cells=cells.T, resolution=0.1)  # not C-contiguous


def test_box_room_mapped_with_true_poses_matches_the_ground_truth() -> None:
    rng = np.random.default_rng(4)
    world = box_room()
    # A start pose off the lattice and at an angle: the map is rotated against the world.
    start = np.array([2.37, 1.81, 0.43])
    slam = RobotSlam(SlamConfig(mode="ground_truth"), 360, 8.0)
    waypoints = [start, [4.9, 1.2, 1.2], [5.2, 3.3, 2.8], [2.6, 3.2, -2.4], [0.6, 2.2, -1.0]]
    path = np.concatenate(
        [np.linspace(a, b, 25, endpoint=False) for a, b in pairwise(np.asarray(waypoints))]
    )
    for pose in path:
        in_map = compose(inverse(start), pose)
        slam.update(in_map, noisy_scan(world, pose, rng), in_map)
    raster = ground_truth_map(world, 0.05, margin=1.0)
    gridmap = slam.grid.to_gridmap()
    assert (gridmap.cells == OCCUPIED).sum() > 500 and (gridmap.cells == FREE).sum() > 5000
    assert map_agreement(gridmap, start, raster) >= 0.97
    # The same map placed wrongly (a 0.3 m shift) must not pass: the check can fail.
    assert map_agreement(gridmap, start + np.array([0.3, 0.0, 0.0]), raster) < 0.96


def test_a_wall_on_a_cell_edge_keeps_its_ridge_on_its_surface() -> None:
    # Range noise splits the hits on a wall lying on a cell edge between two rows of cells;
    # without surface_margin the beams clear the front row and the ridge sinks behind the
    # surface (each row's mean hit point is the noise's half on its side of the edge).
    world = WorldSpec.from_walls(
        "room", [box(-0.1, -0.1, 8.1, 0.0), box(-0.1, 5.0, 8.1, 5.1), box(-0.1, 0.0, 0.0, 5.0),
                 box(8.0, 0.0, 8.1, 5.0)], [[1.5, 1.0, 0.0]],
    )  # fmt: skip
    poses = [
        np.array([x, 1.0 + 0.3 * math.sin(x), 0.2 * math.cos(2.0 * x)])
        for x in np.linspace(1.5, 6.0, 40)
    ]
    along = np.arange(1.0, 6.0, 0.1)
    across = np.arange(-0.02, 0.02, 0.0002)

    def ridge_offsets(config: GridConfig) -> np.ndarray:
        rng = np.random.default_rng(0)
        grid = OccupancyGrid(config)
        for pose in poses:
            grid.integrate_scan(pose, noisy_scan(world, pose, rng), 8.0)
        ox, oy = grid.origin
        sector = sector_of(math.pi / 2.0)  # the south wall's face y = 0 faces +y
        offsets = []
        for x in along:
            gx = (x - ox) / grid.resolution - 0.5
            values = [
                interpolate(
                    grid.fine_fields, sector, grid.fine_scale, gx, (y - oy) / grid.resolution - 0.5
                )[0]
                for y in across
            ]
            offsets.append(across[int(np.argmax(values))])
        return np.array(offsets)

    offsets = ridge_offsets(GridConfig())
    assert abs(offsets.mean()) < 0.001 and np.abs(offsets).max() < 0.0025
    assert ridge_offsets(replace(GridConfig(), surface_margin=0.0)).mean() < -0.003
