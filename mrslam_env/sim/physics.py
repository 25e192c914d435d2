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
from mrslam_env.sim.world import WorldSpec

__all__ = ["Physics"]

WALL = 1
ROBOT = 2


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
        n = len(self.bodies)
        self.commanded = np.zeros((n, 2))  # the ramped (v, omega) actually applied

    def __getstate__(self) -> dict[str, object]:
        # pymunk does not pickle its cached contacts (used to warm-start the solver), so a
        # restored space would drift from this one while robots touch walls. Re-create this
        # space through the same pickling path first: both then continue bit-identically.
        self.space, self.bodies, self.controls = copy.deepcopy(
            (self.space, self.bodies, self.controls)
        )
        return {
            name: getattr(self, name)
            for name in ("robot", "space", "bodies", "controls", "commanded")
        }

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

        Parameters
        ----------
        targets : ndarray, shape (n, 2)
            Target ``(v, omega)`` per robot, m/s and rad/s (already within limits).
        dt : float
            Duration, s.
        substeps : int
            Physics steps to split ``dt`` into.

        Returns
        -------
        ndarray of bool, shape (n,)
            Whether each robot touched a wall or another robot during the step.
        """
        h = dt / substeps
        dv = self.robot.max_acceleration * h
        dw = self.robot.max_angular_acceleration * h
        collided = [False] * self.n_robots
        commanded = self.commanded.tolist()
        goals = np.asarray(targets, dtype=np.float64).tolist()
        robots = list(zip(self.bodies, self.controls, strict=True))
        for _ in range(substeps):
            for i, (body, control) in enumerate(robots):
                v, w = commanded[i]
                v += min(max(goals[i][0] - v, -dv), dv)
                w += min(max(goals[i][1] - w, -dw), dw)
                commanded[i] = [v, w]
                angle = body.angle
                control.velocity = (v * math.cos(angle), v * math.sin(angle))
                control.angular_velocity = w
            self.space.step(h)
            for i, (body, _control) in enumerate(robots):
                if not collided[i]:
                    collided[i] = _touching(body)
        self.commanded = np.array(commanded)
        return np.array(collided, dtype=bool)


def _touching(body: pymunk.Body) -> bool:
    contacts: list[bool] = []
    body.each_arbiter(lambda arbiter: contacts.append(True))
    return bool(contacts)
