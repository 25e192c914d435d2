"""Sensor models as pure functions: odometry noise, peer sensor, lidar noise.

Every stochastic function takes ``rng`` (a ``numpy.random.Generator``) explicitly and
draws a fixed number of variates per call, whatever the scene, so that the random stream
(and with it a seeded run) does not depend on what the robots happen to see.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from mrslam_env.config import LidarConfig, OdometryConfig, PeerSensorConfig
from mrslam_env.geometry import wrap_angle

FloatArray = NDArray[np.float64]

__all__ = [
    "add_lidar_noise",
    "apply_odometry_increments",
    "odometry_increments",
    "peer_measurements",
    "sample_odometry_increments",
]


def odometry_increments(before: FloatArray, after: FloatArray) -> FloatArray:
    """Decompose motions between poses (n, 3) into ``(rot1, trans, rot2)`` (n, 3).

    Probabilistic Robotics, table 5.6. Backward motion is represented with a negative
    translation (and rotations near zero) rather than a half-turn, so that reversing
    robots do not get heading noise proportional to pi.
    """
    before = np.atleast_2d(before)
    after = np.atleast_2d(after)
    delta = after[:, :2] - before[:, :2]
    trans = np.hypot(delta[:, 0], delta[:, 1])
    rot1 = np.where(
        trans < 1e-9, 0.0, wrap_angle(np.arctan2(delta[:, 1], delta[:, 0]) - before[:, 2])
    )
    backward = np.abs(rot1) > np.pi / 2.0
    rot1 = np.where(backward, wrap_angle(rot1 - np.pi), rot1)
    trans = np.where(backward, -trans, trans)
    rot2 = wrap_angle(after[:, 2] - before[:, 2] - rot1)
    return np.column_stack([rot1, trans, rot2])


def sample_odometry_increments(
    increments: FloatArray, config: OdometryConfig, rng: np.random.Generator
) -> FloatArray:
    """Perturb increments ``(rot1, trans, rot2)`` (n, 3) with the four-alpha model
    (Probabilistic Robotics, table 5.6)."""
    rot1, trans, rot2 = increments[:, 0], increments[:, 1], increments[:, 2]
    a1, a2, a3, a4 = config.alpha1, config.alpha2, config.alpha3, config.alpha4
    std = np.sqrt(
        np.column_stack(
            [
                a1 * rot1**2 + a2 * trans**2,
                a3 * trans**2 + a4 * (rot1**2 + rot2**2),
                a1 * rot2**2 + a2 * trans**2,
            ]
        )
    )
    return increments - rng.standard_normal(increments.shape) * std


def apply_odometry_increments(poses: FloatArray, increments: FloatArray) -> FloatArray:
    """Move poses (n, 3) by increments ``(rot1, trans, rot2)`` (n, 3)."""
    heading = poses[:, 2] + increments[:, 0]
    return np.column_stack(
        [
            poses[:, 0] + increments[:, 1] * np.cos(heading),
            poses[:, 1] + increments[:, 1] * np.sin(heading),
            wrap_angle(heading + increments[:, 2]),
        ]
    )


def add_lidar_noise(
    ranges: FloatArray, config: LidarConfig, rng: np.random.Generator
) -> FloatArray:
    """Gaussian range noise on returns and random dropouts (reported as max range).

    ``ranges`` has any shape, e.g. (n robots, N beams).
    """
    max_range = config.max_range
    noise = rng.standard_normal(ranges.shape) * config.range_noise_std
    dropped = rng.random(ranges.shape) < config.dropout_probability
    hit = ranges < max_range
    noisy = np.where(hit, np.clip(ranges + noise, 0.0, max_range), max_range)
    return np.where(dropped, max_range, noisy)


def peer_measurements(
    poses: FloatArray, config: PeerSensorConfig, rng: np.random.Generator
) -> FloatArray:
    """Noisy ``(range, bearing, relative heading)`` of every robot seen from every other.

    Parameters
    ----------
    poses : ndarray, shape (n, 3)
        Robot poses in one frame.

    Returns
    -------
    ndarray, shape (n, n, 3)
        Entry ``[i, j]`` is robot j seen from robot i: range (m, clipped to
        ``[0, detect_range]``), bearing from i's heading (rad, counter-clockwise) and
        ``theta_j - theta_i``; the diagonal is meaningless. Whether j is detectable at all
        (range, line of sight) is for the caller to decide.
    """
    delta = poses[None, :, :2] - poses[:, None, :2]
    noise = rng.standard_normal((len(poses), len(poses), 3)) * (
        config.range_noise_std,
        config.bearing_noise_std,
        config.heading_noise_std,
    )
    distance = np.clip(
        np.hypot(delta[..., 0], delta[..., 1]) + noise[..., 0], 0.0, config.detect_range
    )
    bearing = wrap_angle(
        np.arctan2(delta[..., 1], delta[..., 0]) - poses[:, None, 2] + noise[..., 1]
    )
    heading = wrap_angle(poses[None, :, 2] - poses[:, None, 2] + noise[..., 2])
    return np.stack([distance, bearing, heading], axis=-1)
