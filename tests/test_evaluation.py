"""Scores against ground truth (mrslam_env.evaluation): the error of a merge transform, the
true overlap of two maps, the coverage of the world. (ATE and map agreement are tested
with the SLAM that they score, in tests/test_slam_robot.py.)"""

from __future__ import annotations

import math

import numpy as np
import pytest
from merge_fixtures import in_frame, room_map

from mrslam_env.evaluation import (
    PLANNER_MARGIN,
    CoverageEvaluator,
    relative_transform_error,
    true_overlap,
)
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import UNKNOWN, GridMap
from mrslam_env.registry import build_world
from mrslam_env.sim.world import WorldSpec, box, ground_truth_map

TRUTH = np.array([1.0, -2.0, 0.5])


# --- relative_transform_error --------------------------------------------------------------


def test_relative_transform_error_wraps_the_angle() -> None:
    translation, rotation = relative_transform_error(
        [1.0, 2.0, math.pi - 0.01], [1.3, 2.4, -math.pi + 0.01]
    )
    assert translation == pytest.approx(0.5)
    assert rotation == pytest.approx(0.02)
    assert relative_transform_error(TRUTH, TRUTH) == (0.0, 0.0)
    assert relative_transform_error(TRUTH, TRUTH, [3.0, -4.0]) == (0.0, 0.0)


def test_relative_transform_error_is_measured_at_the_pivot() -> None:
    pivot = np.array([4.0, 1.5])
    # A turn about the pivot's image moves nothing there, and the frame origin far.
    turn = np.array([0.0, 0.0, 0.1])
    about = transform_points(TRUTH, pivot[None, :])[0]
    to_pivot = np.array([about[0], about[1], 0.0])
    estimate = compose(compose(to_pivot, turn), compose(inverse(to_pivot), TRUTH))
    at_pivot, rotation = relative_transform_error(estimate, TRUTH, pivot)
    at_origin, _ = relative_transform_error(estimate, TRUTH)
    assert at_pivot == pytest.approx(0.0, abs=1e-12)
    assert rotation == pytest.approx(0.1)
    assert at_origin == pytest.approx(2 * math.hypot(*pivot) * math.sin(0.05))
    # In general: the distance between the two images of the pivot.
    other = TRUTH + np.array([0.3, -0.2, 0.05])
    images = transform_points(other, pivot[None, :]) - transform_points(TRUTH, pivot[None, :])
    assert relative_transform_error(other, TRUTH, pivot)[0] == pytest.approx(math.hypot(*images[0]))


def test_relative_transform_error_is_symmetric_in_the_translation() -> None:
    other = TRUTH + np.array([0.3, -0.2, 0.05])
    forward = relative_transform_error(other, TRUTH, [2.0, 1.0])
    backward = relative_transform_error(TRUTH, other, [2.0, 1.0])
    assert forward == pytest.approx(backward)


# --- true_overlap ----------------------------------------------------------------------------


def test_true_overlap_of_shifted_copies() -> None:
    grid = room_map()
    assert true_overlap(grid, grid, np.zeros(3)) == pytest.approx(1.0)
    assert true_overlap(grid, grid, np.array([20.0, 0.0, 1.0])) == 0.0
    # Shifting by half the width overlaps half of each map.
    half = grid.extent[2] / 2
    assert true_overlap(grid, grid, np.array([half, 0.0, 0.0])) == pytest.approx(0.5, abs=0.02)
    # A rotated copy seen through the true transform overlaps itself completely.
    rotated = in_frame(grid, TRUTH)
    assert true_overlap(grid, rotated, TRUTH) == pytest.approx(1.0, abs=0.03)


def test_true_overlap_of_an_unknown_map_is_zero() -> None:
    grid = room_map()
    unknown = GridMap(cells=np.full((10, 10), UNKNOWN, dtype=np.int8), resolution=0.05)
    assert true_overlap(grid, unknown, np.zeros(3)) == 0.0


# --- CoverageEvaluator -----------------------------------------------------------------------


