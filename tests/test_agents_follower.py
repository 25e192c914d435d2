"""The path follower (agents.follower), driven in a kinematic unicycle simulation."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from agents.follower import (
    FollowerConfig,
    PathFollower,
    guard_speed,
    lane_clearance,
    limit_rates,
    lookahead_target,
    pursuit_command,
    teammate_clearance,
)

DT = 0.1
MAX_SPEED, MAX_TURN = 1.0, 2.0
ACCELERATION, ANGULAR_ACCELERATION = 2.0, 6.0  # the env's RobotConfig defaults


def unicycle_step(
    pose: np.ndarray, velocity: np.ndarray, action: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The env's robot model, kinematically: commanded (v, omega) reached within the
    acceleration limits, then one Euler step."""
    command = np.array([action[0] * MAX_SPEED, action[1] * MAX_TURN])
    limits = np.array([ACCELERATION, ANGULAR_ACCELERATION]) * DT
    velocity = velocity + np.clip(command - velocity, -limits, limits)
    theta = pose[2] + velocity[1] * DT
    x = pose[0] + velocity[0] * math.cos(theta) * DT
    y = pose[1] + velocity[0] * math.sin(theta) * DT
    return np.array([x, y, math.remainder(theta, 2 * math.pi)]), velocity


def distance_to_polyline(point: np.ndarray, path: np.ndarray) -> float:
    best = math.inf
    for a, b in itertools.pairwise(path):
        t = np.clip(np.dot(point - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        best = min(best, float(np.hypot(*(point - (a + t * (b - a))))))
    return best


def drive(
    follower: PathFollower, path: np.ndarray, start: np.ndarray, steps: int = 500
) -> tuple[np.ndarray, np.ndarray]:
    follower.set_path(path)
    pose, velocity = start.astype(float), np.zeros(2)
    poses, actions = [pose], []
    for _ in range(steps):
        action = follower.step(pose)
        actions.append(action)
        pose, velocity = unicycle_step(pose, velocity, action)
        poses.append(pose)
        if follower.status == "reached" and np.abs(velocity).max() < 1e-6:
            break
    return np.array(poses), np.array(actions)


L_PATHS = {
    "east_then_north": (np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]]), [0.0, 0.0, 0.0]),
    "north_then_west": (np.array([[0.0, 0.0], [0.0, 2.5], [-3.0, 2.5]]), [0.0, 0.0, 1.0]),
    "start_facing_away": (np.array([[0.0, 0.0], [3.0, 0.0], [3.0, -3.0]]), [0.0, 0.0, math.pi]),
    "short_legs": (np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.8]]), [0.0, 0.0, 0.3]),
}


@pytest.mark.parametrize("name", sorted(L_PATHS))
def test_reaches_the_goal_of_an_l_shaped_path_without_overshoot(name: str) -> None:
    path, start = L_PATHS[name]
    config = FollowerConfig()
    follower = PathFollower(config)
    poses, actions = drive(follower, path, np.array(start))
    assert follower.status == "reached"
    final = poses[-1, :2]
    goal = path[-1]
    assert np.hypot(*(final - goal)) <= config.goal_tolerance + 0.02
    # No overshoot: the robot never gets past the goal along the last leg.
    last_leg = (goal - path[-2]) / np.hypot(*(goal - path[-2]))
    beyond = (poses[:, :2] - goal) @ last_leg
    assert beyond.max() <= 0.05
    # It tracks the path (corners cut by at most about the lookahead's sagitta).
    deviation = max(distance_to_polyline(p, path) for p in poses[:, :2])
    assert deviation <= 0.25
    # Actions are normalised and change smoothly (within the acceleration limits).
    assert np.all(np.abs(actions) <= 1.0)
    jumps = np.abs(np.diff(actions, axis=0))
    assert jumps[:, 0].max() <= config.max_linear_acceleration * DT / MAX_SPEED + 1e-6
    assert jumps[:, 1].max() <= config.max_angular_acceleration * DT / MAX_TURN + 1e-6


def test_turns_in_place_when_the_path_starts_behind_the_robot() -> None:
    follower = PathFollower()
    follower.set_path(np.array([[0.0, 0.0], [-2.0, 0.0]]))
    actions = [follower.step(np.array([0.0, 0.0, 0.0])) for _ in range(5)]
    assert all(a[0] == 0.0 for a in actions)
    assert abs(actions[-1][1]) > 0.5


