"""Rigid-body physics of the robots (mrslam_env.sim.physics): walls and robots are solid,
collisions are reported, acceleration limits and commanded velocities are honoured.

Every run uses the default robot and the default control period and physics substeps of
``EnvConfig`` (whatever they are), driven at full speed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrslam_env.config import EnvConfig, RobotConfig
from mrslam_env.gridmap import OCCUPIED
from mrslam_env.sim.lidar import line_of_sight
from mrslam_env.sim.physics import Physics
from mrslam_env.sim.world import WorldSpec, box, ground_truth_map, polyline_walls

ROBOT = RobotConfig()
R = ROBOT.radius
V = ROBOT.max_speed
W = ROBOT.max_turn_rate
DT = EnvConfig().dt
SUBSTEPS = EnvConfig().physics_substeps
THIN = 0.05  # m, wall thickness of the hard cases
# pymunk has no continuous collision detection: a contact appears only once the shapes
# overlap, so on impact a robot can sink by up to one substep of travel (plus the slop)
# before the solver pushes it out again.
SUBSTEP_TRAVEL = V * DT / SUBSTEPS
PENETRATION_BOUND = SUBSTEP_TRAVEL + 0.005
SETTLED_SLOP = 0.002  # m, overlap left once a robot rests against a wall


def room(*extra: np.ndarray, half: float = 5.0) -> WorldSpec:
    """A closed square room [-half, half]^2 (0.1 m outer walls) plus extra walls."""
    t = 0.1
    outer = [
        box(-half, -half, half, -half + t),
        box(-half, half - t, half, half),
        box(-half, -half, -half + t, half),
        box(half - t, -half, half, half),
    ]
    return WorldSpec.from_walls("room", [*outer, *extra], [(0.0, 0.0, 0.0)])


def drive(world: WorldSpec, starts, targets, steps: int):
    """Run ``steps`` env steps; return poses (steps, n, 3) and collisions (steps, n)."""
    physics = Physics(world, np.asarray(starts, dtype=np.float64), ROBOT)
    targets = np.asarray(targets, dtype=np.float64)
    poses, collisions = [], []
    for _ in range(steps):
        collisions.append(physics.step(targets, DT, SUBSTEPS))
        poses.append(physics.poses())
    return np.array(poses), np.array(collisions)


def min_clearance(world: WorldSpec, poses: np.ndarray) -> float:
    return float(world.clearance(poses[..., :2].reshape(-1, 2)).min())


def passes_through_a_wall(world: WorldSpec, poses: np.ndarray) -> bool:
    """Whether any robot centre crossed a wall edge between consecutive steps.

    Centres keep a clearance of about a radius, and move at most 0.1 m per step, so a
    crossing of a wall edge is a pass through the wall (not a path around its end).
    """
    for k in range(1, len(poses)):
        for a, b in zip(poses[k - 1], poses[k], strict=True):
            if not line_of_sight(a[0], a[1], b[0], b[1], world.segments):
                return True
    return False


# A wall across the whole room at x in [2, 2.05]: its far side is unreachable.
DIVIDER = room(box(2.0, -5.0, 2.0 + THIN, 5.0))

HEAD_ON_CASES = [
    # (start x offset, heading, turn command as a fraction of max)
    (0.0, 0.0, 0.0),
    (0.007, 0.0, 0.0),
    (0.013, 0.0, 0.0),
    (0.031, 0.0, 0.0),
    (0.043, 0.0, 0.0),
    (0.0, 0.4, 0.0),
    (0.011, -0.9, 0.0),
    (0.0, 0.2, 0.15),
    (0.005, -0.3, -0.1),
    (0.0, 0.0, 1.0),  # spinning while pushing
]


@pytest.mark.parametrize(("offset", "heading", "turn"), HEAD_ON_CASES)
def test_full_speed_into_a_thin_wall_never_passes_through(
    offset: float, heading: float, turn: float
) -> None:
    start = (0.5 + offset, 0.0, heading)
    poses, collisions = drive(DIVIDER, [start], [(V, turn * W)], 60)
    x = poses[:, 0, 0]
    assert np.all(x < 2.0)  # never on the far side
    assert not passes_through_a_wall(DIVIDER, poses)
    assert min_clearance(DIVIDER, poses) >= R - PENETRATION_BOUND
    if turn == 0.0:
        # It reached the wall and was stopped there, in contact.
        assert x.max() > 2.0 - R - 0.05
        assert collisions[-1, 0]
        assert DIVIDER.clearance(poses[-1, :, :2])[0] >= R - SETTLED_SLOP


def test_full_speed_impact_penetrates_less_than_one_centimetre() -> None:
    worst = math.inf
    for offset in np.linspace(0.0, SUBSTEP_TRAVEL, 9):
        poses, _ = drive(DIVIDER, [(0.5 + offset, 0.0, 0.0)], [(V, 0.0)], 30)
        worst = min(worst, min_clearance(DIVIDER, poses))
    assert worst >= R - 0.01


@pytest.mark.parametrize("aim", [-0.25, -0.1, 0.0, 0.1, 0.2])
def test_convex_corner_deflects_without_passing_through(aim: float) -> None:
    # A thin wall from the bottom outer wall up to a free end at y = 0 (plus the cap).
    world = room(*polyline_walls([(2.0, -5.0), (2.0, 0.0)], THIN))
    tip_y = THIN / 2
    start = np.array([0.0, aim])
    heading = 0.15  # slightly upwards: slides along the wall and around its end
    poses, _ = drive(world, [(*start, heading)], [(V, 0.0)], 80)
    assert min_clearance(world, poses) >= R - PENETRATION_BOUND
    assert not passes_through_a_wall(world, poses)
    x, y = poses[:, 0, 0], poses[:, 0, 1]
    crossed = np.nonzero(np.sign(x[1:] - 2.0) != np.sign(x[:-1] - 2.0))[0]
    for k in crossed:
        # The centre crosses the wall's line only above its end, a radius away from it.
        assert min(y[k], y[k + 1]) >= tip_y + R - PENETRATION_BOUND


@pytest.mark.parametrize("opening_deg", [90.0, 40.0, 20.0])
@pytest.mark.parametrize("turn", [0.0, 0.5])
def test_concave_corner_holds(opening_deg: float, turn: float) -> None:
    # Two thin walls meeting at (3, 0), opening towards -x, the robot driven into the apex.
    half = math.radians(opening_deg) / 2
    length = 4.0
    ends = [(3.0 - length * math.cos(half), s * length * math.sin(half)) for s in (1, -1)]
    world = room(*polyline_walls([ends[0], (3.0, 0.0), ends[1]], THIN))
    poses, collisions = drive(world, [(0.0, 0.0, 0.0)], [(V, turn * W)], 80)
    assert min_clearance(world, poses) >= R - PENETRATION_BOUND
    assert not passes_through_a_wall(world, poses)
    x, y = poses[:, 0, 0], poses[:, 0, 1]
    assert np.all(x < 3.0)  # never beyond the apex
    if turn == 0.0:
        # Driven straight in, it stays inside the wedge...
        assert np.all(np.abs(y) <= (3.0 - x) * math.tan(half) + 1e-9)
        # Wedged in: at rest, in contact, as deep as the footprint allows.
        assert collisions[-1, 0]
        assert x[-1] == pytest.approx(3.0 - (R + THIN / 2) / math.sin(half), abs=0.02)


def test_gap_narrower_than_the_robot_is_impassable() -> None:
    gap = 0.3  # < 2 r
    world = room(box(2.0, -5.0, 2.0 + THIN, -gap / 2), box(2.0, gap / 2, 2.0 + THIN, 5.0))
    for y0 in (0.0, 0.03):
        poses, collisions = drive(world, [(0.0, y0, 0.0)], [(V, 0.0)], 60)
        assert np.all(poses[:, 0, 0] < 2.0 + THIN / 2)
        assert not passes_through_a_wall(world, poses)
        assert min_clearance(world, poses) >= R - PENETRATION_BOUND
        assert collisions[-1, 0]
    # Nor when a second robot pushes the first one into it at full speed.
    starts = [(1.0, 0.0, 0.0), (0.0, 0.02, 0.0)]
    poses, collisions = drive(world, starts, [(V, 0.0), (V, 0.0)], 80)
    assert np.all(poses[:, :, 0] < 2.0 + THIN / 2)
    assert not passes_through_a_wall(world, poses)
    assert min_clearance(world, poses) >= R - PENETRATION_BOUND
    assert collisions[-1].all()


def pair_distance(poses: np.ndarray) -> np.ndarray:
    return np.hypot(*(poses[:, 0, :2] - poses[:, 1, :2]).T)


@pytest.mark.parametrize("offset", [0.0, 0.011, 0.027, 0.061])
@pytest.mark.parametrize("lateral", [0.0, 0.1, 0.3])
def test_two_robots_head_on_never_overlap_and_report_the_collision(
    offset: float, lateral: float
) -> None:
    world = room()
    starts = [(-1.5 + offset, 0.0, 0.0), (1.5, lateral, math.pi)]
    poses, collisions = drive(world, starts, [(V, 0.0), (V, 0.0)], 60)
    distance = pair_distance(poses)
    # Relative speed is twice the robot speed: up to two substeps of travel on impact.
    assert distance.min() >= 2 * R - 2 * PENETRATION_BOUND
    assert not passes_through_a_wall(world, poses)
    # Far from the walls, a robot is in contact exactly when it touches the other one:
    # reported on every step that ends overlapping, never on a step that starts and ends
    # further apart than the step's relative travel.
    overlapping = distance < 2 * R
    assert overlapping.any()
    assert collisions[overlapping].all()
    apart = np.minimum(distance, np.r_[3.0, distance[:-1]]) > 2 * R + 2 * V * DT + 0.01
    assert apart.any()
    assert not collisions[apart].any()
    np.testing.assert_array_equal(collisions[:, 0], collisions[:, 1])
    if lateral == 0.0:
        # Pressed together for good, at rest.
        assert collisions[-10:].all()
        assert distance[-1] == pytest.approx(2 * R, abs=SETTLED_SLOP)


def test_two_robots_head_on_overlap_less_than_one_centimetre() -> None:
    worst = math.inf
    for offset in np.linspace(0.0, 2 * SUBSTEP_TRAVEL, 9):
        poses, _ = drive(
            room(), [(-1.5 + offset, 0.0, 0.0), (1.5, 0.05, math.pi)], [(V, 0.0), (V, 0.0)], 40
        )
        worst = min(worst, pair_distance(poses).min())
    assert worst >= 2 * R - 0.01


@pytest.mark.parametrize("lateral", [0.0, 0.05])
def test_robot_squeezed_between_a_robot_and_a_thin_wall(lateral: float) -> None:
    # Both drive at the divider at full speed, robot 1 behind robot 0.
    starts = [(1.0, 0.0, 0.0), (0.0, lateral, 0.0)]
    poses, collisions = drive(DIVIDER, starts, [(V, 0.0), (V, 0.0)], 80)
    assert np.all(poses[:, :, 0] < 2.0)
    assert not passes_through_a_wall(DIVIDER, poses)
    assert min_clearance(DIVIDER, poses) >= R - PENETRATION_BOUND
    assert pair_distance(poses).min() >= 2 * R - 2 * PENETRATION_BOUND
    assert collisions[-1].all()


def test_no_collision_reported_in_open_space() -> None:
    world = room()
    starts = [(-2.0, -2.0, 0.0), (2.0, 2.0, 1.0)]
    _, collisions = drive(world, starts, [(V, W / 2), (-V, -W)], 40)
    assert not collisions.any()


def test_collision_flag_clears_after_backing_off() -> None:
    physics = Physics(DIVIDER, np.array([[1.0, 0.0, 0.0]]), ROBOT)
    for _ in range(20):
        touching = physics.step(np.array([[V, 0.0]]), DT, SUBSTEPS)
    assert touching[0]
    # The ramped command was still +V while stalled against the wall: it takes
    # max_speed / max_acceleration (0.5 s) to ramp down before the robot backs off.
    flags = [physics.step(np.array([[-V, 0.0]]), DT, SUBSTEPS)[0] for _ in range(12)]
    assert flags[0]
    assert not any(flags[-4:])
    assert DIVIDER.clearance(physics.poses()[:, :2])[0] > R + 0.1


def test_acceleration_limits_from_rest() -> None:
    physics = Physics(room(), np.zeros((1, 3)), ROBOT)
    physics.step(np.array([[V, W]]), DT, SUBSTEPS)
    body = physics.bodies[0]
    assert abs(body.velocity) <= ROBOT.max_acceleration * DT + 1e-6
    assert abs(body.angular_velocity) <= ROBOT.max_angular_acceleration * DT + 1e-6
    # In open space the robot does follow the ramp exactly.
    assert abs(body.velocity) == pytest.approx(ROBOT.max_acceleration * DT, rel=1e-6)
    assert body.angular_velocity == pytest.approx(ROBOT.max_angular_acceleration * DT, rel=1e-6)


def test_deceleration_and_reversal_are_rate_limited() -> None:
    physics = Physics(room(), np.zeros((1, 3)), ROBOT)
    for _ in range(10):
        physics.step(np.array([[V, 0.0]]), DT, SUBSTEPS)
    speeds = []
    for _ in range(12):
        physics.step(np.array([[-V, 0.0]]), DT, SUBSTEPS)
        speeds.append(physics.bodies[0].velocity.x)
    steps = np.diff([V, *speeds])
    assert np.all(np.abs(steps) <= ROBOT.max_acceleration * DT + 1e-6)
    assert speeds[-1] == pytest.approx(-V, rel=0.02)


def test_reaches_commanded_speed_in_open_space() -> None:
    poses, collisions = drive(room(), [(-3.0, 0.5, 0.3)], [(V, 0.0)], 30)
    assert not collisions.any()
    advance = np.hypot(*np.diff(poses[-10:, 0, :2], axis=0).T)
    np.testing.assert_allclose(advance / DT, V, rtol=0.02)
    # Straight along the heading.
    direction = poses[-1, 0, :2] - poses[-10, 0, :2]
    assert math.atan2(direction[1], direction[0]) == pytest.approx(0.3, abs=1e-3)
    assert poses[-1, 0, 2] == pytest.approx(0.3, abs=1e-6)


@pytest.mark.parametrize("fraction", [1.0, -0.5])
def test_turns_at_the_commanded_rate(fraction: float) -> None:
    poses, _ = drive(room(), [(0.0, 0.0, 0.0)], [(0.0, fraction * W)], 20)
    dtheta = np.angle(np.exp(1j * np.diff(poses[-8:, 0, 2])))
    np.testing.assert_allclose(dtheta / DT, fraction * W, rtol=0.02)
    # Turning in place does not move the centre.
    assert np.abs(poses[:, 0, :2]).max() < 1e-6


def test_driving_and_turning_follows_a_circle() -> None:
    v, w = V, W / 2
    poses, collisions = drive(room(), [(0.0, 0.0, 0.0)], [(v, w)], 80)
    assert not collisions.any()
    # Once at speed, the centre moves on a circle of radius v / w.
    xy = poses[20:, 0, :2]

    # Fit the circle centre: the perpendicular bisector of two chords.
    def centre(p1, p2, p3):
        a = np.array([p2 - p1, p3 - p1]) * 2
        b = np.array([p2 @ p2 - p1 @ p1, p3 @ p3 - p1 @ p1])
        return np.linalg.solve(a, b)

    c = centre(xy[0], xy[len(xy) // 3], xy[2 * len(xy) // 3])
    radii = np.linalg.norm(xy - c, axis=1)
    np.testing.assert_allclose(radii, v / w, rtol=0.02)


def test_poses_shape_and_wrapping() -> None:
    physics = Physics(room(), np.array([[0.0, 0.0, 3.0], [2.0, 2.0, -2.0]]), ROBOT)
    for _ in range(10):
        physics.step(np.array([[0.0, W], [0.0, -W]]), DT, SUBSTEPS)
    assert physics.bodies[0].angle > math.pi  # the body's own angle is not wrapped
    assert physics.bodies[1].angle < -math.pi
    poses = physics.poses()
    assert poses.shape == (2, 3)
    assert poses.dtype == np.float64
    assert np.all((poses[:, 2] > -math.pi) & (poses[:, 2] <= math.pi))
    # The unwrapped body angle and the wrapped pose heading agree modulo 2 pi.
    for body, p in zip(physics.bodies, poses, strict=True):
        assert math.cos(body.angle) == pytest.approx(math.cos(p[2]), abs=1e-12)
        assert math.sin(body.angle) == pytest.approx(math.sin(p[2]), abs=1e-12)


# --- a long randomised run ----------------------------------------------------------------


def cluttered_room() -> WorldSpec:
    """A 6 x 4 m enclosure with thin internal walls: a T, an L (convex and concave
    corners), a free-standing stub and a narrow gap."""
    t = THIN
    walls = [
        box(0.0, 0.0, 6.0, 0.1),
        box(0.0, 3.9, 6.0, 4.0),
        box(0.0, 0.0, 0.1, 4.0),
        box(5.9, 0.0, 6.0, 4.0),
        *polyline_walls([(2.0, 0.1), (2.0, 2.2)], t),  # from the bottom wall
        *polyline_walls([(1.2, 2.2), (2.8, 2.2)], t),  # T on top of it
        *polyline_walls([(4.0, 3.9), (4.0, 2.6), (5.0, 2.6)], t),  # an L hanging down
        *polyline_walls([(3.4, 0.9), (4.6, 1.4)], t),  # a diagonal stub
        *polyline_walls([(4.6, 0.1), (4.6, 0.6)], t),  # a short pier: a narrow niche
    ]
    return WorldSpec.from_walls("cluttered", walls, [(1.0, 1.0, 0.0), (5.0, 2.0, math.pi)])


def test_long_random_run_never_enters_walls() -> None:
    world = cluttered_room()
    grid = ground_truth_map(world, 0.05)
    physics = Physics(world, world.starts, ROBOT)
    rng = np.random.default_rng(2024)
    targets = np.zeros((2, 2))
    hold = np.zeros(2, dtype=int)
    inner = (0.1, 0.1, 5.9, 3.9)
    any_collision = np.zeros(2, dtype=bool)
    worst_clearance = math.inf
    previous = physics.poses()
    for _ in range(3000):
        for i in range(2):
            if hold[i] == 0:
                # Full-magnitude commands held for 0.5-4 s, so robots hit walls at full speed.
                targets[i] = (rng.choice([-V, V]), rng.choice([-W, 0.0, 0.0, W]))
                hold[i] = rng.integers(5, 40)
            hold[i] -= 1
        any_collision |= physics.step(targets, DT, SUBSTEPS)
        poses = physics.poses()
        assert not passes_through_a_wall(world, np.stack([previous, poses]))
        previous = poses
        cells = grid.world_to_cell(poses[:, :2])
        assert np.all(grid.contains(cells))
        assert not np.any(grid.cells[cells[:, 0], cells[:, 1]] == OCCUPIED)
        assert np.all((poses[:, 0] > inner[0]) & (poses[:, 0] < inner[2]))
        assert np.all((poses[:, 1] > inner[1]) & (poses[:, 1] < inner[3]))
        worst_clearance = min(worst_clearance, float(world.clearance(poses[:, :2]).min()))
        assert np.hypot(*(poses[0, :2] - poses[1, :2])) >= 2 * R - 2 * PENETRATION_BOUND
    assert worst_clearance >= R - PENETRATION_BOUND
    assert any_collision.all()  # the run did push both robots into walls
