"""The virtual robot (mrslam_env.merge.virtual): exact grid ray casting against a slow
slab-intersection reference, and runs along the skeleton of a realistic map."""

from __future__ import annotations

import math

import numpy as np
import pytest
from merge_fixtures import map_pair

from mrslam_env.geometry import compose, wrap_angle
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.merge.skeleton import free_space_graph
from mrslam_env.merge.virtual import (
    VirtualRobotConfig,
    odometry_between,
    simulate_scan,
    simulate_scans,
    virtual_robot_runs,
)


def reference_range(grid: GridMap, x: float, y: float, angle: float, max_range: float) -> float:
    """Slow and obvious: intersect the ray with every cell (slab method), walk the cells in
    order of entry distance, apply the rules."""
    rows, cols = grid.shape
    res = grid.resolution
    dx, dy = math.cos(angle), math.sin(angle)
    hits = []
    for r in range(-1, rows + 1):
        for c in range(-1, cols + 1):
            x0, y0 = grid.origin[0] + c * res, grid.origin[1] + r * res
            t_lo, t_hi = 0.0, max_range
            for p, d, lo, hi in ((x, dx, x0, x0 + res), (y, dy, y0, y0 + res)):
                if abs(d) < 1e-15:
                    if not (lo <= p < hi):
                        t_lo, t_hi = 1.0, 0.0
                    continue
                a, b = (lo - p) / d, (hi - p) / d
                t_lo, t_hi = max(t_lo, min(a, b)), min(t_hi, max(a, b))
            if t_hi > t_lo + 1e-12:
                hits.append((t_lo, r, c))
    for t, r, c in sorted(hits):
        if not (0 <= r < rows and 0 <= c < cols):
            return math.nan
        if grid.cells[r, c] == OCCUPIED:
            return t
        if grid.cells[r, c] == UNKNOWN:
            return math.nan
    return max_range


def random_grid(seed: int) -> GridMap:
    rng = np.random.default_rng(seed)
    cells = rng.choice([FREE, OCCUPIED, UNKNOWN], p=[0.9, 0.07, 0.03], size=(16, 19))
    return GridMap(cells=cells.astype(np.int8), resolution=0.1, origin=(-0.73, 0.41))


@pytest.mark.parametrize("seed", range(4))
def test_simulate_scan_matches_the_slab_reference(seed):
    grid = random_grid(seed)
    rng = np.random.default_rng(100 + seed)
    angles = np.sort(rng.uniform(-np.pi, np.pi, 24))
    xmin, ymin, xmax, ymax = grid.extent
    checked = 0
    for _ in range(8):
        pose = np.array([rng.uniform(xmin, xmax), rng.uniform(ymin, ymax), rng.uniform(-3, 3)])
        ranges = simulate_scan(grid, pose, angles, 1.2)
        expected = [reference_range(grid, pose[0], pose[1], pose[2] + a, 1.2) for a in angles]
        np.testing.assert_allclose(ranges, expected, rtol=0, atol=1e-9)
        checked += int(np.isfinite(ranges).sum())
    assert checked > 50  # not all NaN: the comparison saw real returns


def test_scan_rules_wall_unknown_edge_and_no_return():
    cells = np.full((20, 40), FREE, dtype=np.int8)
    cells[:, 30] = OCCUPIED  # wall whose near face is at x = 1.5
    cells[:, 5] = UNKNOWN  # unknown column with its far face at x = 0.3
    grid = GridMap(cells=cells, resolution=0.05)
    pose = np.array([1.0, 0.52, 0.0])
    east, north, west = simulate_scan(grid, pose, np.array([0.0, np.pi / 2, np.pi]), 2.0)
    assert east == pytest.approx(0.5, abs=1e-12)
    assert math.isnan(north)  # leaves the grid at y = 1.0 before max range
    assert math.isnan(west)  # meets unknown space
    # Nothing within range through known free space: a genuine no-return.
    assert simulate_scan(grid, pose, np.array([0.0]), 0.3)[0] == 0.3
    assert simulate_scans(grid, np.tile(pose, (3, 1)), np.array([0.0]), 2.0).shape == (3, 1)
    with pytest.raises(ValueError, match="max_range"):
        simulate_scan(grid, pose, np.array([0.0]), 0.0)


