"""A pure-pursuit path follower for the env's normalised ``(v, omega)`` actions.

One step per function:

* :func:`lookahead_target`: the point a lookahead distance further along the path than the
  robot's projection onto it (Coulter, "Implementation of the pure pursuit path tracking
  algorithm", CMU-RI-TR-92-01, 1992); progress along the path never goes backwards.
* :func:`pursuit_command`: the arc through that point (curvature ``2 sin(alpha) / L``),
  with the speed lowered for sharp turns and near the goal, and turning in place when the
  heading error is large.
* :func:`limit_rates`: acceleration limits, so the commands change smoothly.
* :func:`lane_clearance`: free distance ahead of and behind the footprint from a scan, a
  last-resort guard against driving into what the map does not show yet.
* :func:`guard_speed`: the braking guard on that distance, the one rule that keeps the
  robot off walls it has not mapped and off a teammate: never drive towards a return
  faster than the robot can stop from within *half* the free lane (less a margin), with
  its deceleration and one control period of reaction. Half, because the return may be a
  teammate driving the other way under the same rule: then each stops within its half.
  :func:`teammate_clearance` applies it to teammates the peer sensor sees, at any bearing:
  the speed at which driving closes the gap to one is capped alike.

:class:`PathFollower` is the stateful shell: it follows a path, reports when the goal is
reached, detects when it makes no progress and then backs up and turns (recovery).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.robot import DEFAULT_ENV, EnvFigures, build_for_env, check_against_env
from mrslam_env.config import EnvConfig
from mrslam_env.geometry import wrap_scalar
from mrslam_env.validation import check_fields, require

__all__ = [
    "FollowerConfig",
    "FollowerStatus",
    "PathFollower",
    "escape_command",
    "guard_speed",
    "lane_clearance",
    "limit_rates",
    "lookahead_target",
    "pursuit_command",
    "teammate_clearance",
]

FloatArray = NDArray[np.float64]
FollowerStatus = Literal["idle", "following", "reached", "recovering"]


@dataclass(frozen=True, slots=True, kw_only=True)
class FollowerConfig:
    """Tuning of :class:`PathFollower`. Speeds in SI units; the action scale and the
    control period are the env's (``max_speed``, ``max_turn_rate``, ``dt``: set by
    :meth:`for_env`, checked by :meth:`check_env`)."""

    max_speed: float = DEFAULT_ENV.robot.max_speed
    """Linear speed at action 1, m/s: the env's ``RobotConfig.max_speed``."""
    max_turn_rate: float = DEFAULT_ENV.robot.max_turn_rate
    """Angular speed at action 1, rad/s: the env's ``RobotConfig.max_turn_rate``."""
    dt: float = DEFAULT_ENV.dt
    """Control period, s: the env's ``EnvConfig.dt``."""
    max_acceleration: float = DEFAULT_ENV.robot.max_acceleration
    """The robot's largest change of speed, m/s^2: the env's ``RobotConfig.max_acceleration``
    (the deceleration the braking guard counts on)."""
    cruise_speed: float = 0.8
    """Speed on straight stretches, m/s (<= max_speed)."""
    min_speed: float = 0.08
    """Lowest forward speed while driving to the goal, m/s, so that it is reached."""
    lookahead: float = 0.5
    """Pure-pursuit lookahead distance, m."""
    goal_tolerance: float = 0.15
    """The goal is reached within this distance, m."""
    goal_deceleration: float = 0.8
    """Deceleration planned towards the goal: speed <= sqrt(2 a d), m/s^2."""
    turn_in_place_angle: float = math.radians(50.0)
    """Heading errors above this turn the robot in place, rad (in (0, pi])."""
    turn_gain: float = 2.5
    """Turn rate per radian of heading error when turning in place, 1/s."""
    max_linear_acceleration: float = 1.5
    """Largest change of the commanded speed, m/s^2."""
    max_angular_acceleration: float = 5.0
    """Largest change of the commanded turn rate, rad/s^2."""
    stop_distance: float = 0.1
    """The braking guard's margin: the gap to a return in the lane (beyond the footprint)
    at which driving towards it has stopped, m. Farther out the speed towards it is capped
    by :func:`guard_speed`."""
    stuck_steps: int = 30
    """Steps over which no progress means stuck."""
    stuck_distance: float = 0.08
    """Moving less than this (m) and turning less than ``stuck_angle`` over
    ``stuck_steps`` steps, while commanded to move, is no progress."""
    stuck_angle: float = math.radians(10.0)
    """rad; see ``stuck_distance``."""
    recovery_reverse_steps: int = 8
    """Recovery: steps backing up."""
    recovery_turn_steps: int = 8
    """Recovery: steps turning towards the lookahead point afterwards."""
    recovery_speed: float = 0.25
    """Backing-up speed in recovery, m/s."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=(
                "max_speed",
                "max_turn_rate",
                "dt",
                "max_acceleration",
                "cruise_speed",
                "min_speed",
                "lookahead",
                "goal_tolerance",
                "goal_deceleration",
                "turn_gain",
                "max_linear_acceleration",
                "max_angular_acceleration",
                "stuck_distance",
                "stuck_angle",
                "recovery_speed",
            ),
            non_negative=("stop_distance",),
            counts=("stuck_steps", "recovery_reverse_steps", "recovery_turn_steps"),
        )
        name = type(self).__name__
        require(
            name,
            "cruise_speed",
            self.cruise_speed,
            self.min_speed <= self.cruise_speed <= self.max_speed,
            f"between min_speed ({self.min_speed}) and max_speed ({self.max_speed})",
        )
        require(
            name,
            "recovery_speed",
            self.recovery_speed,
            self.recovery_speed <= self.max_speed,
            f"<= max_speed ({self.max_speed})",
        )
        angle = self.turn_in_place_angle
        require(name, "turn_in_place_angle", angle, 0 < angle <= math.pi, "in (0, pi]")

    @staticmethod
    def env_figures(env: EnvConfig) -> EnvFigures:
        """The fields that are the env's figures: the speeds at action 1, the robot's
        acceleration limit, the period."""
        return {
            "max_speed": ("robot.max_speed", env.robot.max_speed),
            "max_turn_rate": ("robot.max_turn_rate", env.robot.max_turn_rate),
            "max_acceleration": ("robot.max_acceleration", env.robot.max_acceleration),
            "dt": ("dt", env.dt),
        }

    @classmethod
    def for_env(cls, env: EnvConfig, **overrides: Any) -> FollowerConfig:
        """The follower for the env's robot; ``overrides`` set the tuning fields."""
        return build_for_env(cls, cls.env_figures(env), overrides)

    def check_env(self, env: EnvConfig) -> None:
        """Raise a ``ValueError`` if this config contradicts the env's robot or period."""
        check_against_env(self, self.env_figures(env))


