"""Adapters for reinforcement learning: a flat, normalised observation and a single-robot
Gymnasium env with scripted teammates.

Flat observation (:class:`ObservationFlattener`; ``EnvConfig(flat_observation=True)``
makes the env emit it, and ``env.state()`` concatenates it over all robots). One float32
vector per robot, every entry in [-1, 1] or [0, 1], the pieces in this order
(:meth:`ObservationFlattener.layout` gives the slices):

============  ===============  ============================================================
piece         length           value
============  ===============  ============================================================
scan          N                ``range / max_range`` in [0, 1] (1 = no return)
odom          3                ``x / L, y / L`` clipped to [-1, 1], ``theta / pi``
peer          4 (n - 1)        per other robot (row-major, self skipped): ``detected``
                               (0/1), ``range / detect_range``, ``bearing / pi``,
                               ``relative heading / pi``
comm          n - 1            1 when the link is up
pose          3                (SLAM on only) as ``odom``
local_map     2 S S            (SLAM on only) the crop as 0/1 floats, channel 0 free then
                               channel 1 occupied, row-major
============  ===============  ============================================================

``L = EnvConfig.flat_length_scale`` (m, default 50). Privileged data (true poses) is
never part of it.

Single robot (:class:`agents.single_robot.SingleRobotEnv`, registered with Gymnasium as
``"mrslam/SingleRobot-v0"`` on import of this module or of :mod:`mrslam_env.env`;
``gymnasium.make("mrslam_env.wrappers:mrslam/SingleRobot-v0", ...)`` imports it too):
``robot_0`` learns, on the flat observation; its teammates run a scripted policy,
``"frontier"`` (:class:`agents.explorer.ExplorerPolicy` on its own SLAM map; with onboard
SLAM off the teammate runs a SLAM of its own on its odometry and scan), ``"wander"``
(:class:`agents.wander.WanderPolicy`, scan only) or ``"idle"`` (stand still). Its
``reset(options=...)`` passes them to the parallel env, which takes the keys of
``mrslam_env.env.RESET_OPTIONS`` and refuses any other by name. The
library never imports :mod:`agents` (docs/design.md §1): the registration names the class
by a string, which Gymnasium imports when the env is made.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from mrslam_env.config import EnvConfig

__all__ = ["SINGLE_ROBOT_ID", "TEAMMATES", "ObservationFlattener"]

SINGLE_ROBOT_ID = "mrslam/SingleRobot-v0"

TEAMMATES = ("frontier", "wander", "idle")
"""The scripted teammate policies :class:`agents.single_robot.SingleRobotEnv` knows by name."""

Float32Array = NDArray[np.float32]


class ObservationFlattener:
    """Turns one robot's ``Dict`` observation into the flat vector of the module notes.

    Parameters
    ----------
    config : EnvConfig
        The env's configuration (lidar range, peer range, SLAM on or off, crop size,
        ``flat_length_scale``).
    n_robots : int
    """

    def __init__(self, config: EnvConfig, n_robots: int) -> None:
        self.max_range = config.lidar.max_range
        self.detect_range = config.peer.detect_range
        self.length_scale = config.flat_length_scale
        others = n_robots - 1
        sizes = [
            ("scan", config.lidar.n_beams),
            ("odom", 3),
            ("peer", 4 * others),
            ("comm", others),
        ]
        if config.slam is not None:
            sizes += [("pose", 3), ("local_map", 2 * config.local_map.cells**2)]
        self._layout: dict[str, slice] = {}
        start = 0
        for name, size in sizes:
            self._layout[name] = slice(start, start + size)
            start += size
        self.size = start
        low = np.zeros(self.size, dtype=np.float32)
        for name in ("odom", "pose"):
            if name in self._layout:
                low[self._layout[name]] = -1.0
        peer_low = np.tile(np.array([0.0, 0.0, -1.0, -1.0], dtype=np.float32), others)
        low[self._layout["peer"]] = peer_low
        self.space = spaces.Box(low, np.ones(self.size, dtype=np.float32), dtype=np.float32)

    def layout(self) -> dict[str, slice]:
        """Where each piece lies in the flat vector."""
        return dict(self._layout)

    def _pose(self, pose: NDArray[Any]) -> Float32Array:
        xy = np.clip(np.asarray(pose[:2], dtype=np.float64) / self.length_scale, -1.0, 1.0)
        theta = np.clip(float(pose[2]) / np.pi, -1.0, 1.0)
        return np.array([xy[0], xy[1], theta], dtype=np.float32)

    def __call__(self, observation: dict[str, NDArray[Any]]) -> Float32Array:
        out = np.empty(self.size, dtype=np.float32)
        layout = self._layout
        scan = np.asarray(observation["scan"], dtype=np.float64) / self.max_range
        out[layout["scan"]] = np.clip(scan, 0.0, 1.0)
        out[layout["odom"]] = self._pose(observation["odom"])
        peer = np.asarray(observation["peer"], dtype=np.float64).reshape(-1, 4)
        scaled = peer / np.array([1.0, self.detect_range, np.pi, np.pi])
        scaled = np.clip(scaled, [0.0, 0.0, -1.0, -1.0], 1.0)
        out[layout["peer"]] = scaled.ravel()
        out[layout["comm"]] = np.asarray(observation["comm"]) != 0
        if "pose" in layout:
            out[layout["pose"]] = self._pose(observation["pose"])
            out[layout["local_map"]] = np.asarray(observation["local_map"]).ravel() != 0
        return out


# --- scripted teammates --------------------------------------------------------------------

if SINGLE_ROBOT_ID not in gymnasium.registry:
    # A plugin reference, resolved by gymnasium.make: the single-robot env composes the env
    # with scripted agents, so it lives with them (the library never imports agents).
    gymnasium.register(id=SINGLE_ROBOT_ID, entry_point="agents.single_robot:SingleRobotEnv")
