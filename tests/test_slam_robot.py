"""Per-robot SLAM (mrslam_env.slam.slam.RobotSlam), its evaluation helpers, the benchmark,
and the layering rule for the SLAM package."""

from __future__ import annotations

import math
import pickle
import subprocess
import sys

import numpy as np
import pytest
from slam_worlds import corridor_world, noisy_scan

from mrslam_env.config import OdometryConfig
from mrslam_env.evaluation import absolute_trajectory_error, map_agreement
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import GridMap
from mrslam_env.sim.sensors import (
    apply_odometry_increments,
    odometry_increments,
    sample_odometry_increments,
)
from mrslam_env.sim.world import WorldSpec, box, ground_truth_map
from mrslam_env.slam.config import SlamConfig
from mrslam_env.slam.slam import RobotSlam


def room_world() -> WorldSpec:
    t = 0.1
    walls = [
        box(-t, -t, 8.0 + t, 0.0),
        box(-t, 5.0, 8.0 + t, 5.0 + t),
        box(-t, -t, 0.0, 5.0 + t),
        box(8.0, -t, 8.0 + t, 5.0 + t),
        box(3.0, 2.0, 5.0, 2.1),
        box(6.5, 0.8, 6.9, 1.6),
    ]
    return WorldSpec.from_walls("room", walls, [[1.5, 1.0, 0.0]])


def loop_path(n_steps: int) -> np.ndarray:
    """A smooth loop around the room's middle wall, 0.06 m per step (world frame)."""
    t = np.linspace(0.0, 2.0 * np.pi, n_steps)
    x = 4.0 + 2.6 * np.cos(t)
    y = 2.5 + 1.45 * np.sin(t)
    heading = np.arctan2(np.gradient(y), np.gradient(x))
    return np.column_stack([x, y, heading])