def lookahead_target(
    path: FloatArray, position: ArrayLike, progress: float, lookahead: float
) -> tuple[FloatArray, float]:
    """The pure-pursuit target point on a polyline.

    Parameters
    ----------
    path : ndarray of float64, shape (P, 2)
        Waypoints, m (P >= 1).
    position : array_like, shape (2,)
        The robot, m.
    progress : float
        Arc length (m) along the path already passed; the projection is searched only
        from here on (up to ``progress + 2 * lookahead``), so the robot never snaps back
        to an earlier part of a path that doubles back.
    lookahead : float
        m.

    Returns
    -------
    target : ndarray of float64, shape (2,)
        The path point at arc length ``projection + lookahead`` (the end if beyond).
    progress : float
        Arc length of the robot's projection onto the path, m (non-decreasing).
    """
    position = np.asarray(position, dtype=np.float64)[:2]
    if len(path) == 1:
        return path[0].copy(), 0.0
    # One compiled pass over the segments (paths are tens of waypoints: a dozen small
    # numpy calls cost more than the arithmetic); the same operations in the same order.
    target_x, target_y, progress = _lookahead_kernel(
        np.ascontiguousarray(path, dtype=np.float64),
        float(position[0]),
        float(position[1]),
        float(progress),
        float(lookahead),
    )
    return np.array([target_x, target_y]), progress


