"""Path planning (agents.planning): inflation, Dijkstra against a brute-force reference,
path tracing and line-of-sight shortening."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import ndimage
from scipy.sparse import lil_matrix
from scipy.sparse.csgraph import dijkstra

from agents.planning import (
    CostGrid,
    PlannerConfig,
    best_goal_field,
    distance_field,
    inflate,
    line_is_clear,
    nearest_passable_cell,
    plan_path,
    reachable_cells,
    shorten_path,
)
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap

RESOLUTION = 0.05


def reference_costs(cost: np.ndarray, start: tuple[int, int], resolution: float) -> np.ndarray:
    """Dijkstra by scipy on the explicit 8-connected graph, built cell by cell."""
    rows, cols = cost.shape
    graph = lil_matrix((rows * cols, rows * cols))
    for r in range(rows):
        for c in range(cols):
            if not np.isfinite(cost[r, c]):
                continue
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    rr, cc = r + dr, c + dc
                    if (dr, dc) == (0, 0) or not (0 <= rr < rows and 0 <= cc < cols):
                        continue
                    if not np.isfinite(cost[rr, cc]):
                        continue
                    if dr and dc and not (np.isfinite(cost[rr, c]) and np.isfinite(cost[r, cc])):
                        continue
                    length = resolution * math.hypot(dr, dc)
                    graph[r * cols + c, rr * cols + cc] = length * (cost[r, c] + cost[rr, cc]) / 2
    distances = dijkstra(graph.tocsr(), indices=start[0] * cols + start[1])
    return np.asarray(distances).reshape(rows, cols)


def random_cost_grid(rng: np.random.Generator, rows: int, cols: int) -> CostGrid:
    cost = 1.0 + 3.0 * rng.random((rows, cols))
    cost[rng.random((rows, cols)) < 0.25] = np.inf
    return CostGrid(
        cost=cost, wall_distance=np.ones((rows, cols)), resolution=0.1, origin=(0.0, 0.0)
    )


@pytest.mark.parametrize("seed", range(6))
def test_dijkstra_costs_equal_a_brute_force_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    grid = random_cost_grid(rng, 9 + seed, 12)
    start = tuple(int(v) for v in np.argwhere(grid.passable)[0])
    field = distance_field(grid, grid.cell_to_world(np.array(start)), snap_distance=0.01)
    assert field.start == start
    expected = reference_costs(grid.cost, start, grid.resolution)
    np.testing.assert_array_equal(np.isfinite(field.cost), np.isfinite(expected))
    finite = np.isfinite(expected)
    np.testing.assert_allclose(field.cost[finite], expected[finite], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_traced_paths_are_connected_and_cost_what_the_field_says(seed: int) -> None:
    rng = np.random.default_rng(10 + seed)
    grid = random_cost_grid(rng, 15, 15)
    start = tuple(int(v) for v in np.argwhere(grid.passable)[0])
    field = distance_field(grid, grid.cell_to_world(np.array(start)), snap_distance=0.01)
    for goal in np.argwhere(field.reachable)[::7]:
        path = field.path_to(goal)
        assert tuple(path[0]) == start and tuple(path[-1]) == tuple(goal)
        steps = np.diff(path, axis=0)
        assert np.all(np.abs(steps).max(axis=1) == 1)
        cost = sum(
            grid.resolution * math.hypot(*step) * (grid.cost[tuple(a)] + grid.cost[tuple(b)]) / 2
            for step, a, b in zip(steps, path[:-1], path[1:], strict=True)
        )
        assert cost == pytest.approx(field.cost[tuple(goal)], rel=1e-12, abs=1e-12)


def random_map(rng: np.random.Generator, rows: int, cols: int) -> GridMap:
    """Walls in clumps, unknown patches, free elsewhere."""
    cells = np.full((rows, cols), FREE, dtype=np.int8)
    cells[ndimage.binary_dilation(rng.random((rows, cols)) < 0.01, iterations=2)] = OCCUPIED
    cells[ndimage.binary_dilation(rng.random((rows, cols)) < 0.005, iterations=4)] = UNKNOWN
    cells[rng.random((rows, cols)) < 0.01] = OCCUPIED
    return GridMap(cells=cells, resolution=RESOLUTION)


@pytest.mark.parametrize("seed", range(4))
def test_wall_distances_are_scipy_euclidean_distances(seed: int) -> None:
    # The inflation's own exact transform against scipy's, value for value.
    rng = np.random.default_rng(40 + seed)
    grid = random_map(rng, 50 + 7 * seed, 80 - 9 * seed)
    band = PlannerConfig().blocked_radius + PlannerConfig().clearance
    costs = inflate(grid, PlannerConfig(clearance=0.0, unknown="costly"))
    expected = ndimage.distance_transform_edt(grid.cells != OCCUPIED) * RESOLUTION
    # The cost grid covers the known window grown by the band, the whole of this map.
    np.testing.assert_array_equal(costs.wall_distance, expected)
    soft = inflate(grid)
    near = np.where(expected < band, expected, band)
    assert np.array_equal(soft.wall_distance < band, near < band)


@pytest.mark.parametrize("seed", range(4))
def test_costs_follow_the_scipy_distances_inside_unknown_margins(seed: int) -> None:
    # A map inside a wide unknown margin (the cost grid works on its known window): every
    # cell's cost from scipy's distances, under each unknown policy, with and without the
    # soft band.
    rng = np.random.default_rng(60 + seed)
    inner = random_map(rng, 40 + 5 * seed, 60 - 4 * seed)
    cells = np.full((inner.shape[0] + 70, inner.shape[1] + 50), UNKNOWN, dtype=np.int8)
    cells[30 + seed : 30 + seed + inner.shape[0], 20 : 20 + inner.shape[1]] = inner.cells
    grid = GridMap(cells=cells, resolution=RESOLUTION)
    distance = ndimage.distance_transform_edt(cells != OCCUPIED) * RESOLUTION
    for config in (
        PlannerConfig(),
        PlannerConfig(unknown="costly", unknown_cost=3.0),
        PlannerConfig(clearance_cost=0.0, unknown="costly"),
    ):
        costs = inflate(grid, config)
        band = config.blocked_radius + config.clearance
        near = distance < band
        np.testing.assert_array_equal(costs.wall_distance[near], distance[near])
        assert np.all(costs.wall_distance[~near] >= band)
        expected = np.ones(cells.shape)
        if config.clearance_cost > 0:
            beyond = np.clip((distance - config.blocked_radius) / config.clearance, 0.0, 1.0)
            expected = 1.0 + config.clearance_cost * ((1.0 - beyond) * (1.0 - beyond))
        expected[(cells == OCCUPIED) | (distance < config.blocked_radius)] = np.inf
        unknown = cells == UNKNOWN
        costly = expected[unknown] * config.unknown_cost
        expected[unknown] = np.inf if config.unknown == "blocked" else costly
        np.testing.assert_array_equal(costs.cost, expected)


@pytest.mark.parametrize("seed", range(4))
def test_reachable_cells_are_the_searched_ones(seed: int) -> None:
    rng = np.random.default_rng(50 + seed)
    grid = random_cost_grid(rng, 30, 40)
    start_point = grid.cell_to_world(np.argwhere(grid.passable)[len(grid.passable) // 3])
    start, reachable = reachable_cells(grid, start_point, snap_distance=0.01)
    field = distance_field(grid, start_point, snap_distance=0.01)
    assert start == field.start
    np.testing.assert_array_equal(reachable, field.reachable)


@pytest.mark.parametrize("seed", range(6))
def test_best_goal_field_finds_the_best_goal_with_its_exact_cost_and_path(seed: int) -> None:
    rng = np.random.default_rng(60 + seed)
    grid = random_cost_grid(rng, 40, 40)
    start, reachable = reachable_cells(grid, grid.cell_to_world(np.array([20, 20])))
    full = distance_field(grid, grid.cell_to_world(np.array(start)), snap_distance=0.01)
    goals = rng.permutation(np.argwhere(reachable))[:12]
    goals = np.concatenate([goals, goals[:2]])  # two goals on one cell
    values = 20.0 * rng.random(len(goals))
    values[3] = -np.inf
    weight, min_cost = 2.0, 0.3
    field = best_goal_field(grid, start, goals, values, cost_weight=weight, min_cost=min_cost)
    true_costs = full.cost[goals[:, 0], goals[:, 1]]
    costs = field.cost[goals[:, 0], goals[:, 1]]

    def scores(c: np.ndarray) -> np.ndarray:
        return np.where(c >= min_cost, values - weight * c, -np.inf)

    best = int(np.argmax(scores(true_costs)))
    assert int(np.argmax(scores(costs))) == best
    assert costs[best] == true_costs[best]
    np.testing.assert_array_equal(field.path_to(goals[best]), full.path_to(goals[best]))
    assert np.all(costs >= true_costs)  # upper bounds elsewhere
    settled = field.cost <= costs[best]
    np.testing.assert_array_equal(field.cost[settled], full.cost[settled])
    np.testing.assert_array_equal(field.parent[settled], full.parent[settled])
    # The search did stop early on these grids, and runs to the end without a weight.
    assert np.isinf(field.cost[reachable]).any() or (field.cost != full.cost).any()
    whole = best_goal_field(grid, start, goals, values, cost_weight=0.0)
    np.testing.assert_array_equal(whole.cost, full.cost)
    np.testing.assert_array_equal(whole.parent, full.parent)


def test_on_open_free_space_the_cost_is_the_octile_distance() -> None:
    grid = GridMap(cells=np.zeros((40, 40), dtype=np.int8), resolution=RESOLUTION)
    costs = inflate(grid, PlannerConfig(clearance=0.0))
    field = distance_field(costs, grid.cell_to_world(np.array([5, 5])))
    dr, dc = 30 - 5, 20 - 5
    octile = RESOLUTION * (max(dr, dc) - min(dr, dc) + math.sqrt(2) * min(dr, dc))
    assert field.cost[30, 20] == pytest.approx(octile, rel=1e-12)


def corridor_map() -> GridMap:
    """A 4 m x 2 m free box with walls, a 1 m wide gap in a middle wall."""
    cells = np.full((40, 80), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[:, 40] = OCCUPIED
    cells[10:30, 40] = FREE  # the gap: rows 10..29, 1 m
    return GridMap(cells=cells, resolution=RESOLUTION)


def test_inflation_blocks_cells_near_walls_and_prices_clearance() -> None:
    config = PlannerConfig(robot_radius=0.2, safety_margin=0.05, clearance=0.5)
    grid = corridor_map()
    costs = inflate(grid, config)
    wall_distance = ndimage.distance_transform_edt(~grid.occupied) * RESOLUTION
    np.testing.assert_array_equal(costs.passable, wall_distance >= 0.25)
    free_cost = costs.cost[costs.passable]
    assert free_cost.min() == pytest.approx(1.0)
    assert free_cost.max() <= 1.0 + config.clearance_cost + 1e-12
    # Cost falls with distance from the wall (row 20 is the middle of the box).
    row = costs.cost[20, 5:20]
    assert np.all(np.diff(row[np.isfinite(row)]) <= 1e-12)


def test_planned_paths_keep_clearance_from_walls() -> None:
    config = PlannerConfig()
    grid = corridor_map()
    costs = inflate(grid, config)
    path = plan_path(costs, (0.5, 0.4), (3.5, 1.6))
    assert len(path) >= 2
    # Sample the shortened path densely: every point stays out of the blocked zone.
    dense = np.concatenate(
        [np.linspace(a, b, 50, endpoint=False) for a, b in itertools.pairwise(path)]
    )
    wall_cells = grid.cell_to_world(np.argwhere(grid.occupied))
    gaps = np.hypot(*(dense[:, None, :] - wall_cells[None]).transpose(2, 0, 1)).min(axis=1)
    # Cell centres are >= blocked_radius from wall centres; a segment between them may
    # cut a corner by at most half a cell diagonal.
    assert gaps.min() >= config.blocked_radius - RESOLUTION * math.sqrt(2) / 2
    # Through the 1 m gap, it keeps to the middle.
    crossing = dense[np.argmin(np.abs(dense[:, 0] - 40.5 * RESOLUTION))]
    assert crossing[1] == pytest.approx(1.0, abs=0.15)


def test_unknown_cells_are_blocked_or_costly_as_configured() -> None:
    cells = np.full((20, 60), FREE, dtype=np.int8)
    cells[:, 25:35] = UNKNOWN
    grid = GridMap(cells=cells, resolution=RESOLUTION)
    blocked = inflate(grid, PlannerConfig(unknown="blocked", clearance=0.0))
    costly = inflate(grid, PlannerConfig(unknown="costly", unknown_cost=5.0, clearance=0.0))
    start, goal = (0.5, 0.5), (2.5, 0.5)
    assert len(plan_path(blocked, start, goal)) == 0
    path = plan_path(costly, start, goal)
    assert len(path) >= 2
    field = distance_field(costly, start)
    goal_cell = tuple(costly.world_to_cell(np.array(goal)))
    # 40 steps: 29 between free cells, 9 inside the unknown band at five times the cost,
    # and the two steps across its edges at the mean of 1 and 5.
    assert field.cost[goal_cell] == pytest.approx(RESOLUTION * (29 + 9 * 5 + 2 * 3), rel=1e-9)


def test_plan_path_returns_empty_when_the_goal_is_walled_off() -> None:
    cells = np.full((40, 40), FREE, dtype=np.int8)
    cells[:, 20] = OCCUPIED
    grid = GridMap(cells=cells, resolution=RESOLUTION)
    costs = inflate(grid)
    assert plan_path(costs, (0.3, 1.0), (1.7, 1.0)).shape == (0, 2)


def test_a_start_inside_the_inflation_snaps_to_the_nearest_passable_cell() -> None:
    grid = corridor_map()
    costs = inflate(grid)
    near_wall = grid.cell_to_world(np.array([20, 2]))  # 0.1 m from the west wall
    snapped = nearest_passable_cell(costs, near_wall)
    assert snapped is not None and costs.passable[snapped]
    assert snapped[0] == 20 and snapped[1] > 2
    assert nearest_passable_cell(costs, near_wall, max_distance=0.05) is None
    with pytest.raises(ValueError, match="no passable cell"):
        distance_field(costs, near_wall, snap_distance=0.05)


def test_shortened_paths_are_clear_subsequences_with_the_same_ends() -> None:
    grid = corridor_map()
    costs = inflate(grid)
    field = distance_field(costs, (0.5, 0.4))
    cells = field.path_to(costs.world_to_cell(np.array([3.5, 1.6])))
    short = shorten_path(costs, cells)
    assert len(short) < len(cells) // 4
    assert tuple(short[0]) == tuple(cells[0]) and tuple(short[-1]) == tuple(cells[-1])
    positions = {tuple(cell): i for i, cell in enumerate(cells.tolist())}
    order = [positions[tuple(cell)] for cell in short.tolist()]
    assert order == sorted(order)
    for a, b in itertools.pairwise(short):
        assert line_is_clear(costs, a, b)


def test_on_open_space_a_path_shortens_to_its_two_ends() -> None:
    grid = GridMap(cells=np.zeros((30, 30), dtype=np.int8), resolution=RESOLUTION)
    costs = inflate(grid, PlannerConfig(clearance=0.0))
    path = plan_path(costs, (0.2, 0.2), (1.3, 0.9))
    assert len(path) == 2


def test_line_is_clear_agrees_with_dense_sampling() -> None:
    # Reference: sample the segment densely, shifted a hair to either side so that a
    # segment through a cell corner sees the cells on both sides of it.
    rng = np.random.default_rng(7)
    grid = random_cost_grid(rng, 25, 25)
    grid.cost[0, :] = grid.cost[-1, :] = grid.cost[:, 0] = grid.cost[:, -1] = np.inf
    passable = np.argwhere(grid.passable)
    t = np.linspace(0.0, 1.0, 4001)[:, None]
    for _ in range(300):
        a, b = passable[rng.integers(len(passable), size=2)]
        direction = (b - a) / max(np.hypot(*(b - a)), 1e-12)
        normal = np.array([-direction[1], direction[0]])
        clear = True
        for shift in (-1e-7, 1e-7):
            points = a + 0.5 + t * (b - a) + shift * normal
            cells = np.floor(points).astype(int)
            clear &= bool(grid.passable[cells[:, 0], cells[:, 1]].all())
        assert line_is_clear(grid, a, b) == clear


def test_a_map_with_no_free_cell_is_rejected() -> None:
    grid = GridMap(cells=np.full((5, 5), UNKNOWN, dtype=np.int8), resolution=RESOLUTION)
    with pytest.raises(ValueError, match="no FREE cell"):
        inflate(grid)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("robot_radius", 0.0),
        ("safety_margin", -0.1),
        ("clearance", float("inf")),
        ("unknown", "maybe"),
        ("unknown_cost", 0.5),
    ],
)
def test_config_rejects_bad_values_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        PlannerConfig(**{field: value})  # type: ignore[arg-type]