def test_stuck_detection_backs_up_and_counts_the_event() -> None:
    config = FollowerConfig(stuck_steps=20, recovery_reverse_steps=5, recovery_turn_steps=5)
    follower = PathFollower(config)
    follower.set_path(np.array([[0.0, 0.0], [3.0, 0.0]]))
    pinned = np.array([0.0, 0.0, 0.0])  # a robot that cannot move (against a wall)
    actions = [follower.step(pinned) for _ in range(22)]
    assert follower.stuck_events == 1
    assert follower.status == "recovering"
    backing = [follower.step(pinned) for _ in range(4)]
    assert all(a[0] < 0 for a in backing)
    assert all(a[0] >= 0 for a in actions[:20])
    for _ in range(10):
        follower.step(pinned)
    assert follower.status == "following"


def test_a_new_path_does_not_reset_stuck_detection() -> None:
    config = FollowerConfig(stuck_steps=20)
    follower = PathFollower(config)
    pinned = np.array([0.0, 0.0, 0.0])
    for step in range(25):
        if step % 10 == 0:  # the caller replans every 10 steps
            follower.set_path(np.array([[0.0, 0.0], [3.0, 0.0]]))
        follower.step(pinned)
    assert follower.stuck_events == 1


def test_the_clearance_guard_stops_forward_motion_but_allows_turning() -> None:
    follower = PathFollower()
    follower.set_path(np.array([[0.0, 0.0], [3.0, 0.5]]))
    for _ in range(10):
        action = follower.step(np.array([0.0, 0.0, 0.0]), clearance=(0.05, np.inf))
    assert action[0] == 0.0
    assert action[1] > 0.0


ANGLES = -np.pi + np.arange(360) * (2 * np.pi / 360)


def wall_ahead(distance: float) -> np.ndarray:
    """A scan (360 beams) of a wall across the heading ``distance`` m from the centre,
    nothing else within 8 m."""
    with np.errstate(divide="ignore"):
        ranges = np.where(np.cos(ANGLES) > 0, distance / np.cos(ANGLES), np.inf)
    return np.minimum(ranges, 8.0)


def test_guard_speed_stops_within_half_the_gap_less_the_margin() -> None:
    config = FollowerConfig()
    a, dt, margin = ACCELERATION, DT, config.stop_distance
    assert (config.max_acceleration, config.dt) == (a, dt)  # the env's robot and period
    assert guard_speed(margin, config) == 0.0
    assert guard_speed(0.0, config) == 0.0
    assert guard_speed(-0.1, config) == 0.0  # touching already: no closer
    assert guard_speed(np.inf, config) == np.inf
    speeds = [guard_speed(gap, config) for gap in (0.15, 0.3, 0.6, 1.2)]
    assert speeds == sorted(speeds) and speeds[0] > 0.0
    for gap, v in zip((0.15, 0.3, 0.6, 1.2), speeds, strict=True):
        assert v * dt + v * v / (2 * a) == pytest.approx((gap - margin) / 2)
    # A robot that brakes harder may drive faster at the same gap.
    assert guard_speed(0.3, FollowerConfig(max_acceleration=4.0)) > speeds[1]


def test_a_return_close_ahead_slows_the_command_and_a_clear_scan_leaves_it() -> None:
    path = np.array([[0.0, 0.0], [6.0, 0.0]])
    pose = np.array([0.0, 0.0, 0.0])
    free, guarded, close = PathFollower(), PathFollower(), PathFollower()
    for follower in (free, guarded, close):
        follower.set_path(path)
    clear = lane_clearance(np.full(360, 8.0), ANGLES, 0.2)
    near = lane_clearance(wall_ahead(0.6), ANGLES, 0.2)  # a 0.4 m gap
    for _ in range(15):  # up to cruise speed
        unguarded = free.step(pose)
        assert np.array_equal(guarded.step(pose, clearance=clear), unguarded)
        slowed = close.step(pose, clearance=near)
    assert unguarded[0] * MAX_SPEED == pytest.approx(free.config.cruise_speed, abs=1e-6)
    assert slowed[0] * MAX_SPEED == pytest.approx(guard_speed(0.4, close.config), abs=1e-6)
    assert slowed[0] < 0.8 * unguarded[0]
    # A return in the margin stops it; backing up is capped by the gap behind alike.
    assert close.step(pose, clearance=(0.08, np.inf))[0] == 0.0


