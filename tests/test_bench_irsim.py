"""The IR-SIM reference of ``mrslam bench sim`` simulates the same world as ours."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from mrslam_env.sim.world import WorldSpec, box
from scenarios.bench.irsim import build_irsim_env, irsim_available, irsim_steps_per_second

pytestmark = pytest.mark.skipif(not irsim_available(), reason="ir-sim is not installed")

MAX_RANGE = 8.0
N_BEAMS = 72
INNER = (0.1, 9.9)  # free square inside the room's 0.1 m thick walls


def _room() -> WorldSpec:
    walls = [box(0, 0, 10, 0.1), box(0, 9.9, 10, 10), box(0, 0, 0.1, 10), box(9.9, 0, 10, 10)]
    return WorldSpec.from_walls("room", walls, [[2.0, 2.0, 0.0], [7.0, 7.0, math.pi / 2]])


def _expected_ranges(pose: np.ndarray) -> np.ndarray:
    """Exact ranges from ``pose`` to the room's inner walls, beam i at -pi + i 2 pi / n."""
    x, y, theta = pose
    angles = theta - math.pi + np.arange(N_BEAMS) * 2.0 * math.pi / N_BEAMS
    dx, dy = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (INNER[1] - x) / dx, np.where(dx < 0, (INNER[0] - x) / dx, np.inf))
        ty = np.where(dy > 0, (INNER[1] - y) / dy, np.where(dy < 0, (INNER[0] - y) / dy, np.inf))
    return np.minimum(np.minimum(tx, ty), MAX_RANGE)


def _check_scans(env: Any) -> None:
    for i, robot in enumerate(env.robot_list):
        pose = np.asarray(robot.state, dtype=float).ravel()[:3]
        ranges = np.asarray(env.get_lidar_scan(i)["ranges"])
        expected = _expected_ranges(pose)
        assert ranges.shape == (N_BEAMS,)
        # The beam pointing at the nearest wall sees it, at the right distance.
        nearest = int(np.argmin(expected))
        assert ranges[nearest] < MAX_RANGE
        assert ranges[nearest] == pytest.approx(expected[nearest], abs=1e-6)
        # Every beam matches the walls, except the few the other robot's disc blocks.
        assert np.all(ranges <= expected + 1e-6)
        assert np.mean(np.abs(ranges - expected) < 1e-6) > 0.9


def test_irsim_env_sees_the_same_walls_every_step() -> None:
    env = build_irsim_env(_room(), n_beams=N_BEAMS, max_range=MAX_RANGE, range_noise_std=0.0)
    try:
        assert len(env.robot_list) == 2
        assert env.step_time == pytest.approx(0.1)
        _check_scans(env)  # at the start poses: beam 0 of robot 0 looks down -x, 1.9 m
        assert env.get_lidar_scan(0)["ranges"][0] == pytest.approx(1.9, abs=1e-6)

        # Count the lidar casts: one per robot per env.step.
        casts = [0] * len(env.robot_list)
        for i, robot in enumerate(env.robot_list):
            lidar = robot.sensors[0]
            cast = lidar.step

            def counted(state: Any, i: int = i, cast: Any = cast) -> None:
                casts[i] += 1
                cast(state)

            lidar.step = counted
        start = np.array([np.asarray(r.state).ravel()[:3] for r in env.robot_list])
        for _ in range(5):
            env.step([[0.5, 1.0], [0.5, -1.0]], action_id=[0, 1])
            _check_scans(env)
        assert casts == [5, 5]
        moved = np.array([np.asarray(r.state).ravel()[:3] for r in env.robot_list]) - start
        assert np.all(np.hypot(moved[:, 0], moved[:, 1]) > 0.05)
    finally:
        env.end(0)


def test_irsim_steps_per_second_is_positive() -> None:
    rate = irsim_steps_per_second(_room(), n_steps=20, repeats=1)
    assert math.isfinite(rate)
    assert rate > 0
