"""Sensor models as pure functions: odometry noise, peer sensor, lidar noise.

Every stochastic function takes ``rng`` (a ``numpy.random.Generator``) explicitly and
draws a fixed number of variates per call, whatever the scene, so that the random stream
(and with it a seeded run) does not depend on what the robots happen to see.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from mrslam_env.config import LidarConfig, OdometryConfig, PeerSensorConfig
from mrslam_env.geometry import wrap_scalar

FloatArray = NDArray[np.float64]

__all__ = [
    "add_lidar_noise",
    "apply_odometry_increments",
    "odometry_increments",
    "peer_measurements",
    "sample_odometry_increments",
]


MIN_TRAVEL = 0.01
"""Below this travel (m per step) a motion counts as a turn on the spot for the noise."""


def odometry_increments(before: FloatArray, after: FloatArray) -> FloatArray:
    """Decompose motions between poses (n, 3) into ``(rot1, trans, rot2)`` (n, 3).

    Probabilistic Robotics, table 5.6. Backward motion is represented with a negative
    translation (and rotations near zero) rather than a half-turn, so that reversing
    robots do not get heading noise proportional to pi.
    """
    before, after = np.atleast_2d(before), np.atleast_2d(after)
    out = np.empty((len(before), 3))
    for i, ((x0, y0, theta0), (x1, y1, theta1)) in enumerate(
        zip(before.tolist(), after.tolist(), strict=True)
    ):
        trans = math.hypot(x1 - x0, y1 - y0)
        rot1 = 0.0 if trans < 1e-9 else wrap_scalar(math.atan2(y1 - y0, x1 - x0) - theta0)
        if abs(rot1) > math.pi / 2.0:
            rot1, trans = wrap_scalar(rot1 - math.pi), -trans
        out[i] = (rot1, trans, wrap_scalar(theta1 - theta0 - rot1))
    return out


def sample_odometry_increments(
    increments: FloatArray, config: OdometryConfig, rng: np.random.Generator
) -> FloatArray:
    """Perturb increments ``(rot1, trans, rot2)`` (n, 3) with the four-alpha model
    (Probabilistic Robotics, table 5.6)."""
    rot1, trans, rot2 = increments[:, 0], increments[:, 1], increments[:, 2]
    a1, a2, a3, a4 = config.alpha1, config.alpha2, config.alpha3, config.alpha4
    # A turn on the spot has no direction of travel: a sub-millimetre shift (contact
    # jitter) gives an arbitrary rot1 of up to 90 degrees, and the model's noise would
    # then throw the robot tens of centimetres. Below MIN_TRAVEL the rotation counts as
    # one turn (rot1 -> 0) for the noise; the increments themselves stay exact.
    # Likewise a sideways shift (another robot pushing) is no turn-drive-turn of the
    # wheels: rot1 near +-90 degrees would get rotation noise of tens of degrees. Beyond
    # 45 degrees, rot1 folds into rot2 for the noise, wholly at 90 degrees.
    sideways = np.clip((np.pi / 2 - np.abs(rot1)) / (np.pi / 4), 0.0, 1.0)
    weight = np.minimum(np.abs(trans) / MIN_TRAVEL, 1.0) * sideways
    rot1, rot2 = weight * rot1, rot2 + (1.0 - weight) * rot1
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
    poses, increments = np.atleast_2d(poses), np.atleast_2d(increments)
    out = np.empty((len(poses), 3))
    for i, ((x, y, theta), (rot1, trans, rot2)) in enumerate(
        zip(poses.tolist(), increments.tolist(), strict=True)
    ):
        heading = theta + rot1
        out[i] = (
            x + trans * math.cos(heading),
            y + trans * math.sin(heading),
            wrap_scalar(heading + rot2),
        )
    return out


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
    n = len(poses)
    noise = rng.standard_normal((n, n, 3)) * (
        config.range_noise_std,
        config.bearing_noise_std,
        config.heading_noise_std,
    )
    out = np.zeros((n, n, 3))
    rows = poses.tolist()
    for i, (xi, yi, ti) in enumerate(rows):
        for j, (xj, yj, tj) in enumerate(rows):
            if i == j:
                continue
            e_range, e_bearing, e_heading = noise[i, j]
            distance = min(max(math.hypot(xj - xi, yj - yi) + e_range, 0.0), config.detect_range)
            bearing = wrap_scalar(math.atan2(yj - yi, xj - xi) - ti + e_bearing)
            out[i, j] = (distance, bearing, wrap_scalar(tj - ti + e_heading))
    return out