def test_the_ground_truth_covers_everything_in_any_frame() -> None:
    world = build_world("office")
    evaluator = CoverageEvaluator(world, world.starts)
    truth = ground_truth_map(world, 0.1, margin=1.0)
    assert len(evaluator.points) > 0
    assert evaluator.coverage([truth], [np.zeros(3)]) == 1.0
    frame = np.array([12.0, 7.0, 0.7])
    moved = in_frame(truth, frame, resolution=0.05)
    assert evaluator.coverage([moved], [frame]) == pytest.approx(1.0, abs=1e-3)
    # Put in the wrong place, the same map covers less.
    assert evaluator.coverage([moved], [compose(frame, [3.0, 0.0, 0.0])]) < 0.95


def test_coverage_is_the_union_of_the_maps() -> None:
    world = build_world("office")
    evaluator = CoverageEvaluator(world, world.starts)
    truth = ground_truth_map(world, 0.1, margin=1.0)
    half = truth.shape[1] // 2
    left, right = truth.cells.copy(), truth.cells.copy()
    left[:, half:] = UNKNOWN
    right[:, :half] = UNKNOWN
    maps = [GridMap(cells=c, resolution=0.1, origin=truth.origin) for c in (left, right)]
    frames = [np.zeros(3), np.zeros(3)]
    a = evaluator.coverage(maps[:1], frames[:1])
    b = evaluator.coverage(maps[1:], frames[1:])
    assert 0.0 < a < 1.0 and 0.0 < b < 1.0
    assert a + b == pytest.approx(1.0)
    assert evaluator.coverage(maps, frames) == 1.0
    assert evaluator.known(maps[0], frames[0]).sum() + evaluator.known(
        maps[1], frames[1]
    ).sum() == len(evaluator.points)


def test_coverage_counts_only_the_free_space_the_robots_can_reach() -> None:
    enclosure = [box(0, 0, 10, 0.1), box(0, 5.9, 10, 6), box(0, 0, 0.1, 6), box(9.9, 0, 10, 6)]
    sealed = [box(6, 0.1, 6.1, 3), box(6, 2.9, 9.9, 3)]  # a closed room in the corner
    world = WorldSpec.from_walls("sealed", enclosure + sealed, [(1.0, 1.0, 0.0)])
    evaluator = CoverageEvaluator(world, world.starts)
    inside = (evaluator.points[:, 0] > 6.1) & (evaluator.points[:, 1] < 2.9)
    assert not inside.any()
    assert np.all(world.clearance(evaluator.points) > 0)
    empty = GridMap(cells=np.full((5, 5), UNKNOWN, dtype=np.int8), resolution=0.1)
    assert evaluator.coverage([empty], [np.zeros(3)]) == 0.0


def test_coverage_counts_only_the_floor_behind_passages_the_planner_uses() -> None:
    # Two rooms joined by a 0.5 m gap: a robot of radius 0.2 fits, but the planner keeps
    # its safety margin clear and plans through it only as a last resort (the explorer's
    # bare-footprint fallback), so coverage leaves it out. The second room's floor counts
    # only for a strip past the gap; with a 1 m door, all of it.
    counted = {}
    for gap in (0.5, 1.0):
        low, high = 1.3 - gap / 2, 1.3 + gap / 2
        walls = [
            box(0, 0, 8, 0.1),
            box(0, 2.5, 8, 2.6),
            box(0, 0, 0.1, 2.6),
            box(7.9, 0, 8, 2.6),
            box(2.5, 0.1, 2.6, low),
            box(2.5, high, 2.6, 2.5),
        ]
        world = WorldSpec.from_walls("rooms", walls, [(1.0, 1.0, 0.0)])
        points = CoverageEvaluator(world, world.starts).points
        counted[gap] = int(np.count_nonzero(points[:, 0] > 2.6))
        assert np.count_nonzero(points[:, 0] < 2.5) == 24 * 24  # the first room, whole
    assert counted[1.0] == 53 * 24  # the second room, whole
    assert 0 < counted[0.5] < 0.1 * counted[1.0]


def test_the_coverage_margin_is_the_planners() -> None:
    from agents.planning import PlannerConfig

    assert PlannerConfig().safety_margin == PLANNER_MARGIN
