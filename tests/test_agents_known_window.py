"""Planning and frontier extraction work on the known part of a map (a SLAM grid is mostly
unknown margin): the same map inside a wide UNKNOWN margin gives the same cost grid,
distance field and frontiers, shifted by the margin, as the tight map does."""

from __future__ import annotations

import numpy as np
import pytest

from agents.frontiers import FrontierConfig, extract_frontiers
from agents.planning import PlannerConfig, distance_field, inflate
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap

RESOLUTION = 0.05


def rooms(seed: int) -> GridMap:
    """A tight map (known cells touch every edge): free rooms, walls, unknown pockets."""
    rng = np.random.default_rng(seed)
    cells = np.full((90, 120), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[45, 10:100] = OCCUPIED  # a wall with a door
    cells[45, 50:60] = FREE
    for _ in range(6):  # unknown space the robot has not seen, some of it open to the map
        row, col = rng.integers(2, 80), rng.integers(2, 110)
        cells[row : row + rng.integers(4, 25), col : col + rng.integers(4, 25)] = UNKNOWN
    cells[rng.random(cells.shape) < 0.01] = OCCUPIED  # clutter
    cells[0, 30:50] = UNKNOWN  # an opening in the outer wall
    return GridMap(cells=cells, resolution=RESOLUTION, origin=(1.0, -2.0))


def padded(grid: GridMap, rows: tuple[int, int], cols: tuple[int, int]) -> GridMap:
    cells = np.pad(grid.cells, (rows, cols), constant_values=UNKNOWN)
    x, y = grid.origin
    origin = (x - cols[0] * RESOLUTION, y - rows[0] * RESOLUTION)
    return GridMap(cells=cells, resolution=RESOLUTION, origin=origin)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("unknown", ["blocked", "costly"])
def test_planning_ignores_the_unknown_margin(seed: int, unknown: str) -> None:
    tight = rooms(seed)
    wide = padded(tight, (37, 80), (120, 5))
    window = (slice(37, 37 + 90), slice(120, 120 + 120))
    config = PlannerConfig(unknown=unknown)  # type: ignore[arg-type]
    near, far = inflate(tight, config), inflate(wide, config)
    np.testing.assert_array_equal(far.cost[window], near.cost)
    band = config.blocked_radius + config.clearance
    reach = int(np.ceil(band / RESOLUTION))  # walls at the edge cost in the margin too
    distant = np.ones(wide.shape, dtype=bool)
    distant[37 - reach : 37 + 90 + reach, 120 - reach : 120 + 120 + reach] = False
    far_cost = np.inf if unknown == "blocked" else config.unknown_cost
    np.testing.assert_array_equal(far.cost[distant], far_cost)
    exact = near.wall_distance < band
    np.testing.assert_array_equal(far.wall_distance[window][exact], near.wall_distance[exact])
    assert np.all(far.wall_distance[window][~exact] >= band)

    start = np.array([3.0, 0.0])
    tight_field, wide_field = distance_field(near, start), distance_field(far, start)
    np.testing.assert_array_equal(wide_field.cost[window], tight_field.cost)
    assert wide_field.start == (tight_field.start[0] + 37, tight_field.start[1] + 120)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(
    "config",
    [FrontierConfig(), FrontierConfig(gain_model="box"), FrontierConfig(connectivity=8)],
    ids=["connected", "box", "8-connected"],
)
def test_frontiers_ignore_the_unknown_margin(seed: int, config: FrontierConfig) -> None:
    tight = rooms(seed)
    wide = padded(tight, (60, 3), (4, 90))
    reachable = distance_field(inflate(tight), np.array([3.0, 0.0])).reachable
    wide_reachable = np.pad(reachable, ((60, 3), (4, 90)))
    near = extract_frontiers(tight, config, reachable=reachable)
    far = extract_frontiers(wide, config, reachable=wide_reachable)
    assert len(near) > 3
    np.testing.assert_array_equal(far.labels[60:150, 4:124], near.labels)
    assert far.labels.sum() == near.labels.sum()
    np.testing.assert_array_equal(far.goal_cells, near.goal_cells + np.array([60, 4]))
    np.testing.assert_array_equal(far.sizes, near.sizes)
    np.testing.assert_allclose(far.goals, near.goals, rtol=0, atol=1e-9)
    np.testing.assert_allclose(far.centroids, near.centroids, rtol=0, atol=1e-9)
    if config.gain_model == "box":
        # The box gain counts the margin's cells as unknown, as it counts space beyond
        # the tight grid's edge: the same area.
        np.testing.assert_allclose(far.gains, near.gains, rtol=0, atol=1e-9)
    else:
        np.testing.assert_array_equal(far.gains, near.gains)
