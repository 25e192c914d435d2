"""The scenario catalogue: every world is a closed building a robot can drive through.

Checked on the ground-truth raster at 5 cm (ground_truth_map) for every hand-made world,
procedural seeds 0..9, procedural_large seeds 0..3 and procedural_huge seeds 0..1: start
poses free, clear and far apart; the building sealed from the outside; the free space
passable for a 0.2 m robot (no sealed rooms); the procedural generator deterministic and
varied; the two wings of ``twin_wings`` true copies; the large plans wider than the radio's
range; the huge ones with long loops.
"""

from __future__ import annotations

import math
from functools import cache
from importlib.metadata import entry_points

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import ndimage

from mrslam_env.config import CommConfig
from mrslam_env.gridmap import FREE, GridMap
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from scenarios.worlds import buildings
from scenarios.worlds.catalog import SCENARIOS, Scenario
from scenarios.worlds.procedural import (
    ProceduralConfig,
    build_procedural,
    generate_floor_plan,
)
from scenarios.worlds.real import REAL_BUILDINGS

RESOLUTION = 0.05  # m per cell of the test rasters
MARGIN = 1.0  # m of outside space around each raster
ROBOT_RADIUS = 0.2  # m
ROBOT_MARGIN = 0.05  # m, extra clearance for the passability test
MIN_START_CLEARANCE = 0.5  # m
MIN_START_DISTANCE = 6.0  # m
MIN_HEADING_DIFFERENCE = math.radians(30.0)
MIN_REACHABLE_FRACTION = 0.9  # of the building's free area the robot body can sweep
MAX_UNREACHABLE_POCKET = 0.5  # m^2 of robot-centre space the robot cannot get to
PROCEDURAL_SEEDS = range(10)
EIGHT_NEIGHBOURS = np.ones((3, 3), dtype=bool)

HAND_MADE = [
    name for name, s in SCENARIOS.items() if not s.parametric and name not in REAL_BUILDINGS
]
CASES = [(name, 0) for name in HAND_MADE] + [("procedural", seed) for seed in PROCEDURAL_SEEDS]
LARGE_SEEDS = range(4)
LARGE_CASES = [("procedural_large", seed) for seed in LARGE_SEEDS]
HUGE_SEEDS = range(2)
ALL_CASES = CASES + LARGE_CASES + [("procedural_huge", seed) for seed in HUGE_SEEDS]
CASE_IDS = [f"{name}-{seed}" for name, seed in CASES]
ALL_IDS = [f"{name}-{seed}" for name, seed in ALL_CASES]


@cache
def world_of(name: str, seed: int) -> WorldSpec:
    return SCENARIOS[name].build(seed)


@cache
def raster_of(name: str, seed: int) -> GridMap:
    return ground_truth_map(world_of(name, seed), RESOLUTION, margin=MARGIN)


def start_cells(grid: GridMap, world: WorldSpec) -> NDArray[np.int64]:
    cells = grid.world_to_cell(world.starts[:, :2])
    assert grid.contains(cells).all(), f"starts {world.starts[:, :2]} lie outside the raster"
    return cells


def building_component(grid: GridMap, world: WorldSpec) -> NDArray[np.bool_]:
    """Free cells 8-connected to robot 0's start (8-connectivity also leaks through
    diagonal cracks, so it is the stricter choice for the enclosure test)."""
    labels, _ = ndimage.label(grid.free, structure=EIGHT_NEIGHBOURS)
    row, col = start_cells(grid, world)[0]
    return labels == labels[row, col]


def wall_clearance(grid: GridMap) -> NDArray[np.float64]:
    """Distance (m) from each cell centre to the nearest occupied cell's edge (approx.)."""
    return ndimage.distance_transform_edt(grid.free) * grid.resolution - grid.resolution / 2.0


# ----------------------------------------------------------------------------- catalogue


def test_catalogue_holds_the_builtin_scenarios() -> None:
    built = {"office", "warehouse", "maze", "twin_wings"}
    built |= {"procedural", "procedural_large", "procedural_huge"}
    assert set(SCENARIOS) == built | set(REAL_BUILDINGS)
    for name, scenario in SCENARIOS.items():
        assert isinstance(scenario, Scenario)
        assert scenario.name == name
        assert scenario.description and "\n" not in scenario.description
    parametric = [name for name, s in SCENARIOS.items() if s.parametric]
    assert parametric == ["procedural", "procedural_large", "procedural_huge"]


