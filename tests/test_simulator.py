"""The simulator (mrslam_env.sim.simulator): determinism, comm link, peer sensor, lidar of
other robots, odometry frame, start validation and automatic starts."""

from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np
import pytest

from mrslam_env.config import (
    CommConfig,
    EnvConfig,
    LidarConfig,
    OdometryConfig,
    PeerSensorConfig,
    RobotConfig,
)
from mrslam_env.geometry import compose, inverse
from mrslam_env.sim.lidar import cast_scan, line_of_sight
from mrslam_env.sim.simulator import SimState, Simulator, choose_starts
from mrslam_env.sim.world import WorldSpec, box, polyline_walls

R = RobotConfig().radius


def two_rooms() -> WorldSpec:
    """10 x 6 m enclosure split by a wall at x = 5 from the floor to y = 4 (a door above)."""
    walls = [
        box(0.0, 0.0, 10.0, 0.1),
        box(0.0, 5.9, 10.0, 6.0),
        box(0.0, 0.0, 0.1, 6.0),
        box(9.9, 0.0, 10.0, 6.0),
        box(4.95, 0.1, 5.05, 4.0),
    ]
    return WorldSpec.from_walls("two_rooms", walls, [(2.0, 2.0, 0.0), (8.0, 2.0, math.pi)])


EXACT = EnvConfig(
    lidar=LidarConfig(range_noise_std=0.0, dropout_probability=0.0),
    odometry=OdometryConfig(alpha1=0.0, alpha2=0.0, alpha3=0.0, alpha4=0.0),
    peer=PeerSensorConfig(
        detect_range=5.0, range_noise_std=0.0, bearing_noise_std=0.0, heading_noise_std=0.0
    ),
)


def simulator(
    config: EnvConfig = EXACT, starts=None, n_robots: int = 2, seed: int = 0
) -> Simulator:
    if starts is not None:
        config = replace(config, starts=tuple(tuple(s) for s in starts))
    return Simulator(two_rooms(), n_robots, config, np.random.default_rng(seed))


def random_commands(seed: int, steps: int, n: int = 2) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (steps, n, 2))


# --- state layout and determinism --------------------------------------------------------


def test_initial_state_layout() -> None:
    sim = simulator(EnvConfig(), n_robots=3)
    state = sim.state
    assert isinstance(state, SimState)
    assert state.true_poses.shape == (3, 3)
    assert state.scans.shape == (3, 360)
    assert state.odometry.shape == (3, 3)
    assert state.peers.shape == (3, 2, 4)
    assert state.comm.shape == (3, 2)
    assert state.comm.dtype == bool
    assert state.collisions.shape == (3,)
    assert not state.collisions.any()
    np.testing.assert_array_equal(state.odometry, np.zeros((3, 3)))
    np.testing.assert_allclose(state.true_poses[:2], two_rooms().starts, atol=1e-12)


def states_equal(a: SimState, b: SimState) -> bool:
    return all(np.array_equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(SimState))


def test_same_seed_and_commands_give_bit_identical_runs() -> None:
    commands = random_commands(1, 200, n=3)
    a = simulator(EnvConfig(), n_robots=3, seed=7)
    b = simulator(EnvConfig(), n_robots=3, seed=7)
    assert states_equal(a.state, b.state)
    for command in commands:
        assert states_equal(a.step(command), b.step(command))


def test_different_seeds_differ() -> None:
    commands = random_commands(2, 50)
    a, b = simulator(EnvConfig(), seed=1), simulator(EnvConfig(), seed=2)
    scans_differ = odometry_differs = False
    for command in commands:
        sa, sb = a.step(command), b.step(command)
        scans_differ |= not np.array_equal(sa.scans, sb.scans)
        odometry_differs |= not np.array_equal(sa.odometry, sb.odometry)
    assert scans_differ
    assert odometry_differs
    # Automatic starts depend on the seed too.
    starts = {tuple(simulator(EnvConfig(), n_robots=3, seed=s).starts[2]) for s in range(4)}
    assert len(starts) > 1


def test_commands_are_clipped() -> None:
    a, b = simulator(seed=3), simulator(seed=3)
    for _ in range(20):
        sa = a.step(np.array([[5.0, -7.0], [1.0, 0.0]]))
        sb = b.step(np.array([[1.0, -1.0], [1.0, 0.0]]))
        assert states_equal(sa, sb)


def test_time_advances_by_dt() -> None:
    sim = simulator()
    for _ in range(7):
        sim.step(np.zeros((2, 2)))
    assert sim.time == pytest.approx(7 * EXACT.dt)


