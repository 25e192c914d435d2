"""Rendezvous geometry: predicted relative pose, sightings, meeting points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.rendezvous import (
    RendezvousConfig,
    choose_meeting_point,
    field_on_lattice,
    judge_sighting,
    predicted_relative_pose,
    sighting_pose,
)
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import GridMap


def test_prediction_is_t1_inverse_t_t2() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        world_from_map0, world_from_map1 = rng.uniform(-5, 5, (2, 3))
        pose0, pose1 = rng.uniform(-5, 5, (2, 3))  # SLAM poses, each in its own map
        map0_from_map1 = compose(inverse(world_from_map0), world_from_map1)
        world0 = compose(world_from_map0, pose0)
        world1 = compose(world_from_map1, pose1)
        expected = compose(inverse(world0), world1)
        got = predicted_relative_pose(pose0, pose1, map0_from_map1)
        np.testing.assert_allclose(got, expected, atol=1e-12)


def test_a_true_sighting_matches_and_a_wrong_hypothesis_does_not() -> None:
    config = RendezvousConfig()
    observer, other = np.array([1.0, 2.0, 0.3]), np.array([3.0, 2.5, -1.0])
    truth = compose(inverse(observer), other)
    bearing = math.atan2(truth[1], truth[0])
    seen = sighting_pose(math.hypot(truth[0], truth[1]) + 0.05, bearing + 0.02, truth[2] + 0.05)
    assert judge_sighting(seen, truth, config).matches
    # A hypothesis off by 1 m or by 90° predicts the robot elsewhere: rejected.
    off = compose(truth, [1.0, 0.0, 0.0])
    assert not judge_sighting(seen, off, config).matches
    turned = compose(truth, [0.0, 0.0, math.pi / 2])
    sighting = judge_sighting(seen, turned, config)
    assert not sighting.matches and sighting.heading_error == pytest.approx(math.pi / 2, abs=0.1)


def test_meeting_point_minimises_the_later_arrival() -> None:
    grid = GridMap(cells=np.zeros((1, 11), dtype=np.int8), resolution=1.0)
    x = np.arange(11) + 0.5
    cost0 = np.abs(x - 0.5)[None, :]  # robot 0 at the left end
    cost1 = 2.0 * np.abs(x - 10.5)[None, :]  # robot 1 at the right end, half as fast
    point, cost = choose_meeting_point(cost0, cost1, grid)
    # max(|x - 0.5|, 2 |x - 10.5|) is smallest where they cross: x = 7.17 -> cell 7.5.
    assert point[0] == pytest.approx(7.5) and cost == pytest.approx(7.0)
    blocked = np.full_like(cost1, np.inf)
    assert choose_meeting_point(cost0, blocked, grid) is None


def test_fields_move_between_lattices_through_the_transform() -> None:
    grid1 = GridMap(cells=np.zeros((20, 30), dtype=np.int8), resolution=0.1, origin=(-1.0, -1.0))
    field1 = np.arange(600, dtype=np.float64).reshape(20, 30)
    grid0 = GridMap(cells=np.zeros((25, 25), dtype=np.int8), resolution=0.1, origin=(0.0, 0.0))
    map0_from_map1 = np.array([1.2, 0.4, math.pi / 2])
    field0 = field_on_lattice(field1, grid1, grid0, map0_from_map1)
    cells0 = np.argwhere(np.isfinite(field0))
    assert 100 < len(cells0) < 25 * 25
    points1 = transform_points(inverse(map0_from_map1), grid0.cell_to_world(cells0))
    cells1 = grid1.world_to_cell(points1)
    np.testing.assert_array_equal(
        field0[cells0[:, 0], cells0[:, 1]], field1[cells1[:, 0], cells1[:, 1]]
    )


def test_bad_config_is_refused() -> None:
    with pytest.raises(ValueError, match="position_tolerance"):
        RendezvousConfig(position_tolerance=0.0)
    with pytest.raises(ValueError, match="wait_steps"):
        RendezvousConfig(wait_steps=0)