@numba.njit(cache=True)
def _lookahead_kernel(
    path: FloatArray, x: float, y: float, progress: float, lookahead: float
) -> tuple[float, float, float]:
    """:func:`lookahead_target` on a path of at least two waypoints: target ``(x, y)``
    and progress."""
    count = len(path) - 1
    lengths = np.empty(count)
    starts = np.empty(count + 1)
    starts[0] = 0.0
    for k in range(count):
        lengths[k] = np.hypot(path[k + 1, 0] - path[k, 0], path[k + 1, 1] - path[k, 1])
        starts[k + 1] = starts[k] + lengths[k]
    total = starts[count]
    # Projection of the robot on each segment, as an arc length; the nearest one inside
    # the search window (the first on a tie) moves the progress on.
    reach = progress + 2.0 * lookahead
    best = -1
    best_distance = np.inf
    best_arc = 0.0
    for k in range(count):
        dx = path[k + 1, 0] - path[k, 0]
        dy = path[k + 1, 1] - path[k, 1]
        safe = max(lengths[k], 1e-12)
        t = ((x - path[k, 0]) * dx + (y - path[k, 1]) * dy) / (safe * safe)
        t = min(max(t, 0.0), 1.0)
        arc = starts[k] + t * lengths[k]
        inside = (arc >= progress - 1e-9) and (arc <= reach)
        inside = inside or ((starts[k + 1] >= progress) and (starts[k] <= reach))
        if not inside:
            continue
        distance = np.hypot(path[k, 0] + t * dx - x, path[k, 1] + t * dy - y)
        if best < 0 or distance < best_distance:
            best, best_distance, best_arc = k, distance, arc
    if best >= 0:
        progress = max(progress, best_arc)
    progress = min(progress, total)
    along = min(progress + lookahead, total)
    # The last segment starting at or before ``along`` (searchsorted, side "right").
    segment = 0
    for k in range(count + 1):
        if starts[k] <= along:
            segment = k
    segment = min(max(segment, 0), count - 1)
    fraction = min((along - starts[segment]) / max(lengths[segment], 1e-12), 1.0)
    dx = path[segment + 1, 0] - path[segment, 0]
    dy = path[segment + 1, 1] - path[segment, 1]
    return path[segment, 0] + fraction * dx, path[segment, 1] + fraction * dy, progress


def pursuit_command(
    pose: ArrayLike, target: ArrayLike, distance_to_goal: float, config: FollowerConfig
) -> tuple[float, float]:
    """Speed and turn rate that drive the robot along the arc through ``target``.

    Parameters
    ----------
    pose : array_like, shape (3,)
        ``(x, y, theta)``, m and rad.
    target : array_like, shape (2,)
        m.
    distance_to_goal : float
        Remaining path length, m; the speed follows ``sqrt(2 a d)`` near the goal.
    config : FollowerConfig

    Returns
    -------
    v : float
        m/s, >= 0.
    omega : float
        rad/s.
    """
    x, y, theta = (float(value) for value in np.asarray(pose, dtype=np.float64)[:3])
    aim = np.asarray(target, dtype=np.float64)
    dx, dy = float(aim[0]) - x, float(aim[1]) - y
    distance = math.hypot(dx, dy)
    if distance < 1e-9:
        return 0.0, 0.0
    alpha = wrap_scalar(math.atan2(dy, dx) - theta)
    if abs(alpha) > config.turn_in_place_angle:
        omega = float(
            np.clip(config.turn_gain * alpha, -config.max_turn_rate, config.max_turn_rate)
        )
        return 0.0, omega
    curvature = 2.0 * math.sin(alpha) / max(distance, 1e-6)
    speed = config.cruise_speed * (1.0 - abs(alpha) / config.turn_in_place_angle) ** 0.5
    speed = min(speed, math.sqrt(2.0 * config.goal_deceleration * max(distance_to_goal, 0.0)))
    speed = max(speed, config.min_speed)
    if abs(curvature) > 1e-9:
        speed = min(speed, config.max_turn_rate / abs(curvature))
    return speed, speed * curvature


def limit_rates(
    previous: tuple[float, float], desired: tuple[float, float], config: FollowerConfig
) -> tuple[float, float]:
    """Clamp the change from the previous ``(v, omega)`` (m/s, rad/s) to the
    acceleration limits over one control period."""
    dv = config.max_linear_acceleration * config.dt
    dw = config.max_angular_acceleration * config.dt
    v = float(np.clip(desired[0], previous[0] - dv, previous[0] + dv))
    omega = float(np.clip(desired[1], previous[1] - dw, previous[1] + dw))
    return v, omega