# --- sensors in the loop ------------------------------------------------------------------


def test_exact_scans_see_walls_and_the_other_robot() -> None:
    sim = simulator(starts=[(2.0, 2.0, 0.3), (3.5, 2.5, 1.0)])
    world = sim.world
    for command in random_commands(4, 30):
        state = sim.step(command * 0.3)
        for i in range(2):
            others = np.array([[*state.true_poses[j, :2], R] for j in range(2)])
            expected = cast_scan(
                *state.true_poses[i], 360, EXACT.lidar.max_range, world.segments, others
            )
            np.testing.assert_array_equal(state.scans[i], expected)
    # The other robot is in the scan: robot 0 looking at robot 1.
    poses = state.true_poses
    bearing = math.atan2(*(poses[1, 1::-1] - poses[0, 1::-1])) - poses[0, 2]
    beam = round((bearing + math.pi) / (2 * math.pi / 360)) % 360
    distance = math.hypot(*(poses[1, :2] - poses[0, :2]))
    assert state.scans[0, beam] == pytest.approx(distance - R, abs=0.01)


def test_odometry_starts_at_zero_and_tracks_the_start_frame_without_noise() -> None:
    sim = simulator(starts=[(2.0, 2.0, 0.7), (8.0, 1.5, -2.0)])
    np.testing.assert_array_equal(sim.state.odometry, np.zeros((2, 3)))
    starts = sim.state.true_poses.copy()
    for command in random_commands(5, 200):
        state = sim.step(command)
    expected = compose(inverse(starts), state.true_poses)
    np.testing.assert_allclose(state.odometry[:, :2], expected[:, :2], atol=1e-9)
    np.testing.assert_allclose(np.cos(state.odometry[:, 2] - expected[:, 2]), 1.0, atol=1e-12)
    assert np.abs(state.true_poses[:, :2] - starts[:, :2]).max() > 0.5  # it did move


def test_odometry_with_noise_drifts_from_truth() -> None:
    sim = simulator(EnvConfig(), starts=[(2.0, 2.0, 0.0), (8.0, 2.0, math.pi)], seed=6)
    starts = sim.state.true_poses.copy()
    for _ in range(100):
        state = sim.step(np.array([[0.5, 0.2], [0.5, -0.2]]))
    expected = compose(inverse(starts), state.true_poses)
    error = np.hypot(*(state.odometry[:, :2] - expected[:, :2]).T)
    assert np.all(error > 1e-3)
    assert np.all(error < 1.0)


def test_collisions_are_reported_in_the_state() -> None:
    sim = simulator(starts=[(4.4, 1.0, 0.0), (8.0, 2.0, math.pi)])
    collided = []
    for _ in range(15):
        collided.append(sim.step(np.array([[1.0, 0.0], [0.0, 0.0]])).collisions.copy())
    collided = np.array(collided)
    assert collided[-1, 0]
    assert not collided[:, 1].any()


# --- comm link ----------------------------------------------------------------------------


def comm_of(config: EnvConfig, starts, seed: int = 0) -> np.ndarray:
    return simulator(config, starts=starts, seed=seed).state.comm


SAME_ROOM = [(1.0, 1.0, 0.0), (4.0, 3.0, 0.0)]  # 3.6 m apart, line of sight
ACROSS_WALL = [(2.0, 2.0, 0.0), (8.0, 2.0, 0.0)]  # 6 m apart, wall in between


def test_comm_link_range() -> None:
    assert comm_of(replace(EXACT, comm=CommConfig(comm_range=12.0)), ACROSS_WALL).all()
    assert not comm_of(replace(EXACT, comm=CommConfig(comm_range=5.9)), ACROSS_WALL).any()
    assert comm_of(replace(EXACT, comm=CommConfig(comm_range=6.0)), ACROSS_WALL).all()
    assert comm_of(replace(EXACT, comm=CommConfig(comm_range=4.0)), SAME_ROOM).all()
    assert not comm_of(replace(EXACT, comm=CommConfig(comm_range=3.0)), SAME_ROOM).any()


def test_comm_link_blocked_by_walls() -> None:
    blocked = replace(EXACT, comm=CommConfig(comm_range=12.0, blocked_by_walls=True))
    assert not line_of_sight(2.0, 2.0, 8.0, 2.0, two_rooms().segments)
    assert not comm_of(blocked, ACROSS_WALL).any()
    assert comm_of(blocked, SAME_ROOM).all()
    # Through the door above the wall.
    assert comm_of(blocked, [(2.0, 5.0, 0.0), (8.0, 5.0, 0.0)]).all()