def run_towards(obstacle_x: float, other_path: np.ndarray | None, steps: int = 120) -> float:
    """Drive robot A east along y = 0 towards a wall at ``obstacle_x`` (or, with
    ``other_path``, towards robot B following that path westwards under the same rule) in
    the kinematic model; return the smallest gap between footprints and walls seen."""
    radius = 0.2
    robots = [PathFollower()]
    robots[0].set_path(np.array([[0.0, 0.0], [obstacle_x + 5.0, 0.0]]))
    poses = [np.array([0.0, 0.0, 0.0])]
    if other_path is not None:
        robots.append(PathFollower())
        robots[1].set_path(other_path)
        poses.append(np.array([*other_path[0], math.pi]))
    velocities = [np.zeros(2) for _ in robots]
    smallest = math.inf
    for _ in range(steps):
        actions = []
        for i, follower in enumerate(robots):
            # The lidar's view: the wall, or the other robot's disc, along the heading.
            if other_path is None:
                gap = obstacle_x - poses[0][0] - radius
            else:
                gap = float(np.hypot(*(poses[1][:2] - poses[0][:2]))) - 2 * radius
            actions.append(follower.step(poses[i], clearance=(gap, np.inf)))
        for i, action in enumerate(actions):
            poses[i], velocities[i] = unicycle_step(poses[i], velocities[i], action)
        if other_path is None:
            smallest = min(smallest, obstacle_x - poses[0][0] - radius)
        else:
            smallest = min(smallest, float(np.hypot(*(poses[1][:2] - poses[0][:2]))) - 2 * radius)
    return smallest


def test_the_guard_keeps_a_robot_off_an_unmapped_wall_and_two_robots_apart() -> None:
    # A wall 3 m ahead that the path runs through (the map does not show it).
    gap = run_towards(3.0, None)
    assert 0.0 < gap <= PathFollower().config.stop_distance + 1e-9
    # Head-on in a corridor: both drive through where the other one is, at cruise speed.
    gap = run_towards(0.0, np.array([[4.0, 0.0], [-5.0, 0.0]]))
    assert gap > 0.0


def test_lookahead_target_moves_forward_along_the_path() -> None:
    path = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    target, progress = lookahead_target(path, [0.5, 0.1], 0.0, 0.5)
    assert progress == pytest.approx(0.5)
    np.testing.assert_allclose(target, [1.0, 0.0])
    _, progress = lookahead_target(path, [1.8, 0.05], progress, 0.5)
    assert progress == pytest.approx(1.8)
    target, progress = lookahead_target(path, [2.1, 0.3], progress, 0.5)
    assert progress == pytest.approx(2.3)
    np.testing.assert_allclose(target, [2.0, 0.8])
    # Progress never goes back, even if the robot does.
    _, again = lookahead_target(path, [0.0, 0.0], progress, 0.5)
    assert again == pytest.approx(progress)
    # Past the end the target is the end.
    target, progress = lookahead_target(path, [2.0, 2.5], progress, 0.5)
    np.testing.assert_allclose(target, [2.0, 2.0])
    assert progress == pytest.approx(4.0)


def test_lookahead_does_not_jump_to_a_later_part_of_a_path_that_doubles_back() -> None:
    # A hairpin: the return leg passes 0.3 m from the start of the outbound leg.
    path = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 0.3], [0.0, 0.3]])
    _, progress = lookahead_target(path, [0.2, 0.25], 0.0, 0.5)
    assert progress < 1.0


def _numpy_lookahead_target(
    path: np.ndarray, position: np.ndarray, progress: float, lookahead: float
) -> tuple[np.ndarray, float]:
    """The array version lookahead_target replaced (a reference for its compiled pass)."""
    segments = np.diff(path, axis=0)
    lengths = np.hypot(segments[:, 0], segments[:, 1])
    starts = np.concatenate(([0.0], np.cumsum(lengths)))
    total = float(starts[-1])
    safe = np.maximum(lengths, 1e-12)
    t = np.clip(((position - path[:-1]) * segments).sum(axis=1) / safe**2, 0.0, 1.0)
    projections = path[:-1] + t[:, None] * segments
    distance = np.hypot(*(projections - position).T)
    arc = starts[:-1] + t * lengths
    window = (arc >= progress - 1e-9) & (arc <= progress + 2.0 * lookahead)
    window |= (starts[1:] >= progress) & (starts[:-1] <= progress + 2.0 * lookahead)
    if window.any():
        candidates = np.flatnonzero(window)
        best = candidates[np.argmin(distance[candidates])]
        progress = max(progress, float(arc[best]))
    progress = min(progress, total)
    along = min(progress + lookahead, total)
    segment = int(np.clip(np.searchsorted(starts, along, side="right") - 1, 0, len(lengths) - 1))
    fraction = (along - starts[segment]) / max(lengths[segment], 1e-12)
    return path[segment] + min(fraction, 1.0) * segments[segment], progress