@pytest.mark.parametrize("quadrant", range(4))
def test_a_beam_through_cell_corners_does_not_turn_on_the_last_bit_of_its_angle(quadrant):
    # Issue 36: the virtual robot drives from cell centres along diagonals, so its beams at
    # multiples of 45 degrees pass exactly through cell corners. At the first corner one
    # neighbour is UNKNOWN (entering it makes the beam invalid) and the other FREE; a wall
    # lies further along the diagonal. Which neighbour the beam enters must not depend on
    # the last bit of its angle (np.arctan2 and cos/sin differ by an ulp between CPUs).
    cells = np.full((10, 10), FREE, dtype=np.int8)
    cells[0, 1] = UNKNOWN  # the x neighbour at the first corner
    cells[5, 5] = OCCUPIED  # entered through the corner (0, 0)
    # np.rot90 turns the grid by -90 degrees in the map frame (rows are y): the same beam
    # turned with it meets the same cells, the UNKNOWN one now beside it in x or in y.
    grid = GridMap(cells=np.rot90(cells, quadrant).copy(), resolution=0.1, origin=(-0.5, -0.5))
    turn = -quadrant * math.pi / 2
    c, s = math.cos(turn), math.sin(turn)
    start = np.round([-0.45 * (c - s), -0.45 * (s + c)], 12)  # a cell centre
    diagonal = float(wrap_angle(math.pi / 4 + turn))
    angles = np.array([np.nextafter(diagonal, -4.0), diagonal, np.nextafter(diagonal, 4.0)])
    ranges = simulate_scan(grid, np.array([start[0], start[1], 0.0]), angles, 2.0)
    # A corner counts as crossed in y first (virtual._CORNER_TIE), so all three beams agree.
    if quadrant % 2 == 0:  # the y neighbour is FREE: every beam meets the wall at (0, 0)
        np.testing.assert_allclose(ranges, 0.45 * math.sqrt(2.0), rtol=0, atol=1e-9)
    else:  # the y neighbour is the UNKNOWN cell
        assert np.isnan(ranges).all()


@pytest.fixture(scope="module")
def office_map():
    m1, _ = map_pair("office", (5, 4), (9, 4), np.array([1.0, 2.0, 1.2]))
    return m1


def test_runs_follow_the_skeleton_with_exact_odometry(office_map):
    config = VirtualRobotConfig()
    graph = free_space_graph(office_map, config.skeleton)
    runs = virtual_robot_runs(office_map, config=config, rng=np.random.default_rng(0), graph=graph)
    assert 6 <= len(runs) <= config.max_runs
    skeleton_points = office_map.cell_to_world(np.argwhere(graph.skeleton))
    for run in runs:
        poses = run.poses_in_map1
        assert poses.shape[1] == 3 and len(poses) >= 2
        assert run.ranges.shape == (len(poses), config.n_beams)
        # Samples every `step` of arc length (chords on bends are shorter).
        assert (len(poses) - 1) * config.step >= config.min_run_length - 1e-9
        assert run.length <= config.run_length + 1e-9
        steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        assert np.all(steps <= config.step + 1e-9)
        # On the skeleton (within a cell) and heading along the path.
        gaps = np.min(
            np.hypot(*(poses[:, None, :2] - skeleton_points[None]).transpose(2, 0, 1)), axis=1
        )
        assert gaps.max() <= office_map.resolution * 1.5
        travel = np.arctan2(*np.diff(poses[:, :2], axis=0)[:, ::-1].T)
        assert np.median(np.abs(wrap_angle(travel - poses[:-1, 2]))) < 0.35
        # Exact odometry chains back to the poses, and the scans are those of the poses.
        chained = poses[0]
        for motion in run.odometry:
            chained = compose(chained, motion)
        np.testing.assert_allclose(chained, poses[-1], atol=1e-9)
        np.testing.assert_array_equal(
            run.ranges, simulate_scans(office_map, poses, run.beam_angles, run.max_range)
        )
        assert 0 <= run.branch < len(graph.edges)
    # Spread over the map: run midpoints are not bunched together.
    middles = np.array([run.poses_in_map1[len(run.poses_in_map1) // 2, :2] for run in runs])
    pairwise = np.hypot(*(middles[:, None] - middles[None]).transpose(2, 0, 1))
    np.fill_diagonal(pairwise, np.inf)
    assert np.median(pairwise.min(axis=1)) > 0.8


def test_noisy_odometry_is_seeded_and_close(office_map):
    config = VirtualRobotConfig(odometry_translation_noise=0.05, odometry_rotation_noise=0.05)
    a = virtual_robot_runs(office_map, config=config, rng=np.random.default_rng(4))
    b = virtual_robot_runs(office_map, config=config, rng=np.random.default_rng(4))
    assert len(a) == len(b) > 0
    for run_a, run_b in zip(a, b, strict=True):
        np.testing.assert_array_equal(run_a.odometry, run_b.odometry)
        exact = odometry_between(run_a.poses_in_map1)
        error = run_a.odometry - exact
        assert np.abs(error).max() > 0
        assert np.abs(error[:, :2]).max() < 0.1 and np.abs(error[:, 2]).max() < 0.1


def test_maps_without_a_usable_skeleton_give_no_runs():
    cells = np.full((30, 30), UNKNOWN, dtype=np.int8)
    cells[14:16, 14:16] = FREE
    grid = GridMap(cells=cells, resolution=0.05)
    assert virtual_robot_runs(grid, rng=np.random.default_rng(0)) == []


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match=r"VirtualRobotConfig\.step"):
        VirtualRobotConfig(step=0.0)
    with pytest.raises(ValueError, match=r"VirtualRobotConfig\.n_beams"):
        VirtualRobotConfig(n_beams=0)
    with pytest.raises(ValueError, match=r"VirtualRobotConfig\.min_run_length"):
        VirtualRobotConfig(run_length=1.0, min_run_length=2.0)