def test_catalogue_is_the_registered_entry_point() -> None:
    loaded = [e.load() for e in entry_points(group="mrslam.scenarios") if e.name == "builtin"]
    assert len(loaded) == 1 and loaded[0] is SCENARIOS


def test_catalogue_is_read_only() -> None:
    with pytest.raises(TypeError):
        SCENARIOS["extra"] = SCENARIOS["office"]  # type: ignore[index]


@pytest.mark.parametrize("name", ["", "two words", "office\n"])
def test_scenario_rejects_bad_names(name: str) -> None:
    with pytest.raises(ValueError, match=r"Scenario\.name"):
        Scenario(name=name, description="x", build=buildings.build_office)


@pytest.mark.parametrize("name", HAND_MADE)
def test_hand_made_worlds_ignore_the_seed(name: str) -> None:
    a, b = SCENARIOS[name].build(0), SCENARIOS[name].build(17)
    assert np.array_equal(a.walls, b.walls)
    assert np.array_equal(a.starts, b.starts)


# ----------------------------------------------------------------------------- wall kit


def test_door_has_the_requested_clear_width() -> None:
    pieces = buildings.horizontal_wall(2.0, 0.0, 6.0, doors=[(3.0, 1.2)])
    assert len(pieces) == 2
    left_face = pieces[0][:, 0].max()
    right_face = pieces[1][:, 0].min()
    assert right_face - left_face == pytest.approx(1.2, abs=1e-12)
    assert (left_face + right_face) / 2.0 == pytest.approx(3.0, abs=1e-12)
    # The pieces overhang the wall's ends by half the thickness, closing the corners.
    assert pieces[0][:, 0].min() == pytest.approx(-0.05, abs=1e-12)
    assert pieces[1][:, 0].max() == pytest.approx(6.05, abs=1e-12)


@pytest.mark.parametrize("doors", [[(1.0, 1.0), (1.8, 1.0)], [(0.3, 1.0)], [(5.8, 1.0)]])
def test_overlapping_or_overhanging_doors_are_rejected(doors: list[tuple[float, float]]) -> None:
    with pytest.raises(ValueError, match="opening"):
        buildings.horizontal_wall(0.0, 0.0, 6.0, doors=doors)


# ----------------------------------------------------------------------------- each world


@pytest.mark.parametrize(("name", "seed"), CASES, ids=CASE_IDS)
def test_world_size_and_wall_count_are_moderate(name: str, seed: int) -> None:
    world = world_of(name, seed)
    xmin, ymin, xmax, ymax = world.bounds
    assert 12.0 <= xmax - xmin <= 35.0 and 12.0 <= ymax - ymin <= 35.0, world.bounds
    assert 10 <= len(world.walls) <= 400
    assert len(world.starts) == 2


@pytest.mark.parametrize(("name", "seed"), ALL_CASES, ids=ALL_IDS)
def test_starts_are_free_and_clear(name: str, seed: int) -> None:
    world, grid = world_of(name, seed), raster_of(name, seed)
    rows, cols = start_cells(grid, world).T
    assert grid.free[rows, cols].all(), f"a start of {name}-{seed} is not in a free cell"
    clearance = world.clearance(world.starts[:, :2])
    assert np.all(clearance >= MIN_START_CLEARANCE), clearance


@pytest.mark.parametrize(("name", "seed"), ALL_CASES, ids=ALL_IDS)
def test_starts_are_far_apart_and_face_different_ways(name: str, seed: int) -> None:
    first, second = world_of(name, seed).starts
    assert np.hypot(*(first[:2] - second[:2])) >= MIN_START_DISTANCE
    heading_difference = abs(math.remainder(first[2] - second[2], 2.0 * math.pi))
    assert heading_difference >= MIN_HEADING_DIFFERENCE


@pytest.mark.parametrize(("name", "seed"), ALL_CASES, ids=ALL_IDS)
def test_building_is_enclosed(name: str, seed: int) -> None:
    world, grid = world_of(name, seed), raster_of(name, seed)
    inside = building_component(grid, world)
    touches_border = inside[0].any() | inside[-1].any() | inside[:, 0].any() | inside[:, -1].any()
    assert not touches_border, f"the free space of {name}-{seed} leaks to the outside"
    rows, cols = start_cells(grid, world).T
    assert inside[rows, cols].all(), "the starts lie in different free regions"
    # The outside is free too, so the raster really has an outside to leak into.
    assert grid.free[0, 0] and not inside[0, 0]