def test_lookahead_target_equals_the_array_version_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    for trial in range(3000):
        count = int(rng.integers(2, 40))
        path = np.cumsum(rng.normal(0.0, 0.4, (count, 2)), axis=0)
        if trial % 3 == 0:  # repeated waypoints: zero-length segments
            path = np.repeat(path, rng.integers(1, 3, count), axis=0)
        position = path[int(rng.integers(len(path)))] + rng.normal(0.0, 0.3, 2)
        progress = float(rng.uniform(0.0, 3.0)) if trial % 2 else 0.0
        lookahead = float(rng.uniform(0.1, 1.5))
        target, moved = lookahead_target(path, position, progress, lookahead)
        expected, expected_progress = _numpy_lookahead_target(path, position, progress, lookahead)
        assert moved == expected_progress
        assert np.array_equal(target, expected)


def test_pursuit_command_goes_straight_turns_and_slows_near_the_goal() -> None:
    config = FollowerConfig()
    v, omega = pursuit_command([0.0, 0.0, 0.0], [1.0, 0.0], 5.0, config)
    assert v == pytest.approx(config.cruise_speed) and omega == pytest.approx(0.0)
    v, omega = pursuit_command([0.0, 0.0, 0.0], [0.5, 0.3], 5.0, config)
    assert 0 < v < config.cruise_speed and omega > 0
    v_near, _ = pursuit_command([0.0, 0.0, 0.0], [0.2, 0.0], 0.05, config)
    assert v_near < 0.5 * config.cruise_speed
    v, omega = pursuit_command([0.0, 0.0, 0.0], [-1.0, -0.1], 5.0, config)
    assert v == 0.0 and omega < 0


def test_limit_rates_clamps_the_change_per_step() -> None:
    config = FollowerConfig(max_linear_acceleration=1.0, max_angular_acceleration=2.0, dt=0.1)
    assert limit_rates((0.0, 0.0), (1.0, -1.0), config) == pytest.approx((0.1, -0.2))
    assert limit_rates((0.5, 0.5), (0.55, 0.45), config) == pytest.approx((0.55, 0.45))


def test_lane_clearance_measures_gaps_from_the_footprint() -> None:
    angles = -np.pi + np.arange(360) * (2 * np.pi / 360)
    scan = np.full(360, 8.0)
    ahead = np.argmin(np.abs(angles))
    behind = 0  # -pi
    scan[ahead] = 1.0
    scan[behind] = 0.5
    scan[np.argmin(np.abs(angles - np.pi / 2))] = 0.3  # beside the robot: not in the lane
    front, rear = lane_clearance(scan, angles, robot_radius=0.2)
    assert front == pytest.approx(0.8)
    assert rear == pytest.approx(0.3)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("lookahead", 0.0),
        ("cruise_speed", 2.0),
        ("turn_in_place_angle", 4.0),
        ("stuck_steps", 0),
        ("stop_distance", -1.0),
        ("recovery_speed", 5.0),
    ],
)
def test_config_rejects_bad_values_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        FollowerConfig(**{field: value})  # type: ignore[arg-type]


def test_a_non_finite_path_is_rejected() -> None:
    with pytest.raises(ValueError, match="non-finite"):
        PathFollower().set_path(np.array([[0.0, 0.0], [np.nan, 1.0]]))


