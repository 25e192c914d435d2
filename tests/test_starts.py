"""Tests for mrslam_env.sim.starts: the one clearance rule of automatic start poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from agents.planning import PlannerConfig
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.registry import build_world
from mrslam_env.sim.mapworld import wall_mask, world_from_map
from mrslam_env.sim.starts import (
    PASSAGE_MARGIN,
    START_MARGIN,
    START_RESOLUTION,
    cell_clearance,
    reachable_floor,
    start_cells,
    world_start_points,
)
from mrslam_env.sim.world import WorldSpec, box, ground_truth_map, polyline_walls

R = 0.2
OVERESTIMATE = (math.sqrt(0.5) - 0.5) * START_RESOLUTION  # at most this above the truth


def enclosure(width: float = 10.0, height: float = 6.0, extra: list | None = None) -> WorldSpec:
    walls = [
        box(0.0, 0.0, width, 0.1),
        box(0.0, height - 0.1, width, height),
        box(0.0, 0.0, 0.1, height),
        box(width - 0.1, 0.0, width, height),
        *(extra or []),
    ]
    return WorldSpec.from_walls("enclosure", walls, [(1.0, 1.0, 0.0)])


def test_cell_clearance_is_centre_distance_less_half_a_cell() -> None:
    walls = np.zeros((5, 7), dtype=bool)
    walls[2, 3] = True
    clearance = cell_clearance(walls, 0.1)
    assert clearance[2, 3] == pytest.approx(-0.05)
    assert clearance[2, 4] == pytest.approx(0.05)  # straight across: exact
    assert clearance[0, 3] == pytest.approx(0.15)
    assert clearance[1, 4] == pytest.approx((math.sqrt(2) - 0.5) * 0.1)  # diagonal


def test_cell_clearance_brackets_the_distance_to_the_wall_cells() -> None:
    # A world built from a map has exactly the wall cells as walls: the estimate is never
    # below their exact distance, and at most (sqrt(2) - 1) / 2 of a cell above it.
    rng = np.random.default_rng(5)
    cells = np.where(rng.random((40, 40)) < 0.01, OCCUPIED, FREE).astype(np.int8)
    cells = np.where(ndimage.binary_dilation(cells == OCCUPIED), OCCUPIED, FREE).astype(np.int8)
    grid = GridMap(cells=cells, resolution=0.05, origin=(0.3, -0.7))
    world = world_from_map(grid, name="pillars", robot_radius=0.05)
    walls = np.pad(wall_mask(grid), 1, constant_values=True)
    estimate = cell_clearance(walls, grid.resolution)[1:-1, 1:-1]
    free = np.argwhere(grid.cells == FREE)
    exact = world.clearance(grid.cell_to_world(free))
    at_free = estimate[free[:, 0], free[:, 1]]
    assert np.all(at_free >= exact - 1e-9)
    assert np.all(at_free <= exact + (math.sqrt(0.5) - 0.5) * grid.resolution + 1e-9)


def test_cell_clearance_is_safe_on_a_world_raster() -> None:
    # Wall cells cover every wall (a cell a wall touches is a wall cell): the exact
    # clearance is at least the estimate less the overestimate.
    rng = np.random.default_rng(5)
    pillars = [box(x, y, x + 0.3, y + 0.3) for x, y in rng.uniform(1.0, 8.0, (6, 2))]
    world = enclosure(extra=pillars)
    grid = ground_truth_map(world, START_RESOLUTION, margin=START_RESOLUTION)
    clearance = cell_clearance(grid.occupied, START_RESOLUTION)
    free = np.argwhere(grid.free)
    exact = world.clearance(grid.cell_to_world(free))
    inside = exact > 0
    estimate = clearance[free[:, 0], free[:, 1]]
    assert np.all(exact[inside] >= estimate[inside] - OVERESTIMATE - 1e-9)


def test_start_cells_need_radius_plus_margin() -> None:
    walls = np.ones((40, 40), dtype=bool)
    walls[1:-1, 1:-1] = False
    cells = start_cells(walls, 0.1, R)
    clearance = cell_clearance(walls, 0.1)
    assert cells.any()
    np.testing.assert_array_equal(cells, clearance >= R + START_MARGIN)


def test_start_cells_keep_the_reference_region() -> None:
    walls = np.ones((30, 60), dtype=bool)
    walls[1:-1, 1:-1] = False
    walls[:, 20] = True  # a small room left (cols 1..19), a big one right (21..58)
    left = start_cells(walls, 0.1, R, reachable_from=(15, 10))
    right = start_cells(walls, 0.1, R, reachable_from=(15, 40))
    largest = start_cells(walls, 0.1, R)
    assert left.any() and right.any()
    assert not left[:, 20:].any() and not right[:, :21].any()
    np.testing.assert_array_equal(largest, right)


def test_start_cells_reach_nothing_from_a_wall_or_off_the_raster() -> None:
    walls = np.ones((20, 20), dtype=bool)
    walls[1:-1, 1:-1] = False
    for cell in [(0, 0), (-1, 5), (5, 20), (100, 100)]:
        assert not start_cells(walls, 0.1, R, reachable_from=cell).any()
    assert not start_cells(np.ones((5, 5), dtype=bool), 0.1, R).any()


@pytest.mark.parametrize(("gap", "joined"), [(0.3, False), (0.5, False), (1.0, True)])
def test_only_passages_the_planner_can_use_join_the_regions(gap: float, joined: bool) -> None:
    # Two rooms joined by a gap in a wall. A robot of radius 0.2 squeezes through 0.5 m,
    # but the planner keeps its safety margin clear and plans through it only as a last
    # resort (the explorer's bare-footprint fallback): the
    # starts stay in the first room. A 1 m doorway joins the rooms.
    low, high = 1.3 - gap / 2, 1.3 + gap / 2
    world = enclosure(
        width=8.0, height=2.6, extra=[box(2.5, 0.1, 2.6, low), box(2.5, high, 2.6, 2.5)]
    )
    points = world_start_points(world, R, world.starts[0, :2])
    assert len(points) > 0
    assert np.any(points[:, 0] < 2.5)
    assert np.any(points[:, 0] > 2.6) == joined
    assert PlannerConfig().safety_margin <= PASSAGE_MARGIN


@pytest.mark.parametrize(("gap", "joined"), [(0.5, False), (1.0, True)])
def test_the_reachable_floor_ends_at_gaps_the_planner_never_uses(gap: float, joined: bool) -> None:
    # The same two rooms: behind a 0.5 m gap only a strip of floor counts (sqrt(2) times
    # the radius plus PASSAGE_MARGIN, plus a cell, past the gap); behind a 1 m door the
    # whole second room does, into its corners.
    low, high = 1.3 - gap / 2, 1.3 + gap / 2
    world = enclosure(
        width=8.0, height=2.6, extra=[box(2.5, 0.1, 2.6, low), box(2.5, high, 2.6, 2.5)]
    )
    grid = ground_truth_map(world, 0.1, margin=0.1)
    seeds = grid.world_to_cell(world.starts[:, :2])
    floor = reachable_floor(grid.free, grid.occupied, 0.1, R, seeds, PASSAGE_MARGIN)
    x, y = grid.cell_to_world(np.argwhere(grid.free)).T
    counted = floor[grid.free]
    indoors = (x > 0.1) & (x < 7.9) & (y > 0.1) & (y < 2.5)
    assert not counted[~indoors].any()  # the free raster margin outside the walls
    assert counted[indoors & (x < 2.5)].all()  # the first room, corners included
    second = indoors & (x > 2.6)
    if joined:
        assert counted[second].all()
    else:
        reach = math.sqrt(2.0) * (R + PASSAGE_MARGIN) + 0.2
        assert counted[second & (x > 2.6 + reach)].sum() == 0
        assert 0 < counted[second].sum() < 0.2 * second.sum()


def test_a_seed_where_nothing_is_passable_counts_its_free_component() -> None:
    world = enclosure(width=4.0, height=3.0)
    grid = ground_truth_map(world, 0.1, margin=0.1)
    seeds = grid.world_to_cell(world.starts[:, :2])
    # A 2 m robot.
    floor = reachable_floor(grid.free, grid.occupied, 0.1, 2.0, seeds, PASSAGE_MARGIN)
    x, y = grid.cell_to_world(np.argwhere(grid.free)).T
    indoors = (x > 0.1) & (x < 3.9) & (y > 0.1) & (y < 2.9)
    assert indoors.any()
    assert np.array_equal(floor[grid.free], indoors)


def test_world_start_points_have_clearance_and_stay_connected() -> None:
    walls = polyline_walls([(6.0, 0.1), (6.0, 3.0), (9.9, 3.0)], 0.1)  # a sealed corner room
    world = enclosure(extra=walls)
    points = world_start_points(world, R, world.starts[0, :2])
    assert len(points) > 0
    assert np.all(world.clearance(points) >= R + START_MARGIN - OVERESTIMATE - 1e-9)
    sealed = (points[:, 0] > 6.0) & (points[:, 1] < 3.0)
    assert not sealed.any()


@pytest.mark.parametrize("name", ["office", "maze"])
def test_world_start_points_are_the_cells_of_the_raster(name: str) -> None:
    world = build_world(name)
    grid = ground_truth_map(world, START_RESOLUTION, margin=START_RESOLUTION)
    iy, ix = grid.world_to_cell(world.starts[0, :2])
    cells = start_cells(grid.occupied, START_RESOLUTION, R, reachable_from=(iy, ix))
    points = world_start_points(world, R, world.starts[0])
    np.testing.assert_array_equal(points, grid.cell_to_world(np.argwhere(cells)))