def lane_clearance(
    scan: ArrayLike, angles: ArrayLike, robot_radius: float, *, lane_margin: float = 0.02
) -> tuple[float, float]:
    """Free distance ahead of and behind the robot's footprint, from one scan.

    A return counts when it lies in the lane the footprint sweeps driving straight
    (half-width ``robot_radius + lane_margin``).

    Parameters
    ----------
    scan : array_like, shape (N,)
        Ranges, m.
    angles : array_like, shape (N,)
        Beam angles from the heading, rad.
    robot_radius : float
        m.
    lane_margin : float
        m.

    Returns
    -------
    front, rear : float
        Gap from the front (rear) edge of the footprint to the nearest return in the
        lane, m (``inf`` when none).
    """
    ranges = np.asarray(scan, dtype=np.float64)
    beam_angles = np.asarray(angles, dtype=np.float64)
    x = ranges * np.cos(beam_angles)
    y = ranges * np.sin(beam_angles)
    lane = np.abs(y) < robot_radius + lane_margin
    # Along the lane the footprint's front edge is at x = sqrt(r^2 - y^2).
    edge = np.sqrt(np.maximum(robot_radius**2 - y**2, 0.0))
    ahead = lane & (x > 0)
    behind = lane & (x < 0)
    front = float(np.min(x[ahead] - edge[ahead], initial=np.inf))
    rear = float(np.min(-x[behind] - edge[behind], initial=np.inf))
    return front, rear


def guard_speed(gap: float, config: FollowerConfig) -> float:
    """The fastest speed (m/s, >= 0) at which the robot may drive towards a return ``gap``
    (m) beyond its footprint: the speed ``v`` from which it stops within
    ``(gap - stop_distance) / 2``, reacting one control period late and braking at the
    robot's ``max_acceleration`` ``a``: ``v dt + v^2 / (2 a) = (gap - stop_distance) / 2``.

    The half is what makes the rule hold between two robots: a return may be a teammate
    closing in under the same rule, and then each one stops within its half of the gap.
    Against a wall it costs speed only in the last few decimetres (0.6 m/s at 0.4 m with
    the default robot).
    """
    room = 0.5 * (gap - config.stop_distance)
    if room <= 0.0:
        return 0.0
    if math.isinf(room):
        return math.inf
    a, dt = config.max_acceleration, config.dt
    return a * (math.sqrt(dt * dt + 2.0 * room / a) - dt)


def teammate_clearance(positions: ArrayLike, robot_radius: float) -> FloatArray:
    """Gaps to teammates the peer sensor sees, for the braking guard.

    Parameters
    ----------
    positions : array_like, shape (K, 2)
        Teammates' centres in the robot's body frame (x ahead), m (e.g.
        :func:`mrslam_env.slam.scan.sighted_positions` of the peer observation).
    robot_radius : float
        m (both robots' footprints).

    Returns
    -------
    ndarray of float64, shape (K, 2)
        Per teammate: the gap between the footprints (m) and the cosine of its bearing,
        the share of the robot's speed that closes the gap (> 0 ahead, < 0 behind).
    """
    points = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    distance = np.hypot(points[:, 0], points[:, 1])
    cosine = points[:, 0] / np.maximum(distance, 1e-9)
    return np.column_stack([distance - 2.0 * robot_radius, cosine])