def test_escape_turns_to_the_clearest_lane_and_creeps_out() -> None:
    from agents.follower import escape_command

    angles = -np.pi + np.arange(360) * (2 * np.pi / 360)
    # A wall 0.3 m ahead and on the left; open (8 m) to the right and behind.
    x, y = np.cos(angles), np.sin(angles)
    ranges = np.full(360, 8.0)
    ranges[(x > 0.3) | (y > 0.3)] = 0.3
    v, omega = escape_command(ranges, angles, 0.2)
    assert v == 0.0 and omega < -0.5, "turns right, on the spot"
    # Facing an open lane (a wall only behind): drive slowly, no turn.
    open_ahead = np.where(x < -0.5, 0.3, 8.0)
    v, omega = escape_command(open_ahead, angles, 0.2)
    assert v > 0.0 and abs(omega) < 0.3
    # In a pocket (every lane as short) it creeps out as the braking guard allows: slower
    # the tighter, not at all with the return within the margin.
    gaps = (0.3, 0.13, 0.09)  # beyond the footprint
    creeps = [escape_command(np.full(360, 0.2 + gap), angles, 0.2)[0] for gap in gaps]
    assert creeps[0] == pytest.approx(0.25)
    assert creeps[1] == pytest.approx(guard_speed(0.13, FollowerConfig()), abs=1e-3)
    assert 0.0 < creeps[1] < 0.25 and creeps[2] == 0.0


def test_teammate_clearance_gives_the_gap_and_the_share_of_speed_that_closes_it() -> None:
    gaps = teammate_clearance(np.array([[1.0, 0.0], [0.0, -0.5], [-0.3, 0.4]]), 0.2)
    np.testing.assert_allclose(gaps[:, 0], [0.6, 0.1, 0.1])
    np.testing.assert_allclose(gaps[:, 1], [1.0, 0.0, -0.6], atol=1e-12)
    assert teammate_clearance(np.empty((0, 2)), 0.2).shape == (0, 2)


def test_a_teammate_closing_in_from_the_side_caps_the_speed_that_closes_the_gap() -> None:
    path = np.array([[0.0, 0.0], [6.0, 0.0]])
    pose = np.array([0.0, 0.0, 0.0])
    free, watched = PathFollower(), PathFollower()
    for follower in (free, watched):
        follower.set_path(path)
    # A teammate ahead-left at 68 degrees, 0.15 m between the footprints: outside the
    # lane (the lidar guard does not see it), but driving on closes the gap.
    beside = 0.55 * np.array([[math.cos(math.radians(68)), math.sin(math.radians(68))]])
    far = np.array([[5.0, 0.5]])
    for _ in range(15):
        unguarded = free.step(pose)
        assert np.array_equal(watched.step(pose, teammates=teammate_clearance(far, 0.2)), unguarded)
    near = teammate_clearance(beside, 0.2)
    slowed = watched.step(pose, teammates=near)
    cap = guard_speed(0.15, watched.config) / math.cos(math.radians(68))
    assert slowed[0] * MAX_SPEED == pytest.approx(cap, abs=1e-6)
    assert slowed[0] < unguarded[0]
    # Within the margin it stops; a teammate beside (90 degrees) or behind does not.
    touching = teammate_clearance(0.45 * np.array([[0.6, 0.8]]), 0.2)
    assert watched.step(pose, teammates=touching)[0] == 0.0
    side = teammate_clearance(np.array([[0.0, 0.45], [-0.45, 0.0]]), 0.2)
    assert watched.step(pose, teammates=side)[0] > 0.0


def test_a_teammate_within_the_margin_is_backed_away_from_as_the_lane_allows() -> None:
    follower = PathFollower()
    follower.set_path(np.array([[0.0, 0.0], [6.0, 0.0]]))
    pose = np.array([0.0, 0.0, 0.0])
    open_lane = (np.inf, np.inf)
    # Touching ahead-left (30 degrees): reverse; touching behind-right: forward.
    ahead = teammate_clearance(0.42 * np.array([[math.cos(0.5), math.sin(0.5)]]), 0.2)
    behind = teammate_clearance(np.array([[-0.3, -0.25]]), 0.2)
    v_ahead = follower.step(pose, clearance=open_lane, teammates=ahead)[0]
    v_behind = follower.step(pose, clearance=open_lane, teammates=behind)[0]
    assert v_ahead * MAX_SPEED == pytest.approx(-follower.config.recovery_speed)
    assert v_behind * MAX_SPEED == pytest.approx(follower.config.recovery_speed)
    # ... but never into a return on the other side.
    assert follower.step(pose, clearance=(np.inf, 0.05), teammates=ahead)[0] == 0.0