def test_packet_loss_one_is_always_down() -> None:
    config = replace(EXACT, comm=CommConfig(comm_range=12.0, packet_loss=1.0))
    sim = simulator(config, starts=SAME_ROOM)
    assert not sim.state.comm.any()
    for command in random_commands(7, 50):
        assert not sim.step(command * 0.2).comm.any()


def test_packet_loss_is_symmetric_and_at_the_configured_rate() -> None:
    config = replace(EXACT, comm=CommConfig(comm_range=12.0, packet_loss=0.3))
    sim = simulator(config, starts=[(1.0, 1.0, 0.0), (4.0, 3.0, 0.0), (2.0, 4.0, 0.0)], n_robots=3)
    up = []
    for _ in range(400):
        comm = sim.step(np.zeros((3, 2))).comm
        # comm[i] lists the other robots in index order: build the full matrix.
        full = np.zeros((3, 3), dtype=bool)
        for i in range(3):
            full[i, [j for j in range(3) if j != i]] = comm[i]
        np.testing.assert_array_equal(full, full.T)
        up.append(full[np.triu_indices(3, 1)])
    assert 1.0 - np.mean(up) == pytest.approx(0.3, rel=0.15)


# --- peer sensor --------------------------------------------------------------------------


def test_peer_detected_within_range_and_line_of_sight_with_exact_values() -> None:
    starts = [(1.0, 1.0, 0.5), (4.0, 3.0, -1.0)]
    state = simulator(starts=starts).state
    distance = math.hypot(3.0, 2.0)
    assert distance < EXACT.peer.detect_range
    bearing_01 = math.atan2(2.0, 3.0) - 0.5
    bearing_10 = math.remainder(math.atan2(-2.0, -3.0) + 1.0, 2 * math.pi)
    np.testing.assert_allclose(state.peers[0, 0], [1.0, distance, bearing_01, -1.5], atol=1e-9)
    np.testing.assert_allclose(state.peers[1, 0], [1.0, distance, bearing_10, 1.5], atol=1e-9)


def test_peer_not_detected_beyond_detect_range() -> None:
    starts = [(1.0, 1.0, 0.0), (4.0, 5.0, 0.0)]  # 5.0 m... just inside
    assert simulator(starts=starts).state.peers[0, 0, 0] == 1.0
    starts = [(1.0, 1.0, 0.0), (4.1, 5.0, 0.0)]  # 5.06 m
    state = simulator(starts=starts).state
    np.testing.assert_array_equal(state.peers, np.zeros((2, 1, 4)))
    assert state.comm.all()  # the link is independent of the peer sensor


def test_peer_not_detected_through_a_wall() -> None:
    starts = [(4.0, 2.0, 0.0), (6.0, 2.0, 0.0)]  # 2 m apart, wall between
    state = simulator(starts=starts).state
    np.testing.assert_array_equal(state.peers, np.zeros((2, 1, 4)))


def test_peer_slots_skip_the_robot_itself() -> None:
    starts = [(1.0, 1.0, 0.0), (2.0, 1.0, 0.0), (8.0, 1.0, 0.0)]
    state = simulator(starts=starts, n_robots=3).state
    # Robot 0 sees robot 1 (slot 0), not robot 2 (slot 1, other room).
    assert state.peers[0, 0, 0] == 1.0 and state.peers[0, 0, 1] == pytest.approx(1.0)
    assert state.peers[0, 1, 0] == 0.0
    # Robot 1 sees robot 0 in slot 0; robot 2 sees nobody.
    assert state.peers[1, 0, 0] == 1.0 and state.peers[1, 0, 2] == pytest.approx(math.pi)
    assert state.peers[1, 1, 0] == 0.0
    np.testing.assert_array_equal(state.peers[2], np.zeros((2, 4)))


def test_peer_detection_follows_motion() -> None:
    # Robot 1 drives from the other room through the door towards robot 0.
    sim = simulator(starts=[(3.0, 4.9, 0.0), (7.0, 4.9, math.pi)])
    seen = []
    for _ in range(30):
        state = sim.step(np.array([[0.0, 0.0], [0.5, 0.0]]))
        distance = math.hypot(*(state.true_poses[1, :2] - state.true_poses[0, :2]))
        seen.append((distance, state.peers[0, 0, 0] == 1.0))
    for distance, detected in seen:
        assert detected == (distance <= EXACT.peer.detect_range)


# --- starts -------------------------------------------------------------------------------


