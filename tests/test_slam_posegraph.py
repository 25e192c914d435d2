"""The pose graph (mrslam_env.slam.posegraph), loop-closure matching
(mrslam_env.slam.loop_closure) and SLAM mode ``pose_graph`` (mrslam_env.slam.backend,
RobotSlam)."""

from __future__ import annotations

import dataclasses
import inspect
import math
import pickle

import numpy as np
import pytest
from slam_worlds import corridor_world, noisy_scan, ring_path, ring_world
from test_slam_robot import noisy_odometry, room_world

from mrslam_env.evaluation import absolute_trajectory_error, map_agreement
from mrslam_env.geometry import compose, inverse
from mrslam_env.sim.world import ground_truth_map
from mrslam_env.slam.config import SLAM_MODES, MatcherConfig, PoseGraphConfig, SlamConfig
from mrslam_env.slam.grid import OccupancyGrid
from mrslam_env.slam.loop_closure import match_loop, peak_ratio
from mrslam_env.slam.posegraph import PoseGraph
from mrslam_env.slam.slam import RobotSlam

# --- the optimiser on synthetic graphs ----------------------------------------------------


def square_path() -> np.ndarray:
    """40 poses 1 m apart round a 10 m square, heading along it."""
    poses = []
    for side in range(4):
        heading = side * math.pi / 2
        for k in range(10):
            x, y = [(k, 0), (10, k), (10 - k, 10), (0, 10 - k)][side]
            poses.append([x, y, heading])
    return np.array(poses, dtype=np.float64)


ODOMETRY_STD = np.array([0.01, 0.01, math.radians(0.5)])
LOOP_STD = np.array([0.05, 0.05, math.radians(1.0)])


def square_graph(seed: int, *, offset: int = 0) -> tuple[PoseGraph, np.ndarray]:
    """The square with noisy odometry edges (ids ``offset + k``), the first node fixed at
    the truth, the others at dead reckoning; no loop edge yet."""
    truth = square_path()
    rng = np.random.default_rng(seed)
    graph = PoseGraph()
    graph.add_node(offset, truth[0], fixed=True)
    estimate = truth[0]
    for k in range(1, len(truth)):
        measured = compose(inverse(truth[k - 1]), truth[k]) + rng.normal(0.0, ODOMETRY_STD)
        estimate = compose(estimate, measured)
        graph.add_node(offset + k, estimate)
        graph.add_edge(offset + k - 1, offset + k, measured, np.diag(ODOMETRY_STD**-2.0))
    return graph, truth


def rmse(graph: PoseGraph, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((graph.poses[:, :2] - truth[:, :2]) ** 2, axis=1))))


def add_true_loop(graph: PoseGraph, truth: np.ndarray, offset: int = 0) -> None:
    measured = compose(inverse(truth[-1]), truth[0])
    graph.add_edge(offset + len(truth) - 1, offset, measured, np.diag(LOOP_STD**-2.0), "loop")


def test_a_loop_edge_straightens_a_drifting_square() -> None:
    graph, truth = square_graph(0)
    before = rmse(graph, truth)
    add_true_loop(graph, truth)
    result = graph.optimize()
    assert before > 0.2, "the odometry must drift for this test to mean anything"
    assert rmse(graph, truth) < 0.1
    assert rmse(graph, truth) < before / 3
    assert result.converged
    assert result.final_cost < result.initial_cost
    np.testing.assert_allclose(result.loop_weights, [1.0], atol=0.1)  # a true closure stays in


def test_the_first_node_stays_fixed_and_the_answer_is_deterministic() -> None:
    answers = []
    for _ in range(2):
        graph, truth = square_graph(1)
        add_true_loop(graph, truth)
        graph.optimize()
        assert graph.pose(0).tolist() == truth[0].tolist()
        answers.append(graph.poses)
    np.testing.assert_array_equal(answers[0], answers[1])


def test_a_false_loop_edge_is_switched_off() -> None:
    # The reference: the square closed by its true loop edge alone.
    reference, truth = square_graph(2)
    add_true_loop(reference, truth)
    reference.optimize()
    graph, _ = square_graph(2)
    add_true_loop(graph, truth)
    # A false closure between opposite corners, 1.5 m off: least squares bends the square.
    false = compose(inverse(truth[10]), truth[30]) + np.array([1.5, 0.5, 0.0])
    graph.add_edge(10, 30, false, np.diag(LOOP_STD**-2.0), "loop")
    bent = {}
    for robust in ("none", "huber"):
        other = pickle.loads(pickle.dumps(graph))
        other.optimize(robust=robust)  # type: ignore[arg-type]
        bent[robust] = float(np.abs(other.poses[:, :2] - reference.poses[:, :2]).max())
    result = graph.optimize(robust="switchable")
    true_weight, false_weight = result.loop_weights
    assert false_weight < 0.01 and true_weight > 0.9
    # Switched off, the false edge leaves the graph where the true one put it. Huber only
    # bounds its pull: on a chain this soft it still bends the square (why the default
    # kernel is "switchable").
    assert np.abs(graph.poses[:, :2] - reference.poses[:, :2]).max() < 0.01
    assert rmse(graph, truth) < 0.1
    assert bent["none"] > 0.5
    assert 0.1 < bent["huber"] < bent["none"]