def noisy_odometry(path: np.ndarray, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """Dead reckoning along a path with the simulator's four-alpha noise (odom frame)."""
    config = OdometryConfig()
    odometry = np.zeros((len(path), 3))
    for k in range(1, len(path)):
        increments = odometry_increments(path[k - 1][None], path[k][None])
        increments[:, 1] *= scale
        noisy = sample_odometry_increments(increments, config, rng)
        odometry[k] = apply_odometry_increments(odometry[k - 1][None], noisy)[0]
    return odometry


# --- frames and modes --------------------------------------------------------------------------


def test_map_frame_is_the_first_odometry_pose() -> None:
    rng = np.random.default_rng(0)
    world = room_world()
    path = loop_path(40)
    odometry = compose(np.array([1.0, -2.0, 0.7]), noisy_odometry(path, rng))  # odom not at 0
    slam = RobotSlam(SlamConfig(mode="odometry"), 360, 8.0)
    for pose, odom in zip(path, odometry, strict=True):
        estimate = slam.update(odom, noisy_scan(world, pose, rng))
        expected = compose(inverse(odometry[0]), odom)
        np.testing.assert_allclose(estimate, expected, atol=1e-12)
        np.testing.assert_allclose(compose(slam.map_from_odom, odom), estimate, atol=1e-12)
    trajectory = slam.trajectory
    assert trajectory.shape == (40, 3)
    np.testing.assert_array_equal(trajectory[0], [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(slam.pose, trajectory[-1])
    assert slam.last_match is None  # no matching in odometry mode


def test_ground_truth_mode_uses_the_true_pose() -> None:
    rng = np.random.default_rng(1)
    world = room_world()
    path = loop_path(30)
    odometry = noisy_odometry(path, rng)
    slam = RobotSlam(SlamConfig(mode="ground_truth"), 360, 8.0)
    with pytest.raises(ValueError, match="true_pose_in_map"):
        slam.update(odometry[0], noisy_scan(world, path[0], rng))
    for pose, odom in zip(path, odometry, strict=True):
        truth = compose(inverse(path[0]), pose)
        np.testing.assert_array_equal(slam.update(odom, noisy_scan(world, pose, rng), truth), truth)


def test_motion_filter_integrates_only_after_enough_motion() -> None:
    rng = np.random.default_rng(2)
    world = room_world()
    config = SlamConfig(
        min_translation=0.1,
        min_rotation=math.radians(5),
        map_update_translation=0.1,
        map_update_rotation=math.radians(5),
    )
    slam = RobotSlam(config, 360, 8.0)
    start = np.array([1.5, 1.0, 0.0])
    slam.update([0.0, 0.0, 0.0], noisy_scan(world, start, rng))
    assert slam.n_integrated == 1
    for k in range(1, 4):  # 3 cm per step: below the filter
        odom = np.array([0.03 * k, 0.0, 0.0])
        pose = slam.update(odom, noisy_scan(world, start + np.array([0.03 * k, 0, 0]), rng))
        np.testing.assert_allclose(pose, odom)  # propagated by odometry
        assert slam.n_integrated == 1
    slam.update([0.12, 0.0, 0.0], noisy_scan(world, start + np.array([0.12, 0, 0]), rng))
    assert slam.n_integrated == 2 and slam.last_match is not None
    slam.update(
        [0.12, 0.0, 0.1], noisy_scan(world, start + np.array([0.12, 0, 0.1]), rng)
    )  # a turn
    assert slam.n_integrated == 3


def test_scans_between_map_updates_are_matched_but_not_integrated() -> None:
    rng = np.random.default_rng(3)
    world = room_world()
    config = SlamConfig(map_update_translation=0.25, map_update_rotation=math.radians(20))
    slam = RobotSlam(config, 360, 8.0)
    start = np.array([1.5, 1.0, 0.0])
    slam.update([0.0, 0.0, 0.0], noisy_scan(world, start, rng))
    # Odometry overshoots by 2 cm a step; the matches must correct it every step, while the
    # map is left alone until the robot is 0.25 m from where it last integrated a scan.
    for k in range(1, 8):
        truth = np.array([0.1 * k, 0.0, 0.0])
        odom = np.array([0.12 * k, 0.0, 0.0])
        pose = slam.update(odom, noisy_scan(world, start + truth, rng))
        assert slam.last_match is not None and slam.last_match.accepted
        np.testing.assert_allclose(pose[:2], truth[:2], atol=0.01)
        assert slam.n_integrated == 1 + (k >= 3) + (k >= 6), k
    slam.update([0.84, 0.0, 0.4], noisy_scan(world, start + np.array([0.7, 0.0, 0.4]), rng))
    assert slam.n_integrated == 4  # a 23 degree turn


def test_scans_are_matched_against_the_map_of_match_lag_scans_ago() -> None:
    from mrslam_env.slam.grid import OccupancyGrid

    rng = np.random.default_rng(5)
    world = room_world()
    start = np.array([1.5, 1.0, 0.0])
    slam = RobotSlam(SlamConfig(match_lag=3), 360, 8.0)
    scans, poses = [], []
    for k in range(8):  # 0.1 m a step: every scan is integrated
        scans.append(noisy_scan(world, start + np.array([0.1 * k, 0.0, 0.0]), rng))
        poses.append(slam.update([0.1 * k, 0.0, 0.0], scans[-1]))
    assert slam.n_integrated == 8
    # The map itself takes every scan at once; the matched one all but the last 3.
    for grid, n in ((slam.grid, 8), (slam._matched_grid, 5)):
        expected = OccupancyGrid(slam.config.grid)
        for pose, scan in zip(poses[:n], scans[:n], strict=True):
            expected.integrate_scan(pose, scan, 8.0)
        np.testing.assert_array_equal(grid.log_odds, expected.log_odds)
    unlagged = RobotSlam(SlamConfig(match_lag=0), 360, 8.0)
    assert unlagged._matched_grid is unlagged.grid


def test_a_rejected_match_brings_the_matched_map_up_to_date() -> None:
    rng = np.random.default_rng(6)
    world = room_world()
    start = np.array([1.5, 1.0, 0.0])
    slam = RobotSlam(SlamConfig(match_lag=5), 360, 8.0)
    for k in range(4):
        slam.update(
            [0.1 * k, 0.0, 0.0], noisy_scan(world, start + np.array([0.1 * k, 0.0, 0.0]), rng)
        )
    assert len(slam._waiting) == 3
    slam.update([0.5, 0.0, 0.0], np.full(360, 8.0))  # no returns: the match is rejected
    assert slam.last_match is not None and not slam.last_match.accepted
    assert not slam._waiting
    np.testing.assert_array_equal(slam._matched_grid.log_odds, slam.grid.log_odds)


def test_a_spin_at_the_start_of_a_real_building_holds_the_heading() -> None:
    # Turning on the spot in `small_house` (walls rasterised from a map): matched against
    # a map of one scan, each scan's heading is off by up to ~0.15 degrees. Matched against
    # the current map, each scan inherits the last ones' errors and the heading settles
    # about a quarter degree off; matched against the map of 20 scans ago, the first
    # scans are all placed against the start scan and their errors average out.
    from mrslam_env.registry import build_world

    world = build_world("small_house")
    start = np.asarray(world.starts[0], dtype=np.float64)
    path = start + np.array([[0.0, 0.0, -math.radians(5.0) * k] for k in range(72)])
    odometry = noisy_odometry(path, np.random.default_rng([0, 1]))
    scans = [noisy_scan(world, pose, np.random.default_rng([0, k])) for k, pose in enumerate(path)]
    truth = compose(inverse(path[0]), path)
    off = {}
    for lag in (0, SlamConfig().match_lag):
        slam = RobotSlam(SlamConfig(match_lag=lag), 360, 8.0)
        for odom, scan in zip(odometry, scans, strict=True):
            slam.update(odom, scan)
        error = np.degrees(
            np.abs(np.remainder(slam.trajectory[:, 2] - truth[:, 2] + np.pi, 2 * np.pi) - np.pi)
        )
        off[lag] = float(np.mean(error[36:]))  # the second turn
    assert off[0] > 0.2, "the current map must let the heading settle off for this test"
    assert off[SlamConfig().match_lag] < 0.15


def test_inputs_are_validated() -> None:
    with pytest.raises(ValueError, match="n_beams"):
        RobotSlam(None, 2, 8.0)
    with pytest.raises(ValueError, match="max_range"):
        RobotSlam(None, 360, -1.0)
    slam = RobotSlam(None, 360, 8.0)
    with pytest.raises(ValueError, match="ranges"):
        slam.update([0.0, 0.0, 0.0], np.ones(180))
    with pytest.raises(ValueError, match="odom_pose"):
        slam.update([0.0, math.nan, 0.0], np.ones(360))
    assert slam.trajectory.shape == (0, 3)


# --- SLAM itself ---------------------------------------------------------------------------------


def test_a_copied_slam_continues_identically() -> None:
    rng = np.random.default_rng(5)
    world = room_world()
    path = loop_path(60)
    odometry = noisy_odometry(path, rng)
    scans = [noisy_scan(world, pose, rng) for pose in path]
    slam = RobotSlam(SlamConfig(), 360, 8.0)
    for odom, scan in zip(odometry[:30], scans[:30], strict=True):
        slam.update(odom, scan)
    copy = pickle.loads(pickle.dumps(slam))
    for odom, scan in zip(odometry[30:], scans[30:], strict=True):
        np.testing.assert_array_equal(slam.update(odom, scan), copy.update(odom, scan))
    np.testing.assert_array_equal(slam.grid.log_odds, copy.grid.log_odds)
    np.testing.assert_array_equal(slam._matched_grid.fine_fields, copy._matched_grid.fine_fields)


def test_slam_beats_dead_reckoning_around_a_room() -> None:
    rng = np.random.default_rng(3)
    world = room_world()
    path = np.concatenate([loop_path(180), loop_path(180)[1:]])
    odometry = noisy_odometry(path, rng)
    slam = RobotSlam(SlamConfig(), 360, 8.0)
    dead_reckoning = RobotSlam(SlamConfig(mode="odometry"), 360, 8.0)
    for pose, odom in zip(path, odometry, strict=True):
        scan = noisy_scan(world, pose, rng)
        slam.update(odom, scan)
        dead_reckoning.update(odom, scan)
    ate_slam = absolute_trajectory_error(slam.trajectory, path, path[0])
    ate_odometry = absolute_trajectory_error(dead_reckoning.trajectory, path, path[0])
    assert ate_odometry > 0.1, "the odometry must drift for this test to mean anything"
    assert ate_slam < 0.03
    assert ate_slam < ate_odometry / 5
    assert slam.n_rejected == 0
    raster = ground_truth_map(world, 0.05, margin=1.0)
    assert map_agreement(slam.grid.to_gridmap(), path[0], raster) >= 0.97
    assert map_agreement(dead_reckoning.grid.to_gridmap(), path[0], raster) < 0.97


def test_slam_in_a_featureless_corridor_follows_odometry_along_it() -> None:
    rng = np.random.default_rng(4)
    world = corridor_world()
    n = 60
    path = np.column_stack(
        [np.linspace(0.0, 3.0, n), 0.1 * np.sin(np.linspace(0, 3, n)), np.zeros(n)]
    )
    path[:, 2] = np.arctan2(np.gradient(path[:, 1]), np.gradient(path[:, 0]))
    odometry = noisy_odometry(path, rng, scale=1.2)  # 20 % too long along the corridor
    slam = RobotSlam(SlamConfig(), 360, 8.0)
    matched = []
    for pose, odom in zip(path, odometry, strict=True):
        before = slam.n_matched - slam.n_rejected
        slam.update(odom, noisy_scan(world, pose, rng))
        matched.append(slam.n_matched - slam.n_rejected > before)
    assert sum(matched) > 40
    # In the world frame (the map frame is the start pose), x runs along the corridor.
    estimate = compose(path[0], slam.trajectory)
    odometry_in_world = compose(path[0], compose(inverse(odometry[0]), odometry))
    # Along the corridor nothing can be measured: the estimate stays with odometry, no
    # jumps (each step moves about as far as odometry says) ...
    np.testing.assert_allclose(np.diff(estimate[:, 0]), np.diff(odometry_in_world[:, 0]), atol=0.01)
    assert estimate[-1, 0] > path[-1, 0] + 0.3  # the 20 % overshoot was kept
    # ... while across it, and in heading, the walls correct the drift (on the steps that
    # were matched; in between the pose follows odometry).
    assert np.max(np.abs(estimate[matched, 1] - path[matched, 1])) < 0.01
    assert np.max(np.abs(estimate[matched, 2] - path[matched, 2])) < math.radians(0.5)
    assert np.max(np.abs(odometry_in_world[:, 1] - path[:, 1])) > 0.02
    assert slam.last_match is not None and slam.last_match.reason == "degenerate"


def test_short_scenario_run_slam_is_much_better_than_odometry() -> None:
    from scenarios.bench.slam import format_slam_table, run_slam_benchmark

    (row,) = run_slam_benchmark(["office"], steps=600, seed=0)
    assert row["ate_odometry"] > 0.1
    assert row["ate_slam"] < 0.05
    assert row["ratio"] < 1.0 / 3.0
    assert row["map_agreement"] >= 0.97
    assert row["steps_per_s"] > 0 and row["update_ms"] > 0
    # The pose graph replays the same data beside the scan matcher, no worse on it.
    assert row["ate_pose_graph"] < row["ate_slam"] + 0.005
    assert row["map_agreement_pose_graph"] >= 0.97
    assert len(row["loop_closures_per_robot"]) == 2
    assert "office" in format_slam_table([row])


def test_bench_slam_covers_the_real_buildings() -> None:
    from scenarios.bench.slam import (
        BUILT_IN_SCENARIOS,
        DEFAULT_SCENARIOS,
        REAL_BUILDINGS,
        format_slam_table,
        run_slam_benchmark,
    )

    assert DEFAULT_SCENARIOS == BUILT_IN_SCENARIOS + REAL_BUILDINGS
    assert {"aws_warehouse", "bookstore", "small_house", "tb3_sandbox"} <= set(REAL_BUILDINGS)
    (row,) = run_slam_benchmark(["tb3_sandbox"], steps=200, seed=0)
    assert row["ate_slam"] < row["ate_odometry"]
    assert row["map_agreement"] > 0.9
    assert format_slam_table([row]).splitlines()[2].startswith("tb3_sandbox ")


# --- evaluation helpers ---------------------------------------------------------------------


def test_absolute_trajectory_error() -> None:
    truth = np.array([[1.0, 2.0, 0.5], [2.0, 2.0, 0.5], [3.0, 2.0, 0.5]])
    start = truth[0]
    in_map = compose(inverse(start), truth)
    assert absolute_trajectory_error(in_map, truth, start) == pytest.approx(0.0, abs=1e-12)
    shifted = compose(inverse(start), truth + np.array([0.0, 0.3, 0.0]))
    assert absolute_trajectory_error(shifted, truth, start) == pytest.approx(0.3)
    with pytest.raises(ValueError):
        absolute_trajectory_error(in_map[:2], truth, start)


def test_map_agreement_definition() -> None:
    cells = np.full((10, 10), -1, dtype=np.int8)
    truth = GridMap(cells=np.zeros((10, 10), dtype=np.int8), resolution=0.1)
    truth.cells[5, :] = 100  # a wall along row 5
    estimate_cells = cells.copy()
    estimate_cells[4, 2:8] = 100  # one cell off the wall: still agrees
    estimate_cells[1, 2:8] = 0  # free where it is free
    estimate = GridMap(cells=estimate_cells, resolution=0.1)
    assert map_agreement(estimate, [0.0, 0.0, 0.0], truth) == 1.0
    estimate_cells[2, 2:8] = 100  # three cells off: wrong
    estimate_cells[5, 2:4] = 0  # free on the wall: wrong
    value = map_agreement(GridMap(cells=estimate_cells, resolution=0.1), [0.0, 0.0, 0.0], truth)
    assert value == pytest.approx(12 / 20)
    assert map_agreement(GridMap(cells=cells, resolution=0.1), [0, 0, 0], truth) == 1.0


# --- layering ----------------------------------------------------------------------------------


def test_slam_package_stays_light() -> None:
    code = (
        "import sys; import mrslam_env.slam.slam, mrslam_env.evaluation; "
        "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = set(run.stdout.split())
    for heavy in ("pymunk", "pettingzoo", "rerun", "gymnasium", "agents", "scenarios"):
        assert heavy not in loaded