def escape_command(
    scan: ArrayLike,
    angles: ArrayLike,
    robot_radius: float,
    *,
    step_deg: float = 10.0,
    config: FollowerConfig | None = None,
) -> NDArray[np.float32]:
    """A reactive way out when the planner cannot help (no passable cell near the robot,
    or the scan keeps stopping it where the map shows no wall, e.g. at a desk corner seen
    only edge-on): turn towards the heading whose lane (the strip the footprint sweeps)
    is clearest, and creep forward (at most 0.25 of full speed) once facing it, no faster
    than the braking guard allows (:func:`guard_speed` with ``config``: the robot's
    figures; default the default env's).

    Returns the normalised ``(v, omega)`` (float32, (2,)).
    """
    config = config if config is not None else FollowerConfig()
    ranges = np.asarray(scan, dtype=np.float64)
    beam_angles = np.asarray(angles, dtype=np.float64)
    candidates = np.radians(np.arange(-180.0, 180.0, step_deg))
    clear = np.array(
        [
            min(lane_clearance(ranges, beam_angles - heading, robot_radius)[0], 2.0)
            for heading in candidates
        ]
    )
    # The clearest lane; among nearly as clear ones, the smallest turn.
    good = clear >= clear.max() - 0.05
    direction = float(candidates[good][np.argmin(np.abs(candidates[good]))])
    front = float(clear[np.argmin(np.abs(candidates))])
    turn = float(np.clip(direction / (math.pi / 4), -1.0, 1.0))
    forward = 0.0
    if abs(direction) <= math.radians(step_deg):
        forward = min(0.25, guard_speed(front, config) / config.max_speed)
    return np.array([forward, turn], dtype=np.float32)


