"""Tests for mrslam_env.sim.mapworld: simulator worlds from occupancy grids."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.sim.mapworld import (
    cover_rectangles,
    outline_segments,
    wall_mask,
    world_from_map,
)
from mrslam_env.sim.starts import START_MARGIN
from mrslam_env.sim.world import ground_truth_map

FR, OC, UN = FREE, OCCUPIED, UNKNOWN


def perimeter_edges(mask: np.ndarray) -> int:
    """Number of unit cell edges between a True cell and a False one (outside = False)."""
    padded = np.pad(np.asarray(mask, dtype=bool), 1)
    return int((padded[1:] != padded[:-1]).sum() + (padded[:, 1:] != padded[:, :-1]).sum())


def boundary_edge_set(mask: np.ndarray) -> set[tuple[int, int, int, int]]:
    """Slow reference: every boundary unit edge, oriented with the True cell on its left."""
    rows, cols = mask.shape

    def wall(r: int, c: int) -> bool:
        return 0 <= r < rows and 0 <= c < cols and bool(mask[r, c])

    edges = set()
    for r in range(rows + 1):
        for c in range(cols):
            below, above = wall(r - 1, c), wall(r, c)
            if above and not below:
                edges.add((c, r, c + 1, r))
            elif below and not above:
                edges.add((c + 1, r, c, r))
    for c in range(cols + 1):
        for r in range(rows):
            left, right = wall(r, c - 1), wall(r, c)
            if right and not left:
                edges.add((c, r + 1, c, r))
            elif left and not right:
                edges.add((c, r, c, r + 1))
    return edges


def split_into_unit_edges(segments: np.ndarray) -> list[tuple[int, int, int, int]]:
    edges = []
    for x0, y0, x1, y1 in segments.tolist():
        length = abs(x1 - x0) + abs(y1 - y0)
        assert (x0 == x1) != (y0 == y1), "segment must be axis-aligned and non-empty"
        dx, dy = np.sign(x1 - x0), np.sign(y1 - y0)
        edges += [
            (x0 + k * dx, y0 + k * dy, x0 + (k + 1) * dx, y0 + (k + 1) * dy) for k in range(length)
        ]
    return edges


def slack(grid: GridMap) -> float:
    """How far the start clearance estimate may exceed the exact clearance, m."""
    return (np.sqrt(0.5) - 0.5) * grid.resolution


def rooms_grid(rows: int = 60, cols: int = 80, origin: tuple[float, float] = (-2.0, 1.0)):
    """Two rooms joined by a door, a big block, a pillar, some speckle and unknown."""
    cells = np.full((rows, cols), FR, dtype=np.int8)
    cells[:2], cells[-2:], cells[:, :2], cells[:, -2:] = OC, OC, OC, OC
    cells[:, 40:42] = OC
    cells[34:52, 40:42] = FR  # door, 0.9 m: wide enough to plan through
    cells[10:30, 8:30] = OC  # big block
    cells[45, 60] = OC  # pillar
    cells[50:53, 10:14] = UN
    cells[5, 50], cells[6, 51] = OC, OC  # diagonal neighbours
    return GridMap(cells=cells, resolution=0.05, origin=origin)


# --------------------------------------------------------------------------------------
# Pure kernels


@pytest.mark.parametrize("seed", range(5))
def test_cover_rectangles_partition_the_mask(seed: int) -> None:
    rng = np.random.default_rng(seed)
    mask = rng.random((23, 31)) < [0.1, 0.5, 0.9, 0.3, 0.6][seed]
    rectangles = cover_rectangles(mask)
    painted = np.zeros(mask.shape, dtype=np.int64)
    for r0, c0, r1, c1 in rectangles:
        assert 0 <= r0 < r1 <= mask.shape[0] and 0 <= c0 < c1 <= mask.shape[1]
        painted[r0:r1, c0:c1] += 1
    np.testing.assert_array_equal(painted, mask.astype(np.int64))  # exact and disjoint


@pytest.mark.parametrize(
    ("mask", "expected"),
    [
        (np.zeros((3, 4), bool), []),
        (np.ones((3, 4), bool), [[0, 0, 3, 4]]),
        (np.eye(1, dtype=bool), [[0, 0, 1, 1]]),
        (np.array([[1, 1, 0], [1, 1, 0], [0, 1, 1]], bool), [[0, 0, 2, 2], [2, 1, 3, 3]]),
    ],
    ids=["empty", "full", "single", "L-shape"],
)
def test_cover_rectangles_edge_cases(mask: np.ndarray, expected: list) -> None:
    np.testing.assert_array_equal(
        cover_rectangles(mask).reshape(-1, 4), np.reshape(expected, (-1, 4))
    )


@pytest.mark.parametrize("seed", range(5))
def test_outline_matches_slow_reference(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    mask = rng.random((17, 13)) < 0.45
    segments = outline_segments(mask)
    edges = split_into_unit_edges(segments)
    assert len(edges) == len(set(edges)) == perimeter_edges(mask)
    assert set(edges) == boundary_edge_set(mask)


def test_outline_runs_are_maximal() -> None:
    mask = np.zeros((5, 7), dtype=bool)
    mask[1:4, 1:6] = True
    segments = outline_segments(mask)
    # A 5 x 3 block: exactly 4 segments, ccw around the block.
    assert sorted(map(tuple, segments.tolist())) == sorted(
        [(1, 1, 6, 1), (6, 1, 6, 4), (6, 4, 1, 4), (1, 4, 1, 1)]
    )


def test_outline_splits_where_the_wall_side_flips() -> None:
    mask = np.array([[1, 0], [0, 1]], dtype=bool)  # the line y = 1 has walls below, then above
    segments = {tuple(s) for s in outline_segments(mask).tolist()}
    assert (1, 1, 0, 1) in segments and (1, 1, 2, 1) in segments
    assert perimeter_edges(mask) == 8 == sum(abs(a - c) + abs(b - d) for a, b, c, d in segments)


def test_kernels_do_not_mutate_input() -> None:
    mask = np.random.default_rng(3).random((9, 9)) < 0.5
    before = mask.copy()
    cover_rectangles(mask)
    outline_segments(mask)
    np.testing.assert_array_equal(mask, before)


# --------------------------------------------------------------------------------------
# world_from_map


def test_ground_truth_reproduces_the_wall_mask() -> None:
    grid = rooms_grid()
    world = world_from_map(grid, name="rooms")
    truth = ground_truth_map(world, grid.resolution)
    offset = (np.asarray(grid.origin) - np.asarray(truth.origin)) / grid.resolution
    np.testing.assert_allclose(offset, np.round(offset), atol=1e-6)  # same cell lattice
    col, row = np.round(offset).astype(int)
    rows, cols = grid.shape
    inside = truth.cells[row : row + rows, col : col + cols]
    np.testing.assert_array_equal(inside == OC, wall_mask(grid))
    # The one-cell frame is wall all round.
    frame = truth.cells[row - 1 : row + rows + 1, col - 1 : col + cols + 1].copy()
    frame[1:-1, 1:-1] = OC
    assert (frame == OC).all()


def test_unknown_as_wall_false_opens_unknown_cells() -> None:
    grid = rooms_grid()
    world = world_from_map(grid, name="rooms", unknown_as_wall=False)
    truth = ground_truth_map(world, grid.resolution)
    col, row = np.round((np.asarray(grid.origin) - truth.origin) / grid.resolution).astype(int)
    inside = truth.cells[row : row + grid.shape[0], col : col + grid.shape[1]]
    np.testing.assert_array_equal(inside == OC, grid.cells == OC)
    assert (inside[50:53, 10:14] == FR).all()


def test_bounds_are_grid_extent_plus_frame() -> None:
    grid = rooms_grid()
    world = world_from_map(grid, name="rooms")
    xmin, ymin, xmax, ymax = grid.extent
    r = grid.resolution
    np.testing.assert_allclose(world.bounds, [xmin - r, ymin - r, xmax + r, ymax + r], atol=1e-12)
    corners = world.walls.reshape(-1, 2)
    np.testing.assert_allclose(corners.min(axis=0), [xmin - r, ymin - r], atol=1e-12)
    np.testing.assert_allclose(corners.max(axis=0), [xmax + r, ymax + r], atol=1e-12)


def test_few_rectangles_for_big_blocks() -> None:
    cells = np.full((200, 200), FR, dtype=np.int8)
    cells[20:120, 30:90] = OC
    cells[150:190, 100:195] = OC
    cells[:, 140:145] = OC
    grid = GridMap(cells=cells, resolution=0.1)
    world = world_from_map(grid, name="blocks")
    wall_cells = int(wall_mask(grid).sum())
    assert wall_cells > 10_000
    assert len(world.walls) <= 20


def test_outline_length_equals_wall_perimeter() -> None:
    grid = rooms_grid()
    world = world_from_map(grid, name="rooms")
    framed = np.pad(wall_mask(grid), 1, constant_values=True)
    seg = world.segments
    total = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]).sum()
    np.testing.assert_allclose(total, perimeter_edges(framed) * grid.resolution, rtol=1e-12)
    assert np.all((seg[:, 0] == seg[:, 2]) | (seg[:, 1] == seg[:, 3]))  # axis-aligned


def test_walls_are_counter_clockwise_rectangles() -> None:
    world = world_from_map(rooms_grid(), name="rooms")
    w = world.walls
    area2 = np.sum(w[..., 0] * np.roll(w[..., 1], -1, 1) - np.roll(w[..., 0], -1, 1) * w[..., 1], 1)
    assert np.all(area2 > 0)
    edges = np.roll(w, -1, axis=1) - w
    assert np.all(np.abs(edges).min(axis=2) == 0)  # axis-aligned


def test_input_grid_not_mutated() -> None:
    grid = rooms_grid()
    before = grid.cells.copy()
    world_from_map(grid, name="rooms")
    np.testing.assert_array_equal(grid.cells, before)


def test_auto_starts_are_free_far_apart_with_clearance() -> None:
    grid = rooms_grid()
    radius = 0.2
    world = world_from_map(grid, name="rooms", robot_radius=radius, rng=np.random.default_rng(7))
    starts = world.starts
    assert starts.shape == (2, 3)
    cells = grid.world_to_cell(starts[:, :2])
    assert grid.contains(cells).all()
    assert (grid.cells[cells[:, 0], cells[:, 1]] == FR).all()
    assert np.all(world.clearance(starts[:, :2]) >= radius + START_MARGIN - slack(grid) - 1e-9)
    assert abs(starts[0, 2] - starts[1, 2]) > 1.0  # different headings
    assert np.all((starts[:, 2] > -np.pi) & (starts[:, 2] <= np.pi))
    # Far apart: at least half the diagonal of the map.
    diagonal = np.hypot(grid.shape[0], grid.shape[1]) * grid.resolution
    assert np.linalg.norm(starts[0, :2] - starts[1, :2]) > 0.5 * diagonal


def test_auto_starts_stay_in_largest_region() -> None:
    cells = np.full((40, 80), FR, dtype=np.int8)
    cells[:, 20:22] = OC  # a small room (left, 20 cols) and a big one (right, 58 cols)
    grid = GridMap(cells=cells, resolution=0.05)
    world = world_from_map(grid, name="split", n_starts=3, robot_radius=0.1)
    assert world.starts.shape == (3, 3)
    assert np.all(world.starts[:, 0] > 22 * 0.05)
    assert len(np.unique(np.round(world.starts[:, 2], 9))) == 3


def test_auto_starts_are_deterministic_given_rng() -> None:
    grid = rooms_grid()
    a = world_from_map(grid, name="r", rng=np.random.default_rng(11)).starts
    b = world_from_map(grid, name="r", rng=np.random.default_rng(11)).starts
    c = world_from_map(grid, name="r").starts
    d = world_from_map(grid, name="r").starts
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(c, d)


def test_given_starts_are_kept() -> None:
    grid = rooms_grid()
    starts = [[-1.0, 3.2, 0.5], [1.0, 2.0, -3.0]]
    world = world_from_map(grid, name="r", starts=starts)
    np.testing.assert_array_equal(world.starts, starts)


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ((-1.0, 1.05, 0.0), "lies inside a wall"),  # in the bottom wall rows
        ((-1.0, 2.0, 0.0), "lies inside a wall"),  # in the big block
        ((-1.88, 2.5, 0.0), r"is 0\.020 m from a wall, closer than the robot radius 0\.2"),
        ((-5.0, 2.5, 0.0), "lies outside the map"),
        ((1.0, 1.0 + 60 * 0.05 + 0.02, 0.0), "lies outside the map"),  # in the frame
    ],
)
def test_bad_starts_raise_naming_index_and_pose(bad: tuple, message: str) -> None:
    grid = rooms_grid()
    starts = [[-1.0, 3.2, 0.5], bad]
    with pytest.raises(ValueError, match=r"start 1 at \(x, y, theta\) = \(.+\) " + message):
        world_from_map(grid, name="r", starts=starts)


def test_malformed_starts_raise() -> None:
    grid = rooms_grid()
    with pytest.raises(ValueError, match="shape"):
        world_from_map(grid, name="r", starts=[[1.0, 2.0]])
    with pytest.raises(ValueError, match="finite"):
        world_from_map(grid, name="r", starts=[[np.nan, 2.0, 0.0]])


@pytest.mark.parametrize("fill", [OC, UN])
def test_map_without_free_space_raises(fill: np.int8) -> None:
    grid = GridMap(cells=np.full((10, 10), fill, dtype=np.int8), resolution=0.1)
    with pytest.raises(ValueError, match="no free space"):
        world_from_map(grid, name="solid")


def test_unknown_only_map_has_no_free_start() -> None:
    grid = GridMap(cells=np.full((30, 30), UN, dtype=np.int8), resolution=0.1)
    with pytest.raises(ValueError, match="no free space"):
        world_from_map(grid, name="fog", unknown_as_wall=False)


def test_map_too_narrow_for_starts_raises() -> None:
    cells = np.full((30, 30), OC, dtype=np.int8)
    cells[10:13, 5:25] = FR  # a corridor 0.15 m wide
    grid = GridMap(cells=cells, resolution=0.05)
    with pytest.raises(ValueError, match=r"radius 0\.2"):
        world_from_map(grid, name="narrow")


def test_auto_starts_keep_the_start_clearance_among_pillars() -> None:
    # The start clearance rule (mrslam_env.sim.starts), against exact clearance.
    rng = np.random.default_rng(5)
    cells = np.where(rng.random((40, 40)) < 0.01, OC, FR).astype(np.int8)
    cells = np.where(ndimage.binary_dilation(cells == OC), OC, FR).astype(np.int8)
    grid = GridMap(cells=cells, resolution=0.05, origin=(0.3, -0.7))
    world = world_from_map(grid, name="pillars", robot_radius=0.05)
    for seed in range(3):
        starts = world_from_map(
            grid, name="pillars", n_starts=4, robot_radius=0.1, rng=np.random.default_rng(seed)
        ).starts
        clearance = world.clearance(starts[:, :2])
        assert np.all(clearance >= 0.1 + START_MARGIN - slack(grid) - 1e-9)
