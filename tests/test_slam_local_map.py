"""The egocentric local map against a slow reference, and its bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrslam_env.geometry import transform_points
from mrslam_env.slam.grid import OccupancyGrid
from mrslam_env.slam.local_map import FREE_CHANNEL, OCCUPIED_CHANNEL, local_map


def reference_crop(grid: OccupancyGrid, pose, cells: int, cell_size: float, pool: int):
    """Every sample point of every output cell, one at a time."""
    out = np.zeros((2, cells, cells), dtype=np.uint8)
    trinary = grid.to_gridmap()
    step = cell_size / pool
    for r in range(cells):
        for k in range(cells):
            for a in range(pool):
                for b in range(pool):
                    local = [
                        (k - cells / 2) * cell_size + (b + 0.5) * step,
                        (r - cells / 2) * cell_size + (a + 0.5) * step,
                    ]
                    point = transform_points(pose, [local])
                    cell = trinary.world_to_cell(point)
                    if not trinary.contains(cell)[0]:
                        continue
                    iy, ix = cell[0]
                    if trinary.occupied[iy, ix]:
                        out[OCCUPIED_CHANNEL, r, k] = 1
                    elif trinary.free[iy, ix]:
                        out[FREE_CHANNEL, r, k] = 1
    return out


def random_grid(rng: np.random.Generator) -> OccupancyGrid:
    grid = OccupancyGrid()
    grid.ensure_contains(-1.0, -1.0, 1.0, 1.0)
    values = rng.choice(np.array([-1.0, -0.3, 0.0, 0.5, 2.0], dtype=np.float32), grid.shape)
    grid._log_odds[...] = values  # a test may set the state directly
    return grid


@pytest.mark.parametrize("seed", range(4))
def test_crop_matches_the_slow_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    grid = random_grid(rng)
    pose = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-math.pi, math.pi)])
    # 0.1 m crop cells on a 0.05 m grid: 3 x 3 samples per cell.
    expected = reference_crop(grid, pose, 16, 0.1, 3)
    np.testing.assert_array_equal(local_map(grid, pose, 16, 0.1), expected)
    assert expected.any(axis=(1, 2)).all(), "both channels exercised"
    # Out of the grid: all unknown.
    far = local_map(grid, [50.0, 50.0, 0.3], 16, 0.1)
    assert far.dtype == np.uint8 and not far.any()


@pytest.mark.parametrize(("cells", "cell_size"), [(0, 0.1), (8, 0.0), (8, math.nan)])
def test_bad_crop_sizes_are_refused(cells: int, cell_size: float) -> None:
    with pytest.raises(ValueError, match=r"cells must be|cell_size must be"):
        local_map(OccupancyGrid(), [0.0, 0.0, 0.0], cells, cell_size)


def test_returns_from_a_detected_robot_are_dropped_for_slam() -> None:
    from mrslam_env.slam.scan import mask_returns_near

    ranges = np.full(360, 8.0)
    ranges[170:191] = 1.0  # beams straight ahead (beam 180) hit something 1 m away
    ranges[0:10] = 2.0  # and a wall behind
    masked = mask_returns_near(ranges, np.array([[1.1, 0.0]]), 0.35, 8.0)
    assert np.isnan(masked[170:191]).all(), "the robot 1.1 m ahead is not mapped"
    np.testing.assert_array_equal(masked[0:10], 2.0)
    np.testing.assert_array_equal(masked[20:170], 8.0)  # no-return beams stay
    assert not np.isnan(ranges).any(), "the input is not modified"
    np.testing.assert_array_equal(mask_returns_near(ranges, np.empty((0, 2)), 0.35, 8.0), ranges)
