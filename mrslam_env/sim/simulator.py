"""The simulator: robots in a world, with lidar, odometry, peer sensor and comm link.

:class:`Simulator` owns the physics and the sensors' state and draws every random number
from the generator it is given, in a fixed order, so a seed and a sequence of commands
give identical runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mrslam_env.config import EnvConfig
from mrslam_env.sim.lidar import beam_angles, cast_scan, line_of_sight
from mrslam_env.sim.physics import Physics
from mrslam_env.sim.sensors import (
    add_lidar_noise,
    apply_odometry_increments,
    odometry_increments,
    peer_measurements,
    sample_odometry_increments,
)
from mrslam_env.sim.starts import world_start_points
from mrslam_env.sim.world import WorldSpec

FloatArray = NDArray[np.float64]

__all__ = ["SimState", "Simulator", "choose_starts"]

START_CLEARANCE_MARGIN = 0.05  # m beyond the robot radius that a start pose must keep free


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class SimState:
    """What the simulator reports after a reset or a step (n robots, N beams).

    Attributes
    ----------
    true_poses : (n, 3) float64
        Ground-truth poses in the world frame (privileged).
    scans : (n, N) float64
        Lidar ranges, m.
    odometry : (n, 3) float64
        Dead-reckoning poses, each in its robot's odom frame (the start pose is the origin).
    peers : (n, n-1, 4) float64
        For robot i and each other robot j (in index order, skipping i):
        ``(detected, range, bearing, relative heading)``, zeros when not detected.
    comm : (n, n-1) bool
        Whether the link from robot i to each other robot is up.
    collisions : (n,) bool
        Contact with a wall or another robot during the last step.
    """

    true_poses: FloatArray
    scans: FloatArray
    odometry: FloatArray
    peers: FloatArray
    comm: NDArray[np.bool_]
    collisions: NDArray[np.bool_]


def choose_starts(
    world: WorldSpec,
    n_robots: int,
    radius: float,
    rng: np.random.Generator,
    given: FloatArray | None = None,
) -> FloatArray:
    """Start poses (n, 3): the given ones (validated), then automatic ones.

    Automatic starts are drawn in random order from the cells where the robot can start
    reachable from the first start (the start clearance rule,
    :func:`mrslam_env.sim.starts.world_start_points`), each at least 2 m from the other
    robots, with a uniformly random heading.

    Raises
    ------
    ValueError
        If a given start lies inside a wall or closer than the robot radius to one, or two
        given starts overlap, or there is no room for the automatic ones.
    """
    given = world.starts if given is None else np.asarray(given, dtype=np.float64).reshape(-1, 3)
    starts = [np.asarray(s, dtype=np.float64) for s in given[:n_robots]]
    clearance = world.clearance(np.array([s[:2] for s in starts]))
    for i, (start, c) in enumerate(zip(starts, clearance, strict=True)):
        if c < radius + START_CLEARANCE_MARGIN:
            where = "inside a wall" if c < 0 else f"{c:.2f} m from a wall"
            raise ValueError(
                f"start pose {i} ({start[0]:.2f}, {start[1]:.2f}, {start[2]:.2f}) is {where}; "
                f"a robot of radius {radius} m needs {radius + START_CLEARANCE_MARGIN:.2f} m"
            )
        for j in range(i):
            if math.hypot(*(start[:2] - starts[j][:2])) < 2.0 * radius + START_CLEARANCE_MARGIN:
                raise ValueError(
                    f"start pose {i} ({start[0]:.2f}, {start[1]:.2f}) overlaps start pose {j} "
                    f"({starts[j][0]:.2f}, {starts[j][1]:.2f})"
                )
    if len(starts) < n_robots:
        candidates = world_start_points(world, radius, starts[0][:2])
        order = rng.permutation(len(candidates))
        for index in order:
            if len(starts) == n_robots:
                break
            xy = candidates[index]
            if all(math.hypot(*(xy - s[:2])) >= 2.0 for s in starts):
                starts.append(np.array([xy[0], xy[1], rng.uniform(-math.pi, math.pi)]))
        if len(starts) < n_robots:
            raise ValueError(f"world {world.name!r} has no room for {n_robots} robots")
    return np.stack(starts)


class Simulator:
    """Robots with sensors in a world.

    Parameters
    ----------
    world : WorldSpec
    n_robots : int
    config : EnvConfig
    rng : numpy.random.Generator
        The only source of randomness (sensor noise, packet loss, automatic starts).
    """

    def __init__(
        self, world: WorldSpec, n_robots: int, config: EnvConfig, rng: np.random.Generator
    ) -> None:
        if n_robots < 1:
            raise ValueError(f"n_robots must be >= 1, got {n_robots}")
        self.world = world
        self.config = config
        self.rng = rng
        self.starts = choose_starts(
            world,
            n_robots,
            config.robot.radius,
            rng,
            None if config.starts is None else np.asarray(config.starts),
        )
        self.physics = Physics(world, self.starts, config.robot)
        self.n_robots = n_robots
        self.odometry = np.zeros((n_robots, 3))
        self.time = 0.0
        self._last_true = self.physics.poses()
        self.state = self._sense(np.zeros(n_robots, dtype=bool))

    @property
    def beam_angles(self) -> FloatArray:
        """Lidar beam angles (N,) relative to the heading, rad."""
        return beam_angles(self.config.lidar.n_beams)

    def step(self, commands: FloatArray) -> SimState:
        """Advance one env period with normalised commands (n, 2) in [-1, 1].

        Commands are clipped to [-1, 1] and scaled to ``(max_speed, max_turn_rate)``.
        """
        robot = self.config.robot
        targets = np.clip(commands, -1.0, 1.0) * (robot.max_speed, robot.max_turn_rate)
        collisions = self.physics.step(targets, self.config.dt, self.config.physics_substeps)
        self.time += self.config.dt
        true = self.physics.poses()
        increments = odometry_increments(self._last_true, true)
        noisy = sample_odometry_increments(increments, self.config.odometry, self.rng)
        self.odometry = apply_odometry_increments(self.odometry, noisy)
        self._last_true = true
        self.state = self._sense(collisions)
        return self.state

    def _sense(self, collisions: NDArray[np.bool_]) -> SimState:
        config = self.config
        n = self.n_robots
        true = self.physics.poses()
        discs = np.column_stack([true[:, :2], np.full(n, config.robot.radius)])
        segments = self.world.segments
        exact = np.stack(
            [
                cast_scan(
                    pose[0],
                    pose[1],
                    pose[2],
                    config.lidar.n_beams,
                    config.lidar.max_range,
                    segments,
                    discs,
                )
                for pose in true
            ]
        )
        scans = add_lidar_noise(exact, config.lidar, self.rng)
        measurements = peer_measurements(true, config.peer, self.rng)
        link_draws = self.rng.random((n, n))
        peers = np.zeros((n, max(n - 1, 0), 4))
        comm = np.zeros((n, max(n - 1, 0)), dtype=bool)
        for i in range(n):
            for j in range(i + 1, n):
                distance = math.hypot(true[j, 0] - true[i, 0], true[j, 1] - true[i, 1])
                visible = line_of_sight(true[i, 0], true[i, 1], true[j, 0], true[j, 1], segments)
                up = (
                    distance <= config.comm.comm_range
                    and (visible or not config.comm.blocked_by_walls)
                    and link_draws[i, j] >= config.comm.packet_loss
                )
                detected = distance <= config.peer.detect_range and visible
                # slot of j in i's list of others, and of i in j's
                for a, b, slot in ((i, j, j - 1), (j, i, i)):
                    comm[a, slot] = up
                    if detected:
                        peers[a, slot] = (1.0, *measurements[a, b])
        return SimState(
            true_poses=true,
            scans=scans,
            odometry=self.odometry.copy(),
            peers=peers,
            comm=comm,
            collisions=np.asarray(collisions, dtype=bool),
        )