def test_robots_graphs_join_with_their_own_node_ids() -> None:
    # Two robots' squares in one graph: ids 0.. and 1_000_000.., one inter-robot edge
    # (robot 1's start seen from robot 0's start) and only robot 0's first node fixed.
    graph, truth = square_graph(3)
    second, _ = square_graph(4, offset=1_000_000)
    add_true_loop(graph, truth)
    shift = np.array([0.3, -0.2, 0.1])  # robot 1's nodes start off where it believes
    for node_id, pose in zip(second.node_ids, second.poses, strict=True):
        graph.add_node(node_id, compose(shift, pose))
    for edge in second.edges:
        graph.add_edge(edge.i, edge.j, edge.measurement, edge.information, edge.kind)
    add_true_loop(graph, truth, offset=1_000_000)
    graph.add_edge(0, 1_000_000, [0.0, 0.0, 0.0], np.diag(LOOP_STD**-2.0), "loop")
    graph.optimize()
    robot_1 = np.array([graph.pose(1_000_000 + k) for k in range(len(truth))])
    assert np.abs(robot_1[0]).max() < 0.02  # pulled onto robot 0's start
    assert np.sqrt(np.mean(np.sum((robot_1[:, :2] - truth[:, :2]) ** 2, axis=1))) < 0.1