@pytest.mark.parametrize(("name", "seed"), ALL_CASES, ids=ALL_IDS)
def test_robot_can_drive_everywhere(name: str, seed: int) -> None:
    """Erode the free space by the robot's radius (plus a margin): the robot centre's
    space must join both starts, leave no sizeable pocket out of reach (no sealed rooms,
    no door narrower than the robot), and let the robot sweep most of the building."""
    world, grid = world_of(name, seed), raster_of(name, seed)
    inside = building_component(grid, world)
    centre_space = (wall_clearance(grid) >= ROBOT_RADIUS + ROBOT_MARGIN) & inside
    labels, _ = ndimage.label(centre_space)
    rows, cols = start_cells(grid, world).T
    start_labels = labels[rows, cols]
    assert start_labels[0] > 0 and start_labels[0] == start_labels[1], start_labels
    reachable = labels == start_labels[0]
    pocket_area = np.bincount(labels[centre_space & ~reachable]) * RESOLUTION**2
    assert pocket_area.max(initial=0.0) <= MAX_UNREACHABLE_POCKET, (
        f"{name}-{seed}: {pocket_area.max():.2f} m^2 of robot space is out of reach"
    )
    swept_distance = ndimage.distance_transform_edt(~reachable) * RESOLUTION
    swept = swept_distance <= ROBOT_RADIUS + ROBOT_MARGIN + RESOLUTION / 2.0
    fraction = np.count_nonzero(swept & inside) / np.count_nonzero(inside)
    assert fraction >= MIN_REACHABLE_FRACTION, f"{name}-{seed}: robot sweeps {fraction:.1%}"


def test_a_sealed_room_fails_the_passability_check() -> None:
    """The passability check above can fail: a wall across the doorway of the office's
    narrow north room (x 8.5-11.5 m, door at x = 10 m) seals it off."""
    office = world_of("office", 0)
    door = buildings.horizontal_wall(9.0, 9.0, 11.0)
    sealed = WorldSpec.from_walls("sealed", [*office.walls, *door], office.starts)
    grid = ground_truth_map(sealed, RESOLUTION, margin=MARGIN)
    centre_space = wall_clearance(grid) >= ROBOT_RADIUS + ROBOT_MARGIN
    labels, _ = ndimage.label(centre_space)
    start_label = labels[tuple(start_cells(grid, sealed)[0])]
    room_label = labels[tuple(grid.world_to_cell([[10.0, 12.5]])[0])]
    assert room_label > 0 and room_label != start_label
    assert np.count_nonzero(labels == room_label) * RESOLUTION**2 > MAX_UNREACHABLE_POCKET


# ----------------------------------------------------------------------------- procedural


def test_procedural_same_seed_same_world() -> None:
    a, b = build_procedural(3), build_procedural(3)
    assert np.array_equal(a.walls, b.walls)
    assert np.array_equal(a.starts, b.starts)
    assert a.name == b.name == "procedural-3"


def test_procedural_seeds_give_distinct_layouts() -> None:
    layouts = [world_of("procedural", seed).walls for seed in PROCEDURAL_SEEDS]
    for i, first in enumerate(layouts):
        for second in layouts[i + 1 :]:
            assert not (first.shape == second.shape and np.allclose(first, second))


@pytest.mark.parametrize("seed", PROCEDURAL_SEEDS)
def test_procedural_has_at_least_five_rooms(seed: int) -> None:
    assert generate_floor_plan(seed).room_count >= 5
    # Independently, on the raster: closing every 1 m door (eroding by 0.55 m) splits the
    # building into at least five room-sized (>= 2 m^2) spaces.
    world, grid = world_of("procedural", seed), raster_of("procedural", seed)
    rooms, _ = ndimage.label((wall_clearance(grid) >= 0.55) & building_component(grid, world))
    areas = np.bincount(rooms.ravel())[1:] * RESOLUTION**2
    assert np.count_nonzero(areas >= 2.0) >= 5


@pytest.mark.parametrize("seed", LARGE_SEEDS)
def test_procedural_large_is_larger_than_the_radio_range(seed: int) -> None:
    world = world_of("procedural_large", seed)
    assert world.name == f"procedural_large-{seed}"
    xmin, ymin, xmax, ymax = world.bounds
    sides = sorted((xmax - xmin, ymax - ymin))
    assert 24.0 <= sides[0] <= 30.5 and 36.0 <= sides[1] <= 44.5, world.bounds
    # The starts are out of radio range of each other: the link is down at step 0.
    first, second = world.starts
    assert np.hypot(*(first[:2] - second[:2])) > 2.0 * CommConfig().comm_range


