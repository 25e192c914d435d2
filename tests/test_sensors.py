"""Sensor models (mrslam_env.sim.sensors): odometry decomposition and four-alpha noise,
lidar noise and dropouts, the peer sensor's geometry and noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrslam_env.config import LidarConfig, OdometryConfig, PeerSensorConfig
from mrslam_env.geometry import compose
from mrslam_env.sim.sensors import (
    add_lidar_noise,
    apply_odometry_increments,
    odometry_increments,
    peer_measurements,
    sample_odometry_increments,
)

NO_ODOMETRY_NOISE = OdometryConfig(alpha1=0.0, alpha2=0.0, alpha3=0.0, alpha4=0.0)


def angle_difference(a, b) -> np.ndarray:
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


def assert_same_poses(a: np.ndarray, b: np.ndarray, tol: float = 1e-12) -> None:
    np.testing.assert_allclose(a[:, :2], b[:, :2], rtol=0, atol=tol)
    assert np.all(angle_difference(a[:, 2], b[:, 2]) <= tol)


# --- odometry decomposition --------------------------------------------------------------


def test_increments_known_values() -> None:
    before = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2], [0.0, 0.0, 0.0]])
    after = np.array(
        [
            [0.1, 0.0, 0.0],  # forward
            [-0.1, 0.0, 0.0],  # backward: negative translation, no half-turn
            [1.0, 1.0, math.pi / 2 + 0.3],  # pure rotation
            [0.0, 0.2, math.pi / 2],  # sideways then turned
        ]
    )
    increments = odometry_increments(before, after)
    np.testing.assert_allclose(
        increments,
        [[0.0, 0.1, 0.0], [0.0, -0.1, 0.0], [0.0, 0.0, 0.3], [math.pi / 2, 0.2, 0.0]],
        atol=1e-12,
    )


def test_backward_motion_has_small_rotations() -> None:
    rng = np.random.default_rng(0)
    before = np.column_stack([rng.uniform(-5, 5, (200, 2)), rng.uniform(-math.pi, math.pi, 200)])
    # Drive backwards 0.1 m while turning a little.
    turn = rng.uniform(-0.1, 0.1, 200)
    after = compose(
        before, np.column_stack([-0.1 * np.cos(turn / 2), -0.1 * np.sin(turn / 2), turn])
    )
    increments = odometry_increments(before, after)
    assert np.all(increments[:, 1] < 0)
    np.testing.assert_allclose(increments[:, 1], -0.1, atol=1e-12)
    assert np.all(np.abs(increments[:, 0]) <= np.pi / 2)
    np.testing.assert_allclose(increments[:, 0], turn / 2, atol=1e-9)
    np.testing.assert_allclose(increments[:, 2], turn / 2, atol=1e-9)


def test_turning_on_the_spot_with_contact_jitter_stays_a_turn() -> None:
    # A robot turning in place while touching another shifts by fractions of a millimetre;
    # its odometry must still read as a turn, with noise to match (not tenths of metres).
    rng = np.random.default_rng(1)
    before = np.zeros((500, 3))
    jitter = rng.normal(0.0, 3e-4, (500, 2))
    after = np.column_stack([jitter, np.full(500, 0.2)])
    increments = odometry_increments(before, after)
    assert np.abs(increments[:, 0]).max() > 1.0, "the jitter alone sets rot1"
    noisy = sample_odometry_increments(increments, OdometryConfig(), rng)
    moved = apply_odometry_increments(before, noisy)
    assert np.abs(moved[:, :2]).max() < 0.06  # the model: sqrt(alpha4) * turn, 4 sigma
    assert np.abs(moved[:, 2] - 0.2).max() < 0.25  # sqrt(alpha1) * turn, 5.5 sigma


def test_a_sideways_push_gets_no_turn_noise() -> None:
    # Another robot pushes this one 2 cm sideways without turning it (seen in a run: the
    # four-alpha model read rot1 = 90 degrees and threw the SLAM heading off by 45).
    rng = np.random.default_rng(2)
    before = np.zeros((2000, 3))
    after = np.tile([0.0, 0.02, 0.0], (2000, 1))
    increments = odometry_increments(before, after)
    assert np.allclose(np.abs(increments[:, 0]), np.pi / 2)
    noisy = sample_odometry_increments(increments, OdometryConfig(), rng)
    moved = apply_odometry_increments(before, noisy)
    # Heading noise as for 2 cm of travel: sqrt(alpha2) * 0.02 m = 0.0014 rad.
    assert np.abs(moved[:, 2]).max() < 0.01
    assert np.abs(moved[:, :2] - [0.0, 0.02]).max() < 0.02


@pytest.mark.parametrize("kind", ["forward", "backward", "rotation", "any"])
def test_increments_and_apply_are_exact_inverses(kind: str) -> None:
    rng = np.random.default_rng(1)
    n = 1000
    before = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    if kind == "forward":
        motion = np.column_stack(
            [rng.uniform(0.0, 0.2, n), rng.normal(0, 0.01, n), rng.normal(0, 0.2, n)]
        )
    elif kind == "backward":
        motion = np.column_stack(
            [rng.uniform(-0.2, 0.0, n), rng.normal(0, 0.01, n), rng.normal(0, 0.2, n)]
        )
    elif kind == "rotation":
        motion = np.column_stack([np.zeros(n), np.zeros(n), rng.uniform(-math.pi, math.pi, n)])
    else:
        motion = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    after = compose(before, motion)
    increments = odometry_increments(before, after)
    assert increments.shape == (n, 3)
    assert_same_poses(apply_odometry_increments(before, increments), after, tol=1e-12)
    # ... and the other way round: decomposing an applied increment gives it back.
    assert np.all(np.abs(increments[:, 0]) <= np.pi / 2 + 1e-12)
    again = odometry_increments(before, apply_odometry_increments(before, increments))
    np.testing.assert_allclose(again, increments, atol=1e-9)


def test_increments_are_frame_invariant() -> None:
    """Odometry in the odom frame (start = origin) equals odometry in the world frame."""
    rng = np.random.default_rng(2)
    n = 300
    before = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    after = compose(
        before, np.column_stack([rng.uniform(-0.3, 0.3, (n, 2)), rng.normal(0, 0.5, n)])
    )
    frame = np.array([3.0, -2.0, 2.5])
    np.testing.assert_allclose(
        odometry_increments(compose(frame, before), compose(frame, after)),
        odometry_increments(before, after),
        atol=1e-9,
    )


def test_increments_accept_single_poses() -> None:
    increments = odometry_increments(np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.5]))
    assert increments.shape == (1, 3)
    np.testing.assert_allclose(increments[0], [0.0, 1.0, 0.5], atol=1e-12)


def square_path(steps_per_side: int = 100, turn_steps: int = 25, step: float = 0.04) -> np.ndarray:
    """True poses (steps + 1, 3) along a square: drive a side, turn left 90 degrees, x4."""
    poses = [np.zeros(3)]
    for _ in range(4):
        for _ in range(steps_per_side):
            poses.append(compose(poses[-1], [step, 0.0, 0.0]))
        for _ in range(turn_steps):
            poses.append(compose(poses[-1], [0.0, 0.0, (math.pi / 2) / turn_steps]))
    return np.array(poses)


def dead_reckon(truth: np.ndarray, config: OdometryConfig, rng: np.random.Generator) -> np.ndarray:
    odometry = truth[:1].copy()
    for k in range(1, len(truth)):
        increments = odometry_increments(truth[k - 1 : k], truth[k : k + 1])
        noisy = sample_odometry_increments(increments, config, rng)
        odometry = apply_odometry_increments(odometry, noisy)
    return odometry[0]


def test_dead_reckoning_without_noise_is_exact() -> None:
    truth = square_path()
    assert len(truth) == 501
    odometry = dead_reckon(truth, NO_ODOMETRY_NOISE, np.random.default_rng(3))
    np.testing.assert_allclose(odometry[:2], truth[-1, :2], atol=1e-9)
    assert angle_difference(odometry[2], truth[-1, 2]) <= 1e-9
    # The square closes.
    np.testing.assert_allclose(truth[-1], [0.0, 0.0, 0.0], atol=1e-9)


def test_dead_reckoning_with_noise_drifts() -> None:
    truth = square_path()
    errors = []
    for seed in range(5):
        odometry = dead_reckon(truth, OdometryConfig(), np.random.default_rng(seed))
        errors.append(float(np.hypot(*(odometry[:2] - truth[-1, :2]))))
    assert min(errors) > 0.01
    assert np.mean(errors) > 0.05
    assert len(set(errors)) == 5  # each seed its own drift


@pytest.mark.parametrize(
    "increment",
    [
        (0.3, 0.5, -0.2),  # general
        (0.0, 0.0, 0.4),  # pure rotation
        (0.0, 0.1, 0.0),  # pure translation
        (-0.2, -0.3, 0.1),  # backward
    ],
)
def test_sampled_increment_noise_matches_the_four_alpha_model(increment) -> None:
    # Distinct alphas so that a swapped term would show.
    config = OdometryConfig(alpha1=0.1, alpha2=0.01, alpha3=0.05, alpha4=0.002)
    n = 20_000
    increments = np.tile(np.array(increment, dtype=np.float64), (n, 1))
    samples = sample_odometry_increments(increments, config, np.random.default_rng(4))
    rot1, trans, rot2 = increment
    a1, a2, a3, a4 = config.alpha1, config.alpha2, config.alpha3, config.alpha4
    expected_std = np.sqrt(
        [
            a1 * rot1**2 + a2 * trans**2,
            a3 * trans**2 + a4 * rot1**2 + a4 * rot2**2,
            a1 * rot2**2 + a2 * trans**2,
        ]
    )
    error = samples - increments
    std = error.std(axis=0)
    for k in range(3):
        if expected_std[k] == 0.0:
            assert np.all(error[:, k] == 0.0)
        else:
            assert std[k] == pytest.approx(expected_std[k], rel=0.10)
            # Unbiased: mean within 4 standard errors of zero.
            assert abs(error[:, k].mean()) < 4 * expected_std[k] / math.sqrt(n)
    np.testing.assert_array_equal(increments, np.tile(increment, (n, 1)))  # input kept


def test_sample_without_noise_returns_the_increments() -> None:
    increments = np.random.default_rng(5).normal(size=(50, 3))
    out = sample_odometry_increments(increments, NO_ODOMETRY_NOISE, np.random.default_rng(6))
    np.testing.assert_array_equal(out, increments)


# --- lidar noise -------------------------------------------------------------------------


def test_lidar_dropouts_happen_at_the_configured_rate() -> None:
    config = LidarConfig(max_range=8.0, range_noise_std=0.01, dropout_probability=0.05)
    ranges = np.random.default_rng(7).uniform(0.5, 7.5, (200, 500))
    noisy = add_lidar_noise(ranges, config, np.random.default_rng(8))
    assert noisy.shape == ranges.shape
    dropped = noisy == config.max_range
    assert dropped.mean() == pytest.approx(0.05, rel=0.2)


def test_lidar_noise_std_matches() -> None:
    config = LidarConfig(max_range=8.0, range_noise_std=0.03, dropout_probability=0.0)
    ranges = np.random.default_rng(9).uniform(1.0, 7.0, 100_000)
    noisy = add_lidar_noise(ranges, config, np.random.default_rng(10))
    error = noisy - ranges
    assert error.std() == pytest.approx(0.03, rel=0.05)
    assert abs(error.mean()) < 4 * 0.03 / math.sqrt(len(ranges))


def test_lidar_noise_stays_in_range_and_keeps_no_returns() -> None:
    config = LidarConfig(max_range=4.0, range_noise_std=0.5, dropout_probability=0.1)
    rng = np.random.default_rng(11)
    ranges = rng.uniform(0.0, 4.0, (50, 360))
    ranges[:, ::3] = 4.0  # no return
    noisy = add_lidar_noise(ranges, config, rng)
    assert np.all(noisy >= 0.0)
    assert np.all(noisy <= 4.0)
    np.testing.assert_array_equal(noisy[:, ::3], 4.0)
    # Large noise near the limits gets clipped rather than leaving [0, max_range].
    assert (noisy == 0.0).any()


def test_zero_noise_config_returns_input_unchanged() -> None:
    config = LidarConfig(max_range=8.0, range_noise_std=0.0, dropout_probability=0.0)
    ranges = np.random.default_rng(12).uniform(0.1, 8.0, (3, 90))
    ranges[0, :10] = 8.0
    copy = ranges.copy()
    noisy = add_lidar_noise(ranges, config, np.random.default_rng(13))
    np.testing.assert_array_equal(noisy, ranges)
    np.testing.assert_array_equal(ranges, copy)  # input not mutated


def test_random_stream_does_not_depend_on_the_scene() -> None:
    config = LidarConfig()
    rng_a, rng_b = np.random.default_rng(14), np.random.default_rng(14)
    add_lidar_noise(np.full((2, 360), config.max_range), config, rng_a)
    add_lidar_noise(np.full((2, 360), 1.0), config, rng_b)
    assert rng_a.random() == rng_b.random()
    rng_a, rng_b = np.random.default_rng(15), np.random.default_rng(15)
    peer_measurements(np.zeros((3, 3)), PeerSensorConfig(), rng_a)
    peer_measurements(np.ones((3, 3)) * 50, PeerSensorConfig(), rng_b)
    assert rng_a.random() == rng_b.random()


# --- peer sensor -------------------------------------------------------------------------

NO_PEER_NOISE = PeerSensorConfig(
    detect_range=20.0, range_noise_std=0.0, bearing_noise_std=0.0, heading_noise_std=0.0
)


def test_peer_measurement_geometry_without_noise() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, math.pi / 2], [-1.0, 0.0, -3.0]])
    m = peer_measurements(poses, NO_PEER_NOISE, np.random.default_rng(16))
    assert m.shape == (3, 3, 3)
    # Robot 1 seen from robot 0.
    np.testing.assert_allclose(m[0, 1], [5.0, math.atan2(4, 3), math.pi / 2], atol=1e-12)
    # Robot 0 seen from robot 1: direction (-3, -4) in the world, heading +y.
    bearing = math.atan2(-4.0, -3.0) - math.pi / 2
    np.testing.assert_allclose(m[1, 0], [5.0, bearing + 2 * math.pi, -math.pi / 2], atol=1e-12)
    # Robot 2 from robot 0: straight behind, relative heading -3.
    np.testing.assert_allclose(m[0, 2], [1.0, math.pi, -3.0], atol=1e-12)
    # Robot 0 from robot 2 (heading -3): the bearing wraps.
    expected = math.remainder(0.0 - (-3.0), 2 * math.pi)
    assert m[2, 0, 1] == pytest.approx(expected, abs=1e-12)
    assert m[2, 0, 2] == pytest.approx(3.0, abs=1e-12)


def test_peer_measurement_reconstructs_the_relative_pose() -> None:
    rng = np.random.default_rng(17)
    poses = np.column_stack([rng.uniform(-5, 5, (6, 2)), rng.uniform(-math.pi, math.pi, 6)])
    m = peer_measurements(poses, NO_PEER_NOISE, rng)
    for i in range(6):
        for j in range(6):
            if i == j:
                continue
            distance, bearing, heading = m[i, j]
            assert -math.pi < bearing <= math.pi
            assert -math.pi < heading <= math.pi
            relative = np.array(
                [distance * math.cos(bearing), distance * math.sin(bearing), heading]
            )
            np.testing.assert_allclose(compose(poses[i], relative)[:2], poses[j, :2], atol=1e-9)
            assert angle_difference(compose(poses[i], relative)[2], poses[j, 2]) < 1e-9


def test_peer_range_is_clipped_to_detect_range() -> None:
    config = PeerSensorConfig(
        detect_range=5.0, range_noise_std=0.0, bearing_noise_std=0.0, heading_noise_std=0.0
    )
    poses = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    m = peer_measurements(poses, config, np.random.default_rng(18))
    assert m[0, 1, 0] == 5.0


def test_peer_noise_std_matches() -> None:
    config = PeerSensorConfig(
        detect_range=50.0, range_noise_std=0.05, bearing_noise_std=0.02, heading_noise_std=0.04
    )
    poses = np.array([[0.0, 0.0, 0.3], [3.0, 1.0, -0.5]])
    exact = peer_measurements(poses, NO_PEER_NOISE, np.random.default_rng(19))[0, 1]
    rng = np.random.default_rng(20)
    samples = np.array([peer_measurements(poses, config, rng)[0, 1] for _ in range(5000)])
    error = samples - exact
    np.testing.assert_allclose(error.std(axis=0), [0.05, 0.02, 0.04], rtol=0.1)
    assert np.all(np.abs(error.mean(axis=0)) < 4 * np.array([0.05, 0.02, 0.04]) / math.sqrt(5000))
