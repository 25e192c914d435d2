"""Real buildings as worlds: map cleaning for simulation and the six shipped maps."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.mapio import load_map
from mrslam_env.registry import build_world
from mrslam_env.sim.cleaning import clean_for_simulation
from mrslam_env.sim.world import ground_truth_map
from scenarios.worlds.real import REAL_BUILDINGS, map_file

RES = 0.05


def room() -> np.ndarray:
    """A 4 x 3 m room (walls one cell thick) inside unknown space, 0.05 m cells."""
    cells = np.full((80, 100), UNKNOWN, dtype=np.int8)
    cells[10:70, 10:90] = OCCUPIED
    cells[11:69, 11:89] = FREE
    return cells


def clean(cells: np.ndarray, **kwargs) -> np.ndarray:
    grid = GridMap(cells=cells, resolution=RES, origin=(0.0, 0.0))
    return clean_for_simulation(grid, **kwargs).cells


def test_a_clean_room_is_unchanged_and_the_input_is_not_mutated() -> None:
    cells = room()
    before = cells.copy()
    np.testing.assert_array_equal(clean(cells), before)
    np.testing.assert_array_equal(cells, before)


def test_a_ray_streak_through_a_wall_gap_is_removed() -> None:
    cells = room()
    cells[40, 89:100] = FREE  # beams through a one-cell gap marked free cells outside
    cleaned = clean(cells)
    assert (cleaned[40, 90:100] == UNKNOWN).all()
    assert (cleaned[11:69, 11:89] == FREE).all()


def test_free_space_the_robot_cannot_reach_is_removed() -> None:
    cells = room()
    cells[30:50, 60:62] = OCCUPIED  # a closed closet in the corner region
    cells[30:50, 60:80] = OCCUPIED
    cells[31:49, 61:79] = FREE
    cleaned = clean(cells)
    assert (cleaned[31:49, 61:79] == UNKNOWN).all()
    assert cleaned[20, 20] == FREE


def test_speckle_in_open_floor_goes_but_obstacles_and_wall_bumps_stay() -> None:
    cells = room()
    cells[40, 40] = OCCUPIED  # a single noise cell: 0.0025 m²
    cells[20:23, 30:33] = OCCUPIED  # a 15 cm post: a real obstacle
    cells[11, 50] = OCCUPIED  # a bump on the wall: touches the wall, kept
    cleaned = clean(cells)
    assert cleaned[40, 40] == FREE
    assert (cleaned[20:23, 30:33] == OCCUPIED).all()
    assert cleaned[11, 50] == OCCUPIED
    assert clean(cells, speckle_area=0.0)[40, 40] == OCCUPIED


def test_a_map_without_room_for_the_robot_is_refused() -> None:
    cells = np.full((20, 20), OCCUPIED, dtype=np.int8)
    cells[5:15, 9:11] = FREE  # 0.1 m wide: no 0.2 m robot fits
    with pytest.raises(ValueError, match=r"no floor where a robot of radius 0\.2 m fits"):
        clean(cells)
    with pytest.raises(ValueError, match=r"robot_radius must be > 0 m"):
        clean(room(), robot_radius=0.0)


@pytest.mark.parametrize("name", sorted(REAL_BUILDINGS))
def test_each_real_building_is_a_closed_world_of_its_stated_size(name: str) -> None:
    world = build_world(name)
    source = load_map(map_file(name))
    assert source.resolution in (0.02, 0.05)
    raster = ground_truth_map(world, 0.1, margin=0.5)
    # Stated size: the known area's extent, to the metre.
    width, height = (float(v) for v in REAL_BUILDINGS[name].rsplit("(", 1)[1][:-3].split(" x "))
    known = np.argwhere(source.cells != UNKNOWN)
    extent = (known.max(axis=0) - known.min(axis=0) + 1) * source.resolution
    assert abs(extent[1] - width) <= 1.0 and abs(extent[0] - height) <= 1.0
    # Two starts on the free floor, and the floor around them is closed: its free
    # component (8-connected, the stricter choice) never reaches the raster's border.
    assert world.starts.shape == (2, 3)
    cells = raster.world_to_cell(world.starts[:, :2])
    assert (raster.cells[cells[:, 0], cells[:, 1]] == FREE).all()
    labels, _ = ndimage.label(raster.free, structure=np.ones((3, 3), dtype=bool))
    building = np.isin(labels, labels[cells[:, 0], cells[:, 1]])
    assert not (building[0].any() or building[-1].any())
    assert not (building[:, 0].any() or building[:, -1].any())
    assert world.description == REAL_BUILDINGS[name]


def test_real_buildings_are_listed_with_their_size(capsys) -> None:
    from scenarios.cli import main

    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    for name in REAL_BUILDINGS:
        line = next(row for row in out.splitlines() if row.startswith(name + " "))
        assert "real building" in line and " m)" in line