def test_start_inside_a_wall_is_rejected_naming_its_index() -> None:
    with pytest.raises(ValueError, match=r"start pose 1 .*inside a wall"):
        simulator(starts=[(2.0, 2.0, 0.0), (5.0, 2.0, 0.0)])
    with pytest.raises(ValueError, match=r"start pose 0 .*m from a wall"):
        simulator(starts=[(4.8, 2.0, 0.0), (8.0, 2.0, 0.0)])
    with pytest.raises(ValueError, match="start pose 1"):
        choose_starts(
            two_rooms(), 2, R, np.random.default_rng(0), np.array([[2, 2, 0], [0.05, 3, 0]])
        )


def test_extra_robots_get_free_separated_starts() -> None:
    world = two_rooms()
    for seed in range(5):
        starts = choose_starts(world, 5, R, np.random.default_rng(seed))
        assert starts.shape == (5, 3)
        np.testing.assert_array_equal(starts[:2], world.starts)
        clearance = world.clearance(starts[:, :2])
        # Grid-based: at least radius + 0.3 to the nearest wall cell's centre, so at least
        # that minus half a 0.1 m cell diagonal to the wall itself.
        assert np.all(clearance >= R + 0.3 - 0.1 * math.sqrt(0.5) - 1e-9)
        distances = np.hypot(*(starts[:, None, :2] - starts[None, :, :2]).transpose(2, 0, 1))
        assert np.all(distances[np.triu_indices(5, 1)] >= 2.0)
        assert np.all((starts[:, 2] > -math.pi) & (starts[:, 2] <= math.pi))
        # And they are acceptable as given starts.
        Simulator(
            world, 5, replace(EXACT, starts=tuple(map(tuple, starts))), np.random.default_rng(0)
        )


def test_automatic_starts_stay_in_the_first_starts_region() -> None:
    # A sealed room in the corner of the enclosure: never a start there.
    walls = [
        box(0.0, 0.0, 10.0, 0.1),
        box(0.0, 5.9, 10.0, 6.0),
        box(0.0, 0.0, 0.1, 6.0),
        box(9.9, 0.0, 10.0, 6.0),
        *polyline_walls([(6.0, 0.1), (6.0, 3.0), (9.9, 3.0)], 0.1),
    ]
    world = WorldSpec.from_walls("sealed", walls, [(1.0, 1.0, 0.0)])
    for seed in range(10):
        starts = choose_starts(world, 4, R, np.random.default_rng(seed))
        sealed = (starts[:, 0] > 6.0) & (starts[:, 1] < 3.0)
        assert not sealed.any()


def test_no_room_for_robots_raises() -> None:
    walls = [box(0, 0, 2, 0.1), box(0, 1.9, 2, 2), box(0, 0, 0.1, 2), box(1.9, 0, 2, 2)]
    world = WorldSpec.from_walls("closet", walls, [(1.0, 1.0, 0.0)])
    with pytest.raises(ValueError, match="no room for 2 robots"):
        choose_starts(world, 2, R, np.random.default_rng(0))


def test_n_robots_must_be_positive() -> None:
    with pytest.raises(ValueError, match="n_robots"):
        Simulator(two_rooms(), 0, EXACT, np.random.default_rng(0))


def test_empty_starts_is_rejected_or_means_automatic() -> None:
    try:
        sim = Simulator(two_rooms(), 2, replace(EXACT, starts=()), np.random.default_rng(0))
    except ValueError as error:
        assert "starts" in str(error)  # a clear rejection is fine
        return
    assert sim.starts.shape == (2, 3)


def test_overlapping_given_starts_are_rejected() -> None:
    with pytest.raises(ValueError, match="start pose 1"):
        simulator(starts=[(2.0, 2.0, 0.0), (2.1, 2.0, 0.0)])


def test_automatic_starts_are_reachable_by_the_robot() -> None:
    # Room A (left, 2.4 m wide) is joined to room B only by a 0.2 m slit: too small for a
    # robot of radius 0.2, and A has no room for a second start 2 m from the first.
    walls = [
        box(0.0, 0.0, 8.0, 0.1),
        box(0.0, 2.5, 8.0, 2.6),
        box(0.0, 0.0, 0.1, 2.6),
        box(7.9, 0.0, 8.0, 2.6),
        box(2.5, 0.1, 2.6, 1.2),
        box(2.5, 1.4, 2.6, 2.5),
    ]
    world = WorldSpec.from_walls("slit", walls, [(1.3, 1.3, 0.0)])
    try:
        starts = choose_starts(world, 2, R, np.random.default_rng(0))
    except ValueError:
        return  # "no room" is a correct answer
    assert starts[1, 0] < 2.5  # otherwise it is in room B, unreachable
