"""Rigid-body physics of the robots and walls (the only module that imports pymunk).

Each robot is a dynamic disc driven the way pymunk's tank demo drives a body: a kinematic
*control body* carries the commanded velocity, and a pivot joint (linear) and a gear joint
(angular) with bounded forces and no position correction pull the robot towards it, like
wheel traction. The robot's own velocity is never overwritten, so contacts with walls and
other robots are resolved by the solver: robots cannot pass through walls or each other.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pymunk
from numpy.typing import NDArray

from mrslam_env.config import RobotConfig
from mrslam_env.geometry import wrap_scalar
from mrslam_env.sim.lidar import nearest_segment, segments_within
from mrslam_env.sim.world import WorldSpec

__all__ = ["Physics"]

WALL = 1
ROBOT = 2
NEW_CONTACT_OVERLAP = 0.002  # m: the most a robot may overlap a wall or robot on impact
MAX_SUBSTEPS = 100  # per env step, bounding the cost of conservative advancement


class Physics:
    """The pymunk space with static walls and ``n`` differential-drive robots.

    Parameters
    ----------
    world : WorldSpec
        Walls become static convex polygons.
    starts : ndarray, shape (n, 3)
        Initial robot poses in the world frame.
    robot : RobotConfig
        Footprint, mass and acceleration limits.
    """

    def __init__(self, world: WorldSpec, starts: NDArray[np.float64], robot: RobotConfig) -> None:
        self.robot = robot
        space = pymunk.Space()
        space.iterations = 20
        # Slop is in world units (metres): the default 0.1 would let robots sink 10 cm.
        space.collision_slop = 0.001
        for quad in world.walls:
            shape = pymunk.Poly(space.static_body, [tuple(p) for p in quad])
            shape.friction = 0.3
            shape.collision_type = WALL
            space.add(shape)
        moment = pymunk.moment_for_circle(robot.mass, 0.0, robot.radius)
        self.bodies: list[pymunk.Body] = []
        self.controls: list[pymunk.Body] = []
        for x, y, theta in np.asarray(starts, dtype=np.float64):
            body = pymunk.Body(robot.mass, moment)
            body.position = (float(x), float(y))
            body.angle = float(theta)
            disc = pymunk.Circle(body, robot.radius)
            disc.friction = 0.3
            disc.collision_type = ROBOT
            control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            control.position = body.position
            pivot = pymunk.PivotJoint(control, body, (0.0, 0.0), (0.0, 0.0))
            pivot.max_bias = 0.0
            pivot.max_force = robot.mass * 40.0
            gear = pymunk.GearJoint(control, body, 0.0, 1.0)
            gear.max_bias = 0.0
            gear.max_force = moment * 80.0
            space.add(body, disc, control, pivot, gear)
            self.bodies.append(body)
            self.controls.append(control)
        self.space = space
        self.segments = world.segments
        self.commanded = [[0.0, 0.0] for _ in self.bodies]  # ramped (v, omega) per robot
        self._last_h = 0.0  # length of the last substep run, s (0: none yet)
        self._impact = False  # whether the last substep made a new contact

    def __getstate__(self) -> dict[str, object]:
        # pymunk does not pickle its cached contacts (used to warm-start the solver), so a
        # restored space would drift from this one while robots touch walls. Re-create this
        # space through the same pickling path first: both then continue bit-identically.
        self.space, self.bodies, self.controls = copy.deepcopy(
            (self.space, self.bodies, self.controls)
        )
        names = (
            "robot",
            "space",
            "bodies",
            "controls",
            "segments",
            "commanded",
            "_last_h",
            "_impact",
        )
        return {name: getattr(self, name) for name in names}

    def __setstate__(self, state: dict[str, object]) -> None:
        for name, value in state.items():
            setattr(self, name, value)

    @property
    def n_robots(self) -> int:
        return len(self.bodies)

    def poses(self) -> NDArray[np.float64]:
        """True robot poses (n, 3) in the world frame, heading wrapped to (-pi, pi]."""
        return np.array(
            [(*body.position, wrap_scalar(body.angle)) for body in self.bodies],
            dtype=np.float64,
        ).reshape(-1, 3)

    def step(self, targets: NDArray[np.float64], dt: float, substeps: int) -> NDArray[np.bool_]:
        """Advance ``dt`` seconds driving towards target velocities.

        pymunk finds a contact only once shapes overlap, so a plain fixed step would let a
        fast robot sink up to one step of travel into a wall before being pushed out. Each
        substep is therefore cut short (conservative advancement) so that no robot closes a
        gap to a wall or another robot by more than the gap plus ``NEW_CONTACT_OVERLAP``: a
        new contact starts with at most that overlap, and the solver takes it from there.
        In open space the step is split into ``substeps`` equal parts.

        Parameters
        ----------
        targets : ndarray, shape (n, 2)
            Target ``(v, omega)`` per robot, m/s and rad/s (already within limits).
        dt : float
            Duration, s.
        substeps : int
            Physics steps to split ``dt`` into when nothing is near.

        Returns
        -------
        ndarray of bool, shape (n,)
            Whether each robot touched a wall or another robot during the step.
        """
        goals = np.asarray(targets, dtype=np.float64).tolist()
        collided = [False] * self.n_robots
        longest, shortest = dt / substeps, dt / MAX_SUBSTEPS
        # Only walls and robots within two steps of travel can be met during this step.
        reach = self.robot.radius + 2.0 * max(self.robot.max_speed, 1e-9) * dt
        positions = self._positions()
        nearby = [segments_within(x, y, reach, self.segments) for x, y in positions]
        crowded = any(len(segments) for segments in nearby) or any(
            math.hypot(xi - xj, yi - yj) < 2.0 * reach
            for k, (xi, yi) in enumerate(positions)
            for xj, yj in positions[k + 1 :]
        )
        h = self._last_h or longest  # length of the last substep run
        remaining = dt
        while remaining > 1e-12:
            target = min(longest, self._safe_duration(goals, nearby)) if crowded else longest
            # Shrink at once; grow (at most twice as long) only after a substep without a
            # new contact: pymunk warm-starts with the last impulses scaled by the ratio of
            # step lengths, which would multiply an impact impulse into a kick.
            if target <= h:
                h = target
            elif not self._impact:
                h = min(2.0 * h, target)
            h = min(max(h, shortest), remaining)
            self._drive(goals, h)
            self.space.step(h)
            remaining -= h
            self._impact = False
            for i, body in enumerate(self.bodies):
                touching, first = _contacts(body)
                collided[i] = collided[i] or touching
                self._impact = self._impact or first
        self._last_h = h
        return np.array(collided, dtype=bool)

    def _positions(self) -> list[tuple[float, float]]:
        return [(float(b.position.x), float(b.position.y)) for b in self.bodies]

    def _drive(self, goals: list[list[float]], h: float) -> None:
        """Move each commanded velocity towards its target within the acceleration limits
        and set the control body to it, along the robot's current heading.

        The ramp acts on the command, like a motor controller's: a robot stalled against a
        wall keeps its forward command until the new target has ramped past it."""
        dv = self.robot.max_acceleration * h
        dw = self.robot.max_angular_acceleration * h
        for i, (body, control) in enumerate(zip(self.bodies, self.controls, strict=True)):
            v, w = self.commanded[i]
            v += min(max(goals[i][0] - v, -dv), dv)
            w += min(max(goals[i][1] - w, -dw), dw)
            self.commanded[i] = [v, w]
            c, s = math.cos(body.angle), math.sin(body.angle)
            control.velocity = (v * c, v * s)
            control.angular_velocity = w

    def _safe_duration(self, goals: list[list[float]], nearby: list[NDArray[np.float64]]) -> float:
        """Longest substep (s) in which no gap to a wall or robot closes by more than the
        gap plus ``NEW_CONTACT_OVERLAP``; touching pairs (gap <= 0) are the solver's."""
        radius = self.robot.radius
        safe = math.inf
        speeds = []
        positions = self._positions()
        for body, (v_goal, _), (x, y), segments in zip(
            self.bodies, goals, positions, nearby, strict=True
        ):
            # Bound the speed over the substep by what the robot has and what it may reach.
            speed = max(abs(body.velocity), abs(v_goal), 1e-9)
            speeds.append(speed)
            gap = nearest_segment(x, y, segments)[0] - radius
            if gap > 0.0:
                safe = min(safe, (gap + NEW_CONTACT_OVERLAP) / speed)
        for i in range(self.n_robots):
            for j in range(i + 1, self.n_robots):
                (xi, yi), (xj, yj) = positions[i], positions[j]
                gap = math.hypot(xj - xi, yj - yi) - 2.0 * radius
                if gap > 0.0:
                    safe = min(safe, (gap + NEW_CONTACT_OVERLAP) / (speeds[i] + speeds[j]))
        return safe


def _contacts(body: pymunk.Body) -> tuple[bool, bool]:
    """Whether the body touches anything, and whether any of the contacts is new."""
    touching: list[bool] = []
    first: list[bool] = []

    def visit(arbiter: pymunk.Arbiter) -> None:
        touching.append(True)
        if arbiter.is_first_contact:
            first.append(True)

    body.each_arbiter(visit)
    return bool(touching), bool(first)
