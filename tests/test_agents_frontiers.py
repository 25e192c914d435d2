"""Frontier extraction (agents.frontiers): cells, clusters, goals, information gain."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from agents.frontiers import (
    FrontierConfig,
    _clear_specks,
    _components,
    _dilated_inside,
    _nearest_feature_at,
    _open_square,
    _touched_in_squares,
    cluster_frontiers,
    connected_information_gain,
    extract_frontiers,
    frontier_cells,
    information_gain,
    known_integral_image,
)
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap

RESOLUTION = 0.05


def room_with_door(door_width: float = 1.0) -> GridMap:
    """A 4 m x 3 m room (walls one cell thick) inside a 6 m x 5 m grid; a doorway in
    the east wall opens onto unknown space. Known: the room and its walls only."""
    cells = np.full((100, 120), UNKNOWN, dtype=np.int8)
    top, bottom, left, right = 80, 20, 20, 100  # rows/cols of the walls
    cells[bottom : top + 1, left : right + 1] = OCCUPIED
    cells[bottom + 1 : top, left + 1 : right] = FREE
    half = round(door_width / RESOLUTION / 2)
    middle = (top + bottom) // 2
    cells[middle - half : middle + half, right] = FREE  # the doorway itself is free
    return GridMap(cells=cells, resolution=RESOLUTION, origin=(0.0, 0.0))


def test_a_room_with_an_open_door_has_one_frontier_at_the_door() -> None:
    grid = room_with_door(door_width=1.0)
    frontiers = extract_frontiers(grid)
    assert len(frontiers) == 1
    door_x = (100 + 0.5) * RESOLUTION
    door_y = 50 * RESOLUTION
    assert frontiers.centroids[0] == pytest.approx([door_x, door_y], abs=0.06)
    assert frontiers.sizes[0] == pytest.approx(1.0, abs=0.06)
    goal_cell = frontiers.goal_cells[0]
    assert grid.free[goal_cell[0], goal_cell[1]]
    assert np.hypot(*(frontiers.goals[0] - [door_x, door_y])) < 0.1
    # The gain is what one sees through a 1 m opening: capped at size x view_depth,
    # although much more unknown space lies behind the door.
    config = FrontierConfig()
    assert frontiers.gains[0] == pytest.approx(frontiers.sizes[0] * config.view_depth)
    uncapped = extract_frontiers(grid, FrontierConfig(view_depth=100.0))
    assert uncapped.gains[0] > 10.0


def test_a_fully_known_map_and_an_unknown_map_have_no_frontiers() -> None:
    known = np.full((30, 30), FREE, dtype=np.int8)
    known[[0, -1], :] = OCCUPIED
    known[:, [0, -1]] = OCCUPIED
    assert len(extract_frontiers(GridMap(cells=known, resolution=RESOLUTION))) == 0
    unknown = np.full((30, 30), UNKNOWN, dtype=np.int8)
    grid = GridMap(cells=unknown, resolution=RESOLUTION)
    assert not frontier_cells(grid).any()
    assert len(extract_frontiers(grid)) == 0


def test_free_cells_on_the_grid_border_are_frontier_cells() -> None:
    # The SLAM grid only covers what was seen; outside it is unknown.
    grid = GridMap(cells=np.full((10, 10), FREE, dtype=np.int8), resolution=RESOLUTION)
    cells = frontier_cells(grid)
    border = np.ones((10, 10), dtype=bool)
    border[1:-1, 1:-1] = False
    np.testing.assert_array_equal(cells, border)


def test_connectivity_four_ignores_corner_contact() -> None:
    cells = np.full((5, 5), OCCUPIED, dtype=np.int8)
    cells[1:4, 1:4] = FREE
    cells[0, 0] = UNKNOWN  # touches free cell (1, 1) only at a corner
    grid = GridMap(cells=cells, resolution=RESOLUTION)
    config4 = FrontierConfig(connectivity=4, min_unknown_area=0.0)
    config8 = FrontierConfig(connectivity=8, min_unknown_area=0.0)
    assert not frontier_cells(grid, config4).any()
    assert np.argwhere(frontier_cells(grid, config8)).tolist() == [[1, 1]]


def test_unknown_specks_inside_mapped_space_make_no_frontier() -> None:
    cells = np.full((40, 40), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[20, 20] = UNKNOWN  # one cell: a beam gap, not a place to explore
    grid = GridMap(cells=cells, resolution=RESOLUTION)
    assert not frontier_cells(grid).any()
    assert frontier_cells(grid, FrontierConfig(min_unknown_area=0.0)).sum() == 4


def test_speck_removal_matches_labelling_by_the_3x3_square() -> None:
    rng = np.random.default_rng(3)
    for _ in range(40):
        unknown = rng.random((rng.integers(3, 50), rng.integers(3, 50))) < 0.45
        unknown = np.pad(unknown, 1, constant_values=True)
        min_cells = float(rng.integers(2, 30))
        labels, count = ndimage.label(unknown, structure=np.ones((3, 3), dtype=bool))
        keep = np.bincount(labels.ravel(), minlength=count + 1) >= min_cells
        keep[0] = False
        keep[labels[0, 0]] = True
        cleared = unknown.copy()
        _clear_specks(cleared, min_cells)
        assert np.array_equal(cleared, keep[labels])


def test_components_are_scipys_labels_grouped_in_row_major_order() -> None:
    rng = np.random.default_rng(8)
    for trial in range(200):
        shape = (int(rng.integers(1, 70)), int(rng.integers(1, 70)))
        cells = rng.random(shape) < rng.uniform(0.02, 0.6)
        if trial % 5 == 0:  # thin lines, as frontiers are
            cells = cells & ~ndimage.binary_erosion(cells)
        labels, count = ndimage.label(cells, structure=np.ones((3, 3), dtype=bool))
        rows, cols, bounds, found = _components(cells)
        assert found == count and len(bounds) == count + 1 and bounds[-1] == cells.sum()
        for k in range(count):
            own = np.argwhere(labels == k + 1)  # row-major
            np.testing.assert_array_equal(rows[bounds[k] : bounds[k + 1]], own[:, 0])
            np.testing.assert_array_equal(cols[bounds[k] : bounds[k + 1]], own[:, 1])


def test_touched_counts_from_the_summed_area_table_match_the_cell_loop() -> None:
    rng = np.random.default_rng(5)
    regions = rng.integers(0, 4, (30, 40)).astype(np.int32)
    touches = np.zeros((12, 4), dtype=bool)
    touches[:, 2] = True
    touches[::3, 1] = True  # a third touch another region too: the loop
    centres = rng.integers(-5, 45, (12, 2))
    with_table = _touched_in_squares(regions, touches, centres, 6, 2)
    by_loop = _touched_in_squares(regions, touches, centres, 6, 0)  # no outside: no table
    assert np.array_equal(with_table[0], by_loop[0])
    assert np.array_equal(with_table[1], by_loop[1])
    assert with_table[0].sum() > 0


def test_long_frontiers_are_split_into_pieces_no_longer_than_max_size() -> None:
    cells = np.zeros((20, 250), dtype=bool)
    cells[10, 10:210] = True  # a 10 m straight frontier
    config = FrontierConfig(max_size=3.0)
    labels, count = cluster_frontiers(cells, RESOLUTION, config)
    assert count == 4
    for label in range(1, count + 1):
        piece = np.argwhere(labels == label)
        assert len(piece) * RESOLUTION <= 3.0 + 1e-9
        # Each piece is one contiguous run of the line.
        assert np.ptp(piece[:, 1]) == len(piece) - 1
    assert (labels > 0).sum() == 200


def test_one_cell_wide_free_streaks_make_no_frontier() -> None:
    # A beam through a gap in a wall leaves a FREE streak in unknown space.
    cells = np.full((40, 60), UNKNOWN, dtype=np.int8)
    cells[5:35, 5:30] = FREE
    cells[20, 30:55] = FREE  # the streak
    grid = GridMap(cells=cells, resolution=RESOLUTION)
    streak = frontier_cells(grid)[20, 32:55]
    assert not streak.any()
    assert frontier_cells(grid, FrontierConfig(min_free_width=1))[20, 32:55].all()


def test_small_frontiers_are_dropped() -> None:
    cells = np.zeros((20, 20), dtype=bool)
    cells[5, 5:7] = True  # 0.1 m
    cells[10, 2:18] = True  # 0.8 m
    labels, count = cluster_frontiers(cells, RESOLUTION, FrontierConfig(min_size=0.25))
    assert count == 1
    assert (labels > 0).sum() == 16


def test_information_gain_matches_a_brute_force_count() -> None:
    rng = np.random.default_rng(3)
    values = rng.choice([FREE, OCCUPIED, UNKNOWN], size=(37, 53), p=[0.5, 0.2, 0.3])
    grid = GridMap(cells=values.astype(np.int8), resolution=0.1, origin=(-1.0, 2.0))
    points = np.column_stack([rng.uniform(-2.0, 5.0, 30), rng.uniform(1.0, 7.0, 30)])
    sensor_range = 0.75
    gains = information_gain(grid, points, sensor_range)
    half = round(sensor_range / grid.resolution)
    padded = np.pad(grid.unknown, 40, constant_values=True)
    for point, gain in zip(points, gains, strict=True):
        row, col = grid.world_to_cell(point) + 40
        box = padded[row - half : row + half + 1, col - half : col + half + 1]
        assert gain == pytest.approx(box.sum() * grid.resolution**2)
    table = known_integral_image(grid)
    assert table[-1, -1] == (~grid.unknown).sum()


def test_connected_gain_ignores_unknown_space_behind_walls() -> None:
    # Left half: mapped room with a frontier onto a small unknown pocket; a wall then
    # separates it from a large unknown area on the right.
    cells = np.full((40, 80), FREE, dtype=np.int8)
    cells[:, 40] = OCCUPIED
    cells[:, 41:] = UNKNOWN
    cells[15:25, 30:40] = UNKNOWN  # the pocket the frontier opens onto: 100 cells
    grid = GridMap(cells=cells, resolution=0.1)
    labels = np.zeros(grid.shape, dtype=np.int32)
    labels[14, 30:40] = 1  # the frontier cells below the pocket
    point = grid.cell_to_world(np.array([[14, 35]]))
    box_gain = information_gain(grid, point, 2.0)[0]
    connected_gain = connected_information_gain(grid, labels, point, 2.0)[0]
    assert connected_gain == pytest.approx(100 * 0.01)
    assert box_gain > 3 * connected_gain


def test_connected_gain_is_zero_for_the_inside_of_an_obstacle() -> None:
    # A pillar mapped as an outline with a one-cell gap: its unknown inside is no goal.
    cells = np.full((40, 40), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[15:25, 15:25] = OCCUPIED
    cells[16:24, 16:24] = UNKNOWN
    cells[20, 15] = FREE  # the gap
    grid = GridMap(cells=cells, resolution=0.1)
    labels = np.zeros(grid.shape, dtype=np.int32)
    labels[20, 15] = 1
    point = grid.cell_to_world(np.array([[20, 12]]))
    closed = connected_information_gain(grid, labels, point, 2.0, min_open_fraction=0.15)
    open_ = connected_information_gain(grid, labels, point, 2.0, min_open_fraction=0.0)
    assert closed[0] == 0.0
    assert open_[0] == pytest.approx(64 * 0.01)


def test_unreachable_frontiers_are_dropped_and_goals_are_reachable() -> None:
    grid = room_with_door()
    reachable = np.zeros(grid.shape, dtype=bool)
    assert len(extract_frontiers(grid, reachable=reachable)) == 0
    reachable[40:60, 60:80] = True  # a patch 1 m west of the door
    frontiers = extract_frontiers(grid, FrontierConfig(max_goal_offset=1.5), reachable=reachable)
    assert len(frontiers) == 1
    row, col = frontiers.goal_cells[0]
    assert reachable[row, col]
    assert col == 79  # the reachable cell closest to the door
    far = extract_frontiers(grid, FrontierConfig(max_goal_offset=0.5), reachable=reachable)
    assert len(far) == 0


def strip_behind_a_wall(strip_from_row: int) -> tuple[GridMap, np.ndarray]:
    """A 4 m x 4 m map (0.05 m cells) walled at rows 0 and 79 and column 0: a wall along
    column 45, FREE on both sides up to column 59, UNKNOWN from column 60 (the frontier
    is column 59, in two pieces). Reachable: the left side up to column 43 (the wall's
    inflation beyond), and the strip between the wall and the frontier only from row
    ``strip_from_row`` (clutter below)."""
    cells = np.full((80, 80), UNKNOWN, dtype=np.int8)
    cells[:, :60] = FREE
    cells[:, 45] = OCCUPIED
    cells[[0, -1], :60] = OCCUPIED
    cells[:, 0] = OCCUPIED
    reachable = np.zeros(cells.shape, dtype=bool)
    reachable[1:-1, 1:44] = True
    reachable[strip_from_row:-1, 46:59] = True
    return GridMap(cells=cells, resolution=0.05), reachable


def test_a_frontier_is_seen_from_its_goal_not_through_a_wall() -> None:
    # The lower frontier piece (rows 0-39) is nearest to the left room (0.8 m, across the
    # wall); a robot there would reach its goal and never see it. Its goal is the nearest
    # reachable cell that sees it: in the strip, 1.0 m up from the piece's middle.
    grid, reachable = strip_behind_a_wall(strip_from_row=40)
    frontiers = extract_frontiers(grid, FrontierConfig(max_goal_offset=1.5), reachable=reachable)
    assert len(frontiers) == 2
    for index in range(len(frontiers)):
        row, col = frontiers.goal_cells[index]
        assert reachable[row, col]
        assert col > 45  # the frontier's side of the wall
    lower = int(np.argmin(frontiers.centroids[:, 1]))
    assert tuple(frontiers.goal_cells[lower]) == (40, 58)
    # No reachable cell within max_goal_offset sees the lower piece: it is dropped.
    grid, reachable = strip_behind_a_wall(strip_from_row=72)
    frontiers = extract_frontiers(grid, FrontierConfig(max_goal_offset=1.5), reachable=reachable)
    assert len(frontiers) == 1
    assert frontiers.centroids[0, 1] > grid.cell_to_world(np.array([[40, 0]]))[0, 1]
    assert frontiers.goal_cells[0, 1] > 45


def test_extraction_does_not_modify_the_map() -> None:
    grid = room_with_door()
    before = grid.cells.copy()
    extract_frontiers(grid)
    np.testing.assert_array_equal(grid.cells, before)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("connectivity", 6),
        ("min_size", -1.0),
        ("sensor_range", 0.0),
        ("max_goal_offset", float("nan")),
        ("gain_model", "cone"),
        ("min_open_fraction", 2.0),
        ("view_depth", 0.0),
        ("min_free_width", 0),
    ],
)
def test_config_rejects_bad_values_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        FrontierConfig(**{field: value})  # type: ignore[arg-type]


def test_config_needs_max_size_above_min_size() -> None:
    with pytest.raises(ValueError, match="max_size"):
        FrontierConfig(min_size=2.0, max_size=1.0)


def test_reachable_mask_of_the_wrong_shape_is_rejected() -> None:
    with pytest.raises(ValueError, match="reachable"):
        extract_frontiers(room_with_door(), reachable=np.ones((3, 3), dtype=bool))


@pytest.mark.parametrize("width", [1, 3, 5])
def test_the_square_opening_is_scipys(width: int) -> None:
    # The frontier step's own opening (odd widths) against ndimage.binary_opening, on
    # masks from sparse to dense, touching the border.
    rng = np.random.default_rng(width)
    for density in (0.3, 0.6, 0.85, 0.97):
        for _ in range(25):
            mask = rng.random((int(rng.integers(1, 30)), int(rng.integers(1, 30)))) < density
            expected = ndimage.binary_opening(mask, structure=np.ones((width, width), dtype=bool))
            np.testing.assert_array_equal(_open_square(mask, width // 2), expected)


def test_the_nearest_feature_is_scipys_ties_included() -> None:
    # The goal step's nearest reachable cell against ndimage's feature transform, at all
    # cells and at random subsets, on masks from one cell to dense, with many ties.
    rng = np.random.default_rng(7)
    for density in (0.005, 0.05, 0.3, 0.9):
        for _ in range(60):
            shape = (int(rng.integers(1, 35)), int(rng.integers(1, 35)))
            features = rng.random(shape) < density
            features[tuple(rng.integers(0, shape))] = True
            rows, cols = ndimage.distance_transform_edt(
                ~features, return_distances=False, return_indices=True
            )
            everywhere = np.argwhere(np.ones(shape, dtype=bool))
            some = everywhere[rng.random(len(everywhere)) < rng.random()]
            for cells in (everywhere, some):
                expected = np.stack([rows[tuple(cells.T)], cols[tuple(cells.T)]], axis=1)
                np.testing.assert_array_equal(_nearest_feature_at(features, cells), expected)


def test_long_frontier_pieces_and_goals_do_not_depend_on_where_the_map_lies() -> None:
    # The same room placed at another offset in a larger grid: the same frontiers,
    # shifted (the clustering works in each component's own box).
    grid = room_with_door(2.5)
    config = FrontierConfig(max_size=0.5)
    base = extract_frontiers(grid, config)
    cells = np.full((160, 190), UNKNOWN, dtype=np.int8)
    cells[37:137, 51:171] = grid.cells
    moved = extract_frontiers(GridMap(cells=cells, resolution=RESOLUTION), config)
    assert len(base) > 3 and len(moved) == len(base)
    np.testing.assert_array_equal(moved.goal_cells, base.goal_cells + np.array([37, 51]))
    np.testing.assert_array_equal(moved.sizes, base.sizes)
    np.testing.assert_array_equal(moved.labels[37:137, 51:171], base.labels)


@pytest.mark.parametrize("corners", [False, True])
def test_the_dilation_next_to_unknown_is_scipys(corners: bool) -> None:
    rng = np.random.default_rng(11)
    structure = ndimage.generate_binary_structure(2, 2 if corners else 1)
    for density in (0.02, 0.2, 0.6):
        for _ in range(40):
            padded = rng.random((int(rng.integers(2, 30)), int(rng.integers(2, 30)))) < density
            expected = ndimage.binary_dilation(padded, structure=structure)[1:-1, 1:-1]
            np.testing.assert_array_equal(_dilated_inside(padded, corners), expected)
