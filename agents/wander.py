"""A reactive wandering policy: drive forward, steer away from obstacles, meander.

It reads only the robot's own lidar scan (never ground truth), so it is a fair baseline
and a simple driver for data collection. Deterministic given its ``rng``. It implements the
exploration-policy protocol (:class:`agents.policy.ExplorationPolicy`; it ignores the
context) and :func:`wander_policy` is its factory: ``mrslam run --policy
agents.wander:wander_policy``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.policy import PolicyContext
from agents.robot import DEFAULT_ENV, EnvFigures, build_for_env, check_against_env
from mrslam_env.config import EnvConfig
from mrslam_env.validation import check_fields, require

__all__ = ["WanderConfig", "WanderPolicy", "wander_policy"]


@dataclass(frozen=True, slots=True, kw_only=True)
class WanderConfig:
    """Tuning of :class:`WanderPolicy`; distances are from the robot centre."""

    robot_radius: float = DEFAULT_ENV.robot.radius
    """Footprint radius, m: the env's ``RobotConfig.radius`` (:meth:`for_env`)."""
    stop_distance: float = 0.55
    """Closer than this ahead: stop and turn in place, m."""
    slow_distance: float = 1.5
    """Closer than this ahead: slow down and steer away, m."""
    cruise_speed: float = 0.8
    """Normalised forward command in open space, in (0, 1]."""
    front_half_angle: float = math.radians(35.0)
    """Half-width of the sector that counts as 'ahead', rad."""
    meander: float = 0.25
    """Standard deviation of the random turn command per step (normalised)."""
    meander_persistence: float = 0.95
    """How much of the previous random turn carries over to the next step, in [0, 1)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=("robot_radius", "stop_distance", "slow_distance", "front_half_angle"),
            non_negative=("meander",),
        )
        name = type(self).__name__
        radius, stop, slow = self.robot_radius, self.stop_distance, self.slow_distance
        require(name, "robot_radius", radius, radius < stop, f"< stop_distance ({stop})")
        require(name, "slow_distance", slow, stop < slow, f"> stop_distance ({stop})")
        speed = self.cruise_speed
        require(name, "cruise_speed", speed, 0 < speed <= 1, "in (0, 1]")
        persistence = self.meander_persistence
        require(name, "meander_persistence", persistence, 0 <= persistence < 1, "in [0, 1)")

    @staticmethod
    def env_figures(env: EnvConfig) -> EnvFigures:
        """The fields that are the env's figures: the robot's radius."""
        return {"robot_radius": ("robot.radius", env.robot.radius)}

    @classmethod
    def for_env(cls, env: EnvConfig, **overrides: Any) -> WanderConfig:
        """The policy's tuning for the env's robot; ``overrides`` set the tuning fields."""
        return build_for_env(cls, cls.env_figures(env), overrides)

    def check_env(self, env: EnvConfig) -> None:
        """Raise a ``ValueError`` if this config contradicts the env's robot."""
        check_against_env(self, self.env_figures(env))


class WanderPolicy:
    """Maps a scan to a normalised ``(v, omega)`` action in [-1, 1].

    Parameters
    ----------
    n_beams : int
        Beams per scan; beam i points at ``-pi + i 2pi/N`` from the heading (the env's
        ``LidarConfig.n_beams``: :meth:`for_env` reads it there).
    rng : numpy.random.Generator
    config : WanderConfig
        Defaults to the default env's robot; :meth:`for_env` follows a given env's.
    """

    def __init__(
        self, n_beams: int, rng: np.random.Generator, config: WanderConfig | None = None
    ) -> None:
        self.config = config if config is not None else WanderConfig()
        self.rng = rng
        self.angles = -np.pi + np.arange(n_beams) * (2.0 * np.pi / n_beams)
        self._front = np.abs(self.angles) <= self.config.front_half_angle
        self._left = (self.angles > self.config.front_half_angle) & (self.angles < 2.0)
        self._right = (self.angles < -self.config.front_half_angle) & (self.angles > -2.0)
        self.reset()

    def reset(self) -> None:
        """Forget the meander and the escape direction (a new episode)."""
        self._random_turn = 0.0
        self._escape_direction = 0.0

    @classmethod
    def for_env(
        cls, env: EnvConfig, rng: np.random.Generator, config: WanderConfig | None = None
    ) -> WanderPolicy:
        """A policy for the env's robot and lidar (``env.lidar.n_beams``): ``config``
        (checked against the env) or :meth:`WanderConfig.for_env`."""
        if config is None:
            config = WanderConfig.for_env(env)
        config.check_env(env)
        return cls(env.lidar.n_beams, rng, config)

    def act(
        self,
        observation: dict[str, Any] | NDArray[np.floating],
        context: PolicyContext | None = None,
    ) -> NDArray[np.float32]:
        """One action for one observation (its ``scan``) or for one scan (N,) of ranges in
        metres; ``context`` is not needed (the protocol form)."""
        config = self.config
        scan = np.asarray(
            observation["scan"] if isinstance(observation, dict) else observation,
            dtype=np.float64,
        )
        # Scan points in the robot frame: x ahead, y to the left.
        x = scan * np.cos(self.angles)
        y = scan * np.sin(self.angles)
        # 'Ahead' is the lane the footprint sweeps, plus a cone around the heading.
        in_lane = (x > 0) & (np.abs(y) < config.robot_radius + 0.1)
        front = float(np.min(x[in_lane | self._front], initial=np.inf))
        left = float(np.mean(np.minimum(scan[self._left], 4.0)))
        right = float(np.mean(np.minimum(scan[self._right], 4.0)))
        # A persistent random turn (AR(1) process) so that the path meanders smoothly.
        persistence = config.meander_persistence
        innovation = config.meander * math.sqrt(1.0 - persistence**2)
        self._random_turn = persistence * self._random_turn + innovation * float(
            self.rng.standard_normal()
        )

        if front < config.stop_distance:
            # Turn in place, keeping one direction until the way is clear (no dithering).
            if self._escape_direction == 0.0:
                self._escape_direction = 1.0 if left >= right else -1.0
            return np.array([0.0, self._escape_direction], dtype=np.float32)
        self._escape_direction = 0.0
        away = float(np.clip((left - right) / max(left + right, 1e-6) * 2.0, -1.0, 1.0))
        if front < config.slow_distance:
            closeness = (config.slow_distance - front) / (
                config.slow_distance - config.stop_distance
            )
            speed = config.cruise_speed * (1.0 - 0.7 * closeness)
            turn = np.clip(away + math.copysign(closeness, away if away != 0 else 1.0), -1.0, 1.0)
            return np.array([speed, turn], dtype=np.float32)
        turn = np.clip(0.3 * away + self._random_turn, -1.0, 1.0)
        return np.array([config.cruise_speed, turn], dtype=np.float32)


def wander_policy(env: EnvConfig, rng: np.random.Generator) -> WanderPolicy:
    """The exploration-policy factory (:data:`agents.policy.PolicyFactory`) of the wander
    policy: ``mrslam run --policy agents.wander:wander_policy``."""
    return WanderPolicy.for_env(env, rng)
