"""GridMap, WorldSpec and the ground-truth rasteriser (mrslam_env.gridmap, mrslam_env.sim.world)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.sim.world import (
    WorldSpec,
    box,
    ground_truth_map,
    polygon_edges,
    polyline_walls,
    thick_segment,
)


def world_of(*walls: np.ndarray, starts=((0.0, 0.0, 0.0),)) -> WorldSpec:
    return WorldSpec.from_walls("test", list(walls), starts)


def occupied_set(grid: GridMap) -> set[tuple[int, int]]:
    return {(int(r), int(c)) for r, c in np.argwhere(grid.occupied)}


# --- GridMap -----------------------------------------------------------------------------


def test_gridmap_accepts_the_three_states_and_exposes_views() -> None:
    cells = np.array([[FREE, OCCUPIED], [UNKNOWN, FREE], [OCCUPIED, OCCUPIED]], dtype=np.int8)
    grid = GridMap(cells=cells, resolution=0.5, origin=(1, -2))
    assert grid.shape == (3, 2)
    assert grid.origin == (1.0, -2.0)
    assert isinstance(grid.origin[0], float)
    assert grid.extent == (1.0, -2.0, 2.0, -0.5)
    np.testing.assert_array_equal(grid.free, cells == 0)
    np.testing.assert_array_equal(grid.occupied, cells == 100)
    np.testing.assert_array_equal(grid.unknown, cells == -1)
    np.testing.assert_array_equal(grid.world_to_cell([1.6, -0.6]), [2, 1])
    np.testing.assert_allclose(grid.cell_to_world([2, 1]), [1.75, -0.75])
    np.testing.assert_array_equal(
        grid.contains(np.array([[0, 0], [2, 1], [3, 0], [0, 2], [-1, 0], [0, -1]])),
        [True, True, False, False, False, False],
    )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"cells": np.zeros(4, dtype=np.int8), "resolution": 0.1}, "2-D"),
        ({"cells": np.zeros((2, 2, 2), dtype=np.int8), "resolution": 0.1}, "2-D"),
        ({"cells": np.zeros((2, 2), dtype=np.int16), "resolution": 0.1}, "int8"),
        ({"cells": np.zeros((2, 2), dtype=np.uint8), "resolution": 0.1}, "int8"),
        ({"cells": np.full((2, 2), 50, dtype=np.int8), "resolution": 0.1}, "50"),
        ({"cells": np.zeros((2, 2), dtype=np.int8), "resolution": 0.0}, "resolution"),
        ({"cells": np.zeros((2, 2), dtype=np.int8), "resolution": -0.1}, "resolution"),
        ({"cells": np.zeros((2, 2), dtype=np.int8), "resolution": math.nan}, "resolution"),
        ({"cells": np.zeros((2, 2), dtype=np.int8), "resolution": math.inf}, "resolution"),
        (
            {"cells": np.zeros((2, 2), dtype=np.int8), "resolution": 0.1, "origin": (0.0,)},
            "origin",
        ),
        (
            {
                "cells": np.zeros((2, 2), dtype=np.int8),
                "resolution": 0.1,
                "origin": (0.0, math.nan),
            },
            "origin",
        ),
    ],
)
def test_gridmap_validation(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        GridMap(**kwargs)


# --- wall geometry -----------------------------------------------------------------------


def test_box_is_counter_clockwise_and_order_independent() -> None:
    b = box(3.0, 2.0, 1.0, 0.0)
    np.testing.assert_array_equal(b, [[1, 0], [3, 0], [3, 2], [1, 2]])
    area2 = np.sum(b[:, 0] * np.roll(b[:, 1], -1) - np.roll(b[:, 0], -1) * b[:, 1])
    assert area2 == pytest.approx(8.0)


def test_thick_segment_geometry() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        p, q = rng.uniform(-5.0, 5.0, (2, 2))
        thickness = rng.uniform(0.01, 0.5)
        quad = thick_segment(p, q, thickness)
        length = float(np.hypot(*(q - p)))
        u = (q - p) / length
        n = np.array([-u[1], u[0]])
        # A rectangle centred on the segment's midpoint, extended by thickness/2 at both ends.
        centre = (p + q) / 2
        along = (quad - centre) @ u
        across = (quad - centre) @ n
        np.testing.assert_allclose(np.abs(along), (length + thickness) / 2, atol=1e-12)
        np.testing.assert_allclose(np.abs(across), thickness / 2, atol=1e-12)
        edge_lengths = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1)
        np.testing.assert_allclose(edge_lengths, [length + thickness, thickness] * 2, atol=1e-12)
        # Counter-clockwise (positive area) and equal to length * thickness... plus the caps.
        area2 = np.sum(quad[:, 0] * np.roll(quad[:, 1], -1) - np.roll(quad[:, 0], -1) * quad[:, 1])
        assert area2 / 2 == pytest.approx((length + thickness) * thickness, rel=1e-9)


def test_thick_segment_known_values_and_zero_length() -> None:
    quad = thick_segment([0.0, 0.0], [2.0, 0.0], 0.2)
    np.testing.assert_allclose(quad, [[-0.1, -0.1], [2.1, -0.1], [2.1, 0.1], [-0.1, 0.1]])
    with pytest.raises(ValueError, match="zero length"):
        thick_segment([1.0, 1.0], [1.0, 1.0])


def test_polyline_walls_close_the_corner() -> None:
    walls = polyline_walls([(0, 0), (2, 0), (2, 2)], thickness=0.1)
    assert len(walls) == 2
    world = world_of(*walls, starts=[(1.0, 1.0, 0.0)])
    # The outer corner of the L is covered (extension by half the thickness).
    assert world.inside_walls([[2.04, -0.04]])[0]
    assert not world.inside_walls([[2.06, -0.06]])[0]


def test_polygon_edges() -> None:
    quads = np.stack([box(0, 0, 1, 1), box(2, 2, 3, 4)])
    edges = polygon_edges(quads)
    assert edges.shape == (8, 4)
    np.testing.assert_array_equal(edges[0], [0, 0, 1, 0])
    np.testing.assert_array_equal(edges[3], [0, 1, 0, 0])
    np.testing.assert_array_equal(edges[7], [2, 4, 2, 2])


# --- WorldSpec validation ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("walls", "message"),
    [
        (np.zeros((0, 4, 2)), "shape"),
        (np.zeros((4, 2)), "shape"),
        (np.zeros((1, 3, 2)), "shape"),
        (np.zeros((1, 4, 3)), "shape"),
        (np.array([[[0, 0], [1, 0], [1, math.nan], [0, 1]]]), "non-finite"),
        # A dart: not convex.
        (np.array([[[0.0, 0.0], [2.0, 1.0], [0.0, 2.0], [0.5, 1.0]]]), "convex"),
        # A bow tie: self-intersecting.
        (np.array([[[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]]), "convex"),
        # All points on one line: degenerate.
        (np.array([[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]]), "degenerate"),
    ],
)
def test_worldspec_rejects_bad_walls(walls: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        WorldSpec(name="bad", walls=walls, starts=np.zeros((1, 3)))


def test_worldspec_error_names_the_bad_wall() -> None:
    dart = np.array([[0.0, 0.0], [2.0, 1.0], [0.0, 2.0], [0.5, 1.0]])
    walls = np.stack([box(0, 0, 1, 1), box(2, 2, 3, 3), dart])
    with pytest.raises(ValueError, match="wall polygon 2"):
        WorldSpec(name="bad", walls=walls, starts=np.zeros((1, 3)))


def test_worldspec_rejects_bad_starts_and_bounds() -> None:
    walls = np.stack([box(0, 0, 1, 1)])
    with pytest.raises(ValueError, match="starts"):
        WorldSpec(name="bad", walls=walls, starts=np.zeros((0, 3)))
    with pytest.raises(ValueError, match="starts"):
        WorldSpec(name="bad", walls=walls, starts=[(0.0, math.inf, 0.0)])
    with pytest.raises(ValueError, match="bounds"):
        WorldSpec(name="bad", walls=walls, starts=np.zeros((1, 3)), bounds=(1.0, 0.0, 1.0, 2.0))
    with pytest.raises(ValueError, match="bounds"):
        WorldSpec(name="bad", walls=walls, starts=np.zeros((1, 3)), bounds=(0.0, 2.0, 1.0, 1.0))


def test_worldspec_normalises_and_freezes() -> None:
    clockwise = box(0, 0, 2, 1)[::-1].copy()
    world = WorldSpec(name="w", walls=np.stack([clockwise]), starts=[1.0, 2.0, 0.5])
    quad = world.walls[0]
    area2 = np.sum(quad[:, 0] * np.roll(quad[:, 1], -1) - np.roll(quad[:, 0], -1) * quad[:, 1])
    assert area2 > 0  # re-oriented counter-clockwise
    assert world.starts.shape == (1, 3)
    assert world.segments.shape == (4, 4)
    assert world.bounds == (0.0, 0.0, 2.0, 1.0)
    for array in (world.walls, world.starts, world.segments):
        with pytest.raises(ValueError):
            array[0] = 0.0


# --- inside_walls / clearance ------------------------------------------------------------


def test_inside_walls_and_clearance_on_known_points() -> None:
    world = world_of(box(0, 0, 2, 1), box(4, 0, 4.1, 3))
    points = np.array(
        [
            [1.0, 0.5],  # centre of the first box: 0.5 from its long edges
            [1.0, 0.9],  # inside, 0.1 from the top
            [1.0, 1.5],  # 0.5 above
            [3.0, 0.5],  # between the boxes: 1.0 from both
            [2.0, 0.5],  # on an edge
            [-3.0, -4.0],  # 5 m from the corner (0, 0)
            [4.05, 1.5],  # inside the thin wall
        ]
    )
    np.testing.assert_array_equal(
        world.inside_walls(points), [True, True, False, False, False, False, True]
    )
    np.testing.assert_allclose(
        world.clearance(points), [-0.5, -0.1, 0.5, 1.0, 0.0, 5.0, -0.05], atol=1e-12
    )


def test_clearance_matches_exact_distance() -> None:
    shapely = pytest.importorskip("shapely")
    rng = np.random.default_rng(1)
    walls = [thick_segment(*rng.uniform(0.0, 5.0, (2, 2)), 0.1) for _ in range(6)]
    world = world_of(*walls)
    points = rng.uniform(-1.0, 6.0, (500, 2))
    outlines = shapely.MultiLineString([s.reshape(2, 2) for s in world.segments])
    exact = shapely.distance(shapely.points(points), outlines)
    clearance = world.clearance(points)
    np.testing.assert_allclose(np.abs(clearance), exact, atol=1e-9)
    inside = np.any(
        [shapely.contains(shapely.Polygon(q), shapely.points(points)) for q in world.walls], axis=0
    )
    np.testing.assert_array_equal(world.inside_walls(points), inside)
    np.testing.assert_array_equal(clearance < 0, inside)


# --- ground truth raster -----------------------------------------------------------------


def test_ground_truth_of_an_aligned_box_is_exactly_its_cells() -> None:
    # Box edges on grid lines: touching cells do not count.
    world = world_of(box(0.3, 0.2, 0.5, 0.35), starts=[(0.0, 0.0, 0.0)])
    grid = ground_truth_map(world, 0.05, margin=0.2)
    assert grid.resolution == 0.05
    np.testing.assert_allclose(grid.origin, (0.1, 0.0), atol=1e-12)
    ys, xs = np.arange(0.2, 0.35 - 1e-9, 0.05), np.arange(0.3, 0.5 - 1e-9, 0.05)
    expected = {tuple(grid.world_to_cell([x + 0.025, y + 0.025]).tolist()) for y in ys for x in xs}
    assert len(expected) == 12
    assert occupied_set(grid) == expected
    assert grid.free.sum() == grid.cells.size - 12


def test_ground_truth_of_an_unaligned_box_is_every_overlapped_cell() -> None:
    world = world_of(box(0.12, 0.07, 0.31, 0.18), starts=[(0.0, 0.0, 0.0)])
    grid = ground_truth_map(world, 0.1, margin=0.3)
    # x in [0.12, 0.31] overlaps columns of [0.1, 0.2), [0.2, 0.3), [0.3, 0.4);
    # y in [0.07, 0.18] overlaps rows [0.0, 0.1), [0.1, 0.2).
    expected = {
        tuple(grid.world_to_cell([x, y]).tolist()) for x in (0.15, 0.25, 0.35) for y in (0.05, 0.15)
    }
    assert occupied_set(grid) == expected


def test_ground_truth_covers_bounds_with_margin() -> None:
    world = world_of(box(-1.03, 0.51, 2.02, 1.49))
    grid = ground_truth_map(world, 0.1, margin=0.25)
    x0, y0, x1, y1 = grid.extent
    assert x0 <= -1.03 - 0.25 + 1e-9
    assert y0 <= 0.51 - 0.25 + 1e-9
    assert x1 >= 2.02 + 0.25 - 1e-9
    assert y1 >= 1.49 + 0.25 - 1e-9
    # The origin lies on the resolution lattice through the world origin.
    assert grid.origin[0] / 0.1 == pytest.approx(round(grid.origin[0] / 0.1), abs=1e-9)
    assert grid.origin[1] / 0.1 == pytest.approx(round(grid.origin[1] / 0.1), abs=1e-9)
    # No more than one extra cell of slack on each side.
    assert x0 > -1.03 - 0.25 - 0.1 and x1 < 2.02 + 0.25 + 0.1


def test_ground_truth_anchor_puts_the_origin_on_its_lattice() -> None:
    world = world_of(box(0.12, 0.07, 0.31, 0.18), box(-0.52, 1.0, -0.4, 1.33))
    anchor = (0.03, -0.07)
    grid = ground_truth_map(world, 0.1, margin=0.05, anchor=anchor)
    for k in range(2):
        offset = (grid.origin[k] - anchor[k]) / 0.1
        assert offset == pytest.approx(round(offset), abs=1e-9)
    x0, y0, x1, y1 = grid.extent
    assert x0 <= -0.52 - 0.05 + 1e-9 and y0 <= 0.07 - 0.05 + 1e-9
    assert x1 >= 0.31 + 0.05 - 1e-9 and y1 >= 1.33 + 0.05 - 1e-9
    # Cells are still exactly those overlapping the walls.
    for quad in world.walls:
        points = np.random.default_rng(0).dirichlet(np.ones(4), 500) @ quad
        cells = grid.world_to_cell(points)
        assert np.all(grid.cells[cells[:, 0], cells[:, 1]] == OCCUPIED)
    centres = grid.cell_to_world(np.argwhere(grid.occupied))
    assert np.all(world.clearance(centres) <= 0.1 * math.sqrt(2) / 2 + 1e-9)


def test_ground_truth_rejects_bad_resolution() -> None:
    world = world_of(box(0, 0, 1, 1))
    for res in (0.0, -0.1, math.nan, math.inf):
        with pytest.raises(ValueError, match="resolution"):
            ground_truth_map(world, res)


def _four_connected(cells: set[tuple[int, int]]) -> bool:
    start = next(iter(cells))
    seen, todo = {start}, [start]
    while todo:
        r, c = todo.pop()
        for nb in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
            if nb in cells and nb not in seen:
                seen.add(nb)
                todo.append(nb)
    return seen == cells


def test_rotated_thin_wall_marks_a_connected_line() -> None:
    rng = np.random.default_rng(2)
    for _ in range(10):
        angle = rng.uniform(0.05, math.pi / 2 - 0.05)
        p = np.array([0.3, 0.3]) + rng.uniform(0.0, 0.1, 2)
        q = p + 3.0 * np.array([math.cos(angle), math.sin(angle)])
        world = world_of(thick_segment(p, q, 0.02))
        grid = ground_truth_map(world, 0.1, margin=0.2)
        cells = occupied_set(grid)
        assert _four_connected(cells)
        # It covers both end points and the whole line between them.
        for t in np.linspace(0.0, 1.0, 301):
            assert tuple(grid.world_to_cell(p + t * (q - p)).tolist()) in cells
        # A thin line: roughly (|dx| + |dy|) / res cells, far fewer than its bounding box.
        rows = {r for r, _ in cells}
        cols = {c for _, c in cells}
        assert len(cells) <= 1.3 * (len(rows) + len(cols)) + 4
        assert len(cells) < 0.5 * len(rows) * len(cols)


def _random_walls_world(rng: np.random.Generator) -> WorldSpec:
    walls = []
    while len(walls) < rng.integers(2, 7):
        p, q = rng.uniform(0.0, 3.0, (2, 2))
        if np.hypot(*(q - p)) > 0.05:
            walls.append(thick_segment(p, q, rng.uniform(0.02, 0.3)))
    return world_of(*walls)


def test_every_cell_overlapping_a_wall_is_occupied() -> None:
    rng = np.random.default_rng(3)
    for _ in range(15):
        world = _random_walls_world(rng)
        res = float(rng.choice([0.05, 0.1, 0.13]))
        grid = ground_truth_map(world, res, margin=0.1)
        # Sample points inside every wall (random convex combinations of the corners,
        # plus points near the corners and edges).
        for quad in world.walls:
            weights = rng.dirichlet(np.full(4, 0.3), 4000)
            points = weights @ quad
            points = points[world.inside_walls(points)]
            cells = grid.world_to_cell(points)
            assert np.all(grid.contains(cells))
            assert np.all(grid.cells[cells[:, 0], cells[:, 1]] == OCCUPIED)


def test_every_occupied_cell_is_near_a_wall() -> None:
    rng = np.random.default_rng(4)
    for _ in range(15):
        world = _random_walls_world(rng)
        res = float(rng.choice([0.05, 0.1, 0.13]))
        grid = ground_truth_map(world, res, margin=0.1)
        centres = grid.cell_to_world(np.argwhere(grid.occupied))
        # The cell's square overlaps a wall, so its centre is within half a diagonal.
        assert np.all(world.clearance(centres) <= res * math.sqrt(2) / 2 + 1e-9)


def test_ground_truth_matches_exact_polygon_overlap() -> None:
    shapely = pytest.importorskip("shapely")
    rng = np.random.default_rng(5)
    for _ in range(25):
        world = _random_walls_world(rng)
        res = float(rng.choice([0.05, 0.1, 0.13]))
        grid = ground_truth_map(world, res, margin=float(rng.choice([0.0, 0.2])))
        rows, cols = grid.shape
        iy, ix = np.mgrid[0:rows, 0:cols]
        x0 = grid.origin[0] + ix.ravel() * res
        y0 = grid.origin[1] + iy.ravel() * res
        squares = shapely.box(x0, y0, x0 + res, y0 + res)
        area = np.zeros(rows * cols)
        for quad in world.walls:
            area = np.maximum(
                area, shapely.area(shapely.intersection(squares, shapely.Polygon(quad)))
            )
        area = area.reshape(rows, cols)
        clear = (area > 1e-9) | (area == 0.0)  # skip cells grazed by less than rounding
        assert clear.mean() > 0.99
        np.testing.assert_array_equal(grid.occupied[clear], area[clear] > 0.0)


def test_touching_boxes_do_not_bleed_into_neighbours() -> None:
    # Two boxes sharing an edge on a grid line, and a box whose corner touches a cell corner.
    world = world_of(box(0.0, 0.0, 0.2, 0.2), box(0.2, 0.0, 0.4, 0.1), box(0.4, 0.1, 0.5, 0.2))
    grid = ground_truth_map(world, 0.1)
    expected = np.array(
        [
            [OCCUPIED, OCCUPIED, OCCUPIED, OCCUPIED, FREE],
            [OCCUPIED, OCCUPIED, FREE, FREE, OCCUPIED],
        ],
        dtype=np.int8,
    )
    np.testing.assert_array_equal(grid.cells, expected)


def test_triangle_given_as_a_quad_is_rejected_or_handled() -> None:
    triangle = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    try:
        world = world_of(triangle, starts=[(2.0, 2.0, 0.0)])
    except ValueError:
        return  # rejecting degenerate quads is fine
    assert world.inside_walls([[0.2, 0.2]])[0]
    assert world.clearance([[0.2, 0.2]])[0] == pytest.approx(-0.2)
    grid = ground_truth_map(world, 0.1)
    # Cells [ix, ix + 0.1] x [iy, iy + 0.1] overlapping x + y < 1: ix + iy <= 9.
    assert grid.occupied.sum() == 55