def test_graph_inputs_are_validated() -> None:
    graph = PoseGraph()
    graph.add_node(5, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="already exists"):
        graph.add_node(5, [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="finite"):
        graph.add_node(6, [math.nan, 0.0, 0.0])
    graph.add_node(7, [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="existing nodes"):
        graph.add_edge(5, 8, [1.0, 0.0, 0.0], np.eye(3))
    with pytest.raises(ValueError, match="semi-definite"):
        graph.add_edge(5, 7, [1.0, 0.0, 0.0], -np.eye(3))
    with pytest.raises(ValueError, match="kind"):
        graph.add_edge(5, 7, [1.0, 0.0, 0.0], np.eye(3), "odom")  # type: ignore[arg-type]
    graph.add_edge(5, 7, [1.0, 0.0, 0.0], np.eye(3))
    with pytest.raises(ValueError, match="fixed node"):
        graph.optimize()


# --- loop-closure matching -----------------------------------------------------------------


def submap_of(world: object, poses: np.ndarray, seed: int) -> OccupancyGrid:
    rng = np.random.default_rng(seed)
    grid = OccupancyGrid()
    for pose in poses:
        grid.integrate_scan(pose, noisy_scan(world, pose, rng), 8.0)  # type: ignore[arg-type]
    return grid


def test_peak_ratio_is_the_best_distinct_score_over_the_best() -> None:
    planar = np.zeros((7, 7))
    planar[3, 3], planar[3, 4], planar[0, 6] = 1.0, 0.95, 0.6
    assert peak_ratio(planar, (3, 3), 0.1, 0.25) == pytest.approx(0.6)  # (3, 4) is too near
    assert peak_ratio(planar, (3, 3), 0.1, 0.05) == pytest.approx(0.95)
    assert peak_ratio(planar, (3, 3), 0.1, 10.0) == 0.0  # nothing that far


def test_a_closure_with_a_clear_margin_is_accepted_and_accurate() -> None:
    world = room_world()
    truth = np.array([4.0, 1.0, 0.3])
    submap = submap_of(world, np.array([[1.5, 1.0, 0.0], [2.5, 1.2, 0.5], [6.0, 4.0, 2.5]]), 0)
    scan = noisy_scan(world, truth, np.random.default_rng(1))
    predicted = truth + np.array([0.2, -0.15, math.radians(2.5)])  # drift since last tied
    config = PoseGraphConfig()
    result = match_loop(
        submap, scan, 8.0, predicted, 0.4, math.radians(4.0), config, MatcherConfig()
    )
    assert result.accepted, result.reason
    assert result.peak_ratio < config.loop_max_peak_ratio - 0.1  # a clear margin
    assert result.score > config.loop_min_score + 0.1
    np.testing.assert_allclose(result.pose[:2], truth[:2], atol=0.01)
    assert abs(result.pose[2] - truth[2]) < math.radians(0.2)


def test_a_closure_along_a_featureless_corridor_is_refused() -> None:
    world = corridor_world()
    submap = submap_of(world, np.array([[x, 0.0, 0.0] for x in np.arange(-2.0, 2.1, 0.5)]), 2)
    truth = np.array([0.3, 0.0, 0.0])
    scan = noisy_scan(world, truth, np.random.default_rng(3))
    predicted = truth + np.array([0.25, 0.05, 0.01])
    result = match_loop(
        submap, scan, 8.0, predicted, 0.6, math.radians(3.0), PoseGraphConfig(), MatcherConfig()
    )
    # Every position along the corridor scores alike: no unique best.
    assert not result.accepted
    assert result.reason == "ambiguous"
    assert result.peak_ratio > 0.95


# --- the mode end to end ------------------------------------------------------------------


def run_ring(mode: str) -> tuple[RobotSlam, np.ndarray]:
    """A lap and a bit round a ring corridor (54 m): along its long sides odometry alone
    says how far the robot went, so the map stretches until the loop closes."""
    world = ring_world()
    path = ring_path(18.0, 10.0, 0.1, 1.12)
    rng = np.random.default_rng(0)
    odometry = noisy_odometry(path, rng)
    slam = RobotSlam(SlamConfig(mode=mode), 360, 8.0)  # type: ignore[arg-type]
    for pose, odom in zip(path, odometry, strict=True):
        slam.update(odom, noisy_scan(world, pose, rng))
    return slam, path


def test_pose_graph_closes_the_loop_that_slam_mode_leaves_open() -> None:
    slam, path = run_ring("slam")
    graph, _ = run_ring("pose_graph")
    raster = ground_truth_map(ring_world(), 0.05, margin=1.0)
    ate_slam = absolute_trajectory_error(slam.trajectory, path, path[0])
    ate_graph = absolute_trajectory_error(graph.optimized_trajectory, path, path[0])
    assert ate_slam > 0.07, "slam mode must drift here for this test to mean anything"
    assert ate_graph < 0.065
    assert ate_graph < 0.6 * ate_slam
    assert graph.backend is not None and graph.backend.n_closures >= 1
    assert graph.n_rerenders >= 1
    agreement_slam = map_agreement(slam.grid.to_gridmap(), path[0], raster)
    agreement_graph = map_agreement(graph.grid.to_gridmap(), path[0], raster)
    assert agreement_graph > agreement_slam + 0.005
    assert agreement_graph >= 0.985
    # The pose the robot reports and map_from_odom moved with the graph.
    np.testing.assert_allclose(graph.pose, graph.trajectory[-1])
    assert graph.backend.graph.pose(0).tolist() == [0.0, 0.0, 0.0]


def test_pose_graph_mode_keeps_map_from_odom_and_continues_after_a_copy() -> None:
    rng = np.random.default_rng(5)
    world = room_world()
    path = np.concatenate([ring_like_room_loop(), ring_like_room_loop()[1:]])
    odometry = noisy_odometry(path, rng)
    scans = [noisy_scan(world, pose, rng) for pose in path]
    slam = RobotSlam(SlamConfig(mode="pose_graph"), 360, 8.0)
    for odom, scan in zip(odometry[:200], scans[:200], strict=True):
        pose = slam.update(odom, scan)
        np.testing.assert_allclose(compose(slam.map_from_odom, odom), pose, atol=1e-9)
    copy = pickle.loads(pickle.dumps(slam))
    for odom, scan in zip(odometry[200:], scans[200:], strict=True):
        np.testing.assert_array_equal(slam.update(odom, scan), copy.update(odom, scan))
    np.testing.assert_array_equal(slam.grid.log_odds, copy.grid.log_odds)
    assert slam.n_integrated == len(slam.backend.scans)  # type: ignore[union-attr]
    assert slam.optimized_trajectory.shape == slam.trajectory.shape


def ring_like_room_loop() -> np.ndarray:
    """A smooth loop round the room's middle wall, 0.06 m per step (world frame)."""
    t = np.linspace(0.0, 2.0 * np.pi, 180)
    x, y = 4.0 + 2.6 * np.cos(t), 2.5 + 1.45 * np.sin(t)
    return np.column_stack([x, y, np.arctan2(np.gradient(y), np.gradient(x))])


# --- configuration --------------------------------------------------------------------------


def test_pose_graph_config_fields_are_documented_and_validated() -> None:
    text = inspect.getsource(PoseGraphConfig)
    for field in dataclasses.fields(PoseGraphConfig):
        declaration = text.split(f"    {field.name}:", 1)[1]
        assert declaration.split("\n", 2)[1].strip().startswith('"""'), field.name
    for name, value in [
        ("node_translation", 0.0),
        ("loop_min_score", 1.5),
        ("loop_max_peak_ratio", -0.1),
        ("robust", "cauchy"),
        ("local_map_scans", 0),
        ("loop_window_xy_max", 0.1),
    ]:
        with pytest.raises(ValueError, match=f"PoseGraphConfig.{name}"):
            PoseGraphConfig(**{name: value})
    assert "pose_graph" in SLAM_MODES
    assert SlamConfig().mode == "slam"  # not the default (yet)


def test_the_command_line_knows_every_slam_mode() -> None:
    from scenarios import cli
    from scenarios.experiment import RunConfig

    assert cli.SLAM_MODES == SLAM_MODES
    args = cli._build_parser().parse_args(["run", "--slam-mode", "pose_graph"])
    assert args.slam_mode == "pose_graph"
    with pytest.raises(ValueError, match="slam_mode"):
        RunConfig(slam_mode="lidar")  # type: ignore[arg-type]