class PathFollower:
    """Follows a map-frame path with pure pursuit; outputs normalised actions.

    Call :meth:`set_path`, then :meth:`step` once per control period with the robot's
    pose (in the path's frame). :attr:`status` says ``"following"``, ``"reached"`` (goal
    within ``goal_tolerance``; the robot is brought to rest), ``"recovering"`` (stuck:
    backing up, then turning) or ``"idle"`` (no path). :attr:`stuck_events` counts how
    often it got stuck, so the caller can replan.

    Parameters
    ----------
    config : FollowerConfig, optional
        Defaults to the default env's robot; :meth:`for_env` follows a given env's.
    """

    def __init__(self, config: FollowerConfig | None = None) -> None:
        self.config = config if config is not None else FollowerConfig()
        self._path = np.empty((0, 2))
        self._length = 0.0
        self._progress = 0.0
        self._command = (0.0, 0.0)
        self._history: list[tuple[float, float, float]] = []
        self._recovery_left = 0
        self.status: FollowerStatus = "idle"
        self.stuck_events = 0

    @classmethod
    def for_env(cls, env: EnvConfig, config: FollowerConfig | None = None) -> PathFollower:
        """A follower for the env's robot: ``config`` (checked against the env) or
        :meth:`FollowerConfig.for_env`."""
        if config is None:
            config = FollowerConfig.for_env(env)
        config.check_env(env)
        return cls(config)

    @property
    def path(self) -> FloatArray:
        """The path being followed, (P, 2) m (a copy)."""
        return self._path.copy()

    @property
    def command(self) -> tuple[float, float]:
        """The last command ``(v m/s, omega rad/s)``."""
        return self._command

    @property
    def progress(self) -> float:
        """Arc length of the path already passed, m."""
        return self._progress

    @property
    def remaining(self) -> float:
        """Path length left, m."""
        return max(self._length - self._progress, 0.0)

    def set_path(self, path: ArrayLike) -> None:
        """Start following ``path`` (P, 2), m. An empty path stops the robot."""
        waypoints = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        if not np.all(np.isfinite(waypoints)):
            raise ValueError("PathFollower.set_path: the path holds non-finite points")
        self._path = waypoints.copy()
        self._length = (
            float(np.hypot(*np.diff(waypoints, axis=0).T).sum()) if len(waypoints) else 0.0
        )
        self._progress = 0.0
        # The motion history survives a new path: replanning is no way out of being stuck.
        if self.status != "recovering":
            self.status = "following" if len(waypoints) else "idle"

    def clear(self) -> None:
        """Drop the path; the robot brakes to a stop."""
        self._path = np.empty((0, 2))
        self._length = 0.0
        self._progress = 0.0
        self._history.clear()
        self._recovery_left = 0
        self.status = "idle"

    def step(
        self,
        pose: ArrayLike,
        *,
        clearance: tuple[float, float] | None = None,
        teammates: ArrayLike | None = None,
    ) -> NDArray[np.float32]:
        """One normalised action ``(v, omega)`` in [-1, 1] for the current pose.

        Parameters
        ----------
        pose : array_like, shape (3,)
            ``(x, y, theta)`` in the path's frame.
        clearance : tuple of float, optional
            ``(front, rear)`` free distances from :func:`lane_clearance`: the speed
            towards each side is capped by :func:`guard_speed` (the braking guard; it may
            brake harder than ``max_linear_acceleration``, up to the robot's
            ``max_acceleration``). Turning is never limited: the footprint is a disc.
        teammates : array_like, shape (K, 2), optional
            :func:`teammate_clearance` of the teammates in sight: the speed at which
            driving closes the gap to each (speed times the bearing's cosine) is capped
            by :func:`guard_speed` alike, so that a teammate closing in from the side
            (outside the lane) is not driven into either; one within ``stop_distance``
            (with ``clearance`` given) is backed away from at up to ``recovery_speed``,
            as far as the lane on that side allows.
        """
        config = self.config
        robot = np.asarray(pose, dtype=np.float64)[:3]
        wanted = self._desired(robot)
        v, omega = limit_rates(self._command, wanted, config)
        if clearance is not None:
            back_cap, ahead_cap = (
                guard_speed(clearance[1], config),
                guard_speed(clearance[0], config),
            )
            v = min(max(v, -back_cap), ahead_cap)
        if teammates is not None:
            for gap, cosine in np.asarray(teammates, dtype=np.float64).reshape(-1, 2):
                if gap < config.stop_distance and clearance is not None:
                    # Inside the margin (touching, or about to): turning in place would
                    # keep the contact; move away from it along the axis, as far as the
                    # lane on that side allows.
                    if cosine >= 0:
                        v = -min(config.recovery_speed, back_cap)
                    else:
                        v = min(config.recovery_speed, ahead_cap)
                    break
                if abs(cosine) > 1e-6:
                    cap = guard_speed(float(gap), config) / abs(float(cosine))
                    v = min(v, cap) if cosine > 0 else max(v, -cap)
        self._command = (v, omega)
        # Progress is judged against what the follower wanted: a guard stop is no excuse.
        self._watch_progress(robot, wanted)
        action = np.array(
            [self._command[0] / config.max_speed, self._command[1] / config.max_turn_rate]
        )
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    def _desired(self, robot: FloatArray) -> tuple[float, float]:
        config = self.config
        if len(self._path) == 0:
            return 0.0, 0.0
        target, self._progress = lookahead_target(
            self._path, robot[:2], self._progress, config.lookahead
        )
        if self.status == "recovering":
            self._recovery_left -= 1
            if self._recovery_left >= config.recovery_turn_steps:
                return -config.recovery_speed, 0.0
            if self._recovery_left <= 0:
                self.status = "following"
                self._history.clear()
            heading = math.atan2(target[1] - robot[1], target[0] - robot[0])
            error = wrap_scalar(heading - robot[2])
            turn = float(np.clip(config.turn_gain * error, -1.0, 1.0)) * config.max_turn_rate
            return 0.0, turn
        goal = self._path[-1]
        to_goal = math.hypot(goal[0] - robot[0], goal[1] - robot[1])
        if self.status == "reached" or to_goal < config.goal_tolerance:
            self.status = "reached"
            return 0.0, 0.0
        remaining = max(self.remaining, to_goal) - config.goal_tolerance
        return pursuit_command(robot, target, remaining, config)

    def _watch_progress(self, robot: FloatArray, desired: tuple[float, float]) -> None:
        """Start a recovery after ``stuck_steps`` steps of being told to move without
        moving or turning."""
        config = self.config
        if self.status != "following" or (desired[0] == 0.0 and desired[1] == 0.0):
            self._history.clear()
            return
        self._history.append((float(robot[0]), float(robot[1]), float(robot[2])))
        if len(self._history) <= config.stuck_steps:
            return
        del self._history[0]
        x0, y0, theta0 = self._history[0]
        moved = math.hypot(robot[0] - x0, robot[1] - y0)
        turned = abs(wrap_scalar(float(robot[2]) - theta0))
        if moved < config.stuck_distance and turned < config.stuck_angle:
            self.status = "recovering"
            self.stuck_events += 1
            self._command = (0.0, 0.0)  # it is not moving, whatever was commanded
            self._recovery_left = config.recovery_reverse_steps + config.recovery_turn_steps
            self._history.clear()