@pytest.mark.parametrize("seed", HUGE_SEEDS)
def test_procedural_huge_is_a_big_building_with_long_loops(seed: int) -> None:
    """Loop closure needs loops: a wall block with floor all around it, whose outline (and
    so any path around it) is at least 100 m long."""
    world = world_of("procedural_huge", seed)
    assert world.name == f"procedural_huge-{seed}"
    xmin, ymin, xmax, ymax = world.bounds
    sides = sorted((xmax - xmin, ymax - ymin))
    assert 45.0 <= sides[0] <= 60.5 and 60.0 <= sides[1] <= 80.5, world.bounds
    grid = ground_truth_map(world, RESOLUTION, margin=1.0)
    blocks, _ = ndimage.label(grid.cells != FREE, structure=EIGHT_NEIGHBOURS)
    outside = set(np.unique(np.concatenate([blocks[0], blocks[-1], blocks[:, 0], blocks[:, -1]])))
    outlines = [
        2 * RESOLUTION * ((rows.stop - rows.start) + (cols.stop - cols.start))
        for label, (rows, cols) in enumerate(ndimage.find_objects(blocks), start=1)
        if label not in outside
    ]
    assert max(outlines) >= 100.0


def test_procedural_rooms_tile_the_floor() -> None:
    plan = generate_floor_plan(5)
    area = sum((r.x1 - r.x0) * (r.y1 - r.y0) for r in plan.rooms)
    assert area == pytest.approx(plan.width * plan.depth, abs=1e-6)
    assert all(
        min(r.x1 - r.x0, r.y1 - r.y0) >= ProceduralConfig().min_room_side - 1e-6
        for r in plan.rooms
        if r.kind.value == "room"
    )


@pytest.mark.parametrize("seed", [-1, 1.5, True])
def test_procedural_rejects_bad_seeds(seed: object) -> None:
    with pytest.raises(ValueError, match="seed"):
        build_procedural(seed)  # type: ignore[arg-type]


def test_procedural_config_is_validated() -> None:
    with pytest.raises(ValueError, match="min_room_side"):
        ProceduralConfig(min_room_side=0.0)
    with pytest.raises(ValueError, match="short_side"):
        ProceduralConfig(short_side=(6.0, 19.0))


# ----------------------------------------------------------------------------- twin wings


def test_twin_wings_are_copies_up_to_small_details() -> None:
    """The east wing is the west wing turned by 180 degrees about the building's centre:
    the raster turned by 180 degrees agrees with itself over a wing in >= 95 % of cells,
    but not everywhere (the asymmetric details make the true alignment unique)."""
    world = world_of("twin_wings", 0)
    grid = ground_truth_map(world, RESOLUTION)
    width = 2.0 * buildings.TWIN_WING_WIDTH + buildings.TWIN_HALL_LENGTH
    xmin, ymin, xmax, ymax = grid.extent
    # The raster is centred on the building, so a half turn maps cells onto cells.
    assert (xmin + xmax) / 2.0 == pytest.approx(width / 2.0, abs=1e-6)
    assert (ymin + ymax) / 2.0 == pytest.approx(buildings.TWIN_WING_DEPTH / 2.0, abs=1e-6)
    turned = grid.cells[::-1, ::-1]
    west_wing = slice(0, round((buildings.TWIN_WING_WIDTH + 0.05 - xmin) / RESOLUTION))
    same = grid.cells[:, west_wing] == turned[:, west_wing]
    assert same.mean() >= 0.95
    # Walls, not just empty space, must match: most wall cells of the west wing are walls
    # of the turned east wing too.
    walls = grid.occupied[:, west_wing]
    assert np.count_nonzero(walls & same) >= 0.95 * np.count_nonzero(walls)
    assert not np.array_equal(grid.cells, turned)


def test_twin_wings_robots_start_at_symmetric_poses() -> None:
    first, second = world_of("twin_wings", 0).starts
    centre = np.array(
        [
            buildings.TWIN_WING_WIDTH + buildings.TWIN_HALL_LENGTH / 2.0,
            buildings.TWIN_WING_DEPTH / 2.0,
        ]
    )
    assert np.allclose(first[:2] + second[:2], 2.0 * centre)
    assert abs(math.remainder(first[2] - second[2] - math.pi, 2.0 * math.pi)) < 1e-9
