"""The exact lidar kernel (mrslam_env.sim.lidar) against a slow, obvious reference.

The reference intersects every beam with every segment and every disc (no angular pruning)
with textbook formulas: the 2x2 linear system of ray and segment by Cramer's rule, and the
ray-circle quadratic.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrslam_env.sim.lidar import beam_angles, cast_scan, line_of_sight

NO_DISCS = np.zeros((0, 3))


def reference_scan(
    x: float,
    y: float,
    heading: float,
    n_beams: int,
    max_range: float,
    segments: np.ndarray,
    discs: np.ndarray,
) -> np.ndarray:
    angles = heading + (-math.pi + np.arange(n_beams) * (2.0 * math.pi / n_beams))
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]  # (N, 1)
    best = np.full(n_beams, float(max_range))
    if len(segments):
        # Solve (x, y) + t d = a + u (b - a) for (t, u), all beams x all segments.
        ax, ay = segments[None, :, 0] - x, segments[None, :, 1] - y
        ex = (segments[:, 2] - segments[:, 0])[None]
        ey = (segments[:, 3] - segments[:, 1])[None]
        det = ex * dy - ey * dx
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (ex * ay - ey * ax) / det
            u = (dx * ay - dy * ax) / det
        hit = (np.abs(det) > 1e-14) & (t > 0.0) & (u >= 0.0) & (u <= 1.0)
        best = np.minimum(best, np.where(hit, t, np.inf).min(axis=1))
    for cx, cy, r in discs:
        px, py = x - cx, y - cy
        c = px * px + py * py - r * r
        if c <= 0.0:  # the sensor is inside: that is the scanning robot itself
            continue
        b = dx[:, 0] * px + dy[:, 0] * py
        discriminant = b * b - c
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(discriminant)
        best = np.minimum(best, np.where((discriminant >= 0.0) & (t > 0.0), t, np.inf))
    return best


def random_scene(rng: np.random.Generator, with_near_segments: bool) -> tuple:
    n_segments = int(rng.integers(0, 40))
    segments = rng.uniform(-5.0, 5.0, (n_segments, 4))
    x, y = rng.uniform(-5.0, 5.0, 2)
    heading = float(rng.uniform(-4.0, 4.0))
    if with_near_segments:
        # A few segments passing close to the sensor (wide angular spans, wrap-around).
        for j in range(min(n_segments, 3)):
            middle = np.array([x, y]) + rng.normal(0.0, 0.05, 2)
            direction = rng.normal(size=2)
            segments[j] = np.r_[middle - direction, middle + direction]
    n_discs = int(rng.integers(0, 5))
    discs = np.column_stack([rng.uniform(-5.0, 5.0, (n_discs, 2)), rng.uniform(0.05, 1.5, n_discs)])
    if rng.random() < 0.5:  # the scanning robot's own disc
        discs = np.vstack([discs, [x, y, 0.2]])
    max_range = float(rng.uniform(0.5, 10.0))
    return float(x), float(y), heading, max_range, segments, discs


@pytest.mark.parametrize("n_beams", [4, 90, 360, 361])
@pytest.mark.parametrize("with_near_segments", [False, True])
def test_cast_scan_matches_reference_on_random_scenes(
    n_beams: int, with_near_segments: bool
) -> None:
    rng = np.random.default_rng(1000 * n_beams + with_near_segments)
    for _ in range(150):
        x, y, heading, max_range, segments, discs = random_scene(rng, with_near_segments)
        got = cast_scan(x, y, heading, n_beams, max_range, segments, discs)
        expected = reference_scan(x, y, heading, n_beams, max_range, segments, discs)
        assert got.shape == (n_beams,)
        assert got.dtype == np.float64
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
        assert np.all(got > 0.0)
        assert np.all(got <= max_range)


def test_cast_scan_matches_reference_in_a_room_of_boxes() -> None:
    # Axis-aligned walls and a pose on the same lattice: many beams along edges and corners.
    from mrslam_env.sim.world import WorldSpec, box

    world = WorldSpec.from_walls(
        "room",
        [
            box(0, 0, 6, 0.1),
            box(0, 3.9, 6, 4),
            box(0, 0, 0.1, 4),
            box(5.9, 0, 6, 4),
            box(2, 1, 3, 2),
        ],
        [(1.0, 1.0, 0.0)],
    )
    rng = np.random.default_rng(7)
    for _ in range(50):
        x, y = rng.uniform(0.4, 5.6), rng.uniform(0.4, 3.6)
        if world.clearance([[x, y]])[0] < 0.2:
            continue
        heading = float(rng.choice([0.0, math.pi / 2, math.pi, rng.uniform(-math.pi, math.pi)]))
        got = cast_scan(x, y, heading, 360, 8.0, world.segments, NO_DISCS)
        expected = reference_scan(x, y, heading, 360, 8.0, world.segments, NO_DISCS)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
        assert np.all(got < 8.0)  # a closed room: every beam hits


def test_beam_angles_convention() -> None:
    np.testing.assert_allclose(beam_angles(4), [-math.pi, -math.pi / 2, 0.0, math.pi / 2])
    angles = beam_angles(360)
    assert angles.shape == (360,)
    assert angles[0] == -math.pi
    np.testing.assert_allclose(np.diff(angles), 2 * math.pi / 360)


@pytest.mark.parametrize("n_beams", [4, 8, 360])
def test_beam_direction_convention(n_beams: int) -> None:
    # A wall 3 m ahead (+x) and another 2 m to the left (+y); heading 0.
    segments = np.array([[3.0, -10.0, 3.0, 10.0], [-10.0, 2.0, 10.0, 2.0]])
    ranges = cast_scan(0.0, 0.0, 0.0, n_beams, 20.0, segments, NO_DISCS)
    assert ranges[n_beams // 2] == pytest.approx(3.0, abs=1e-12)  # beam N/2: straight ahead
    assert ranges[3 * n_beams // 4] == pytest.approx(2.0, abs=1e-12)  # beam 3N/4: to the left
    assert ranges[0] == 20.0  # beam 0 points backwards (-x)
    assert ranges[n_beams // 4] == 20.0  # beam N/4 points right (-y)


def test_beam_directions_rotate_with_heading() -> None:
    segments = np.array([[3.0, -10.0, 3.0, 10.0]])  # wall at x = 3
    # Facing +y, the wall at +x is on the right: beam N/4.
    ranges = cast_scan(0.0, 0.0, math.pi / 2, 8, 20.0, segments, NO_DISCS)
    assert ranges[2] == pytest.approx(3.0, abs=1e-12)
    assert ranges[4] == 20.0
    # Facing -x the wall is behind: beam 0.
    ranges = cast_scan(0.0, 0.0, math.pi, 8, 20.0, segments, NO_DISCS)
    assert ranges[0] == pytest.approx(3.0, abs=1e-12)


def test_nothing_in_range_returns_max_range() -> None:
    segments = np.array([[5.0, -1.0, 5.0, 1.0], [-6.0, -6.0, 6.0, -6.0]])
    discs = np.array([[0.0, 7.0, 1.0]])
    ranges = cast_scan(0.0, 0.0, 0.3, 90, 4.0, segments, discs)
    np.testing.assert_array_equal(ranges, np.full(90, 4.0))
    # Empty scene.
    np.testing.assert_array_equal(
        cast_scan(0.0, 0.0, 0.0, 16, 2.5, np.zeros((0, 4)), NO_DISCS), np.full(16, 2.5)
    )


def test_segment_beyond_range_ignored_but_one_crossing_into_range_counts() -> None:
    max_range = 4.0
    # Far segment: both end points and every point beyond range.
    far = np.array([[5.0, -2.0, 5.0, 2.0]])
    assert np.all(cast_scan(0.0, 0.0, 0.0, 360, max_range, far, NO_DISCS) == max_range)
    # A long segment whose end points are both out of range but whose middle is at 3 m.
    crossing = np.array([[3.0, -10.0, 3.0, 10.0]])
    ranges = cast_scan(0.0, 0.0, 0.0, 360, max_range, crossing, NO_DISCS)
    angles = beam_angles(360)
    visible = np.abs(angles) < math.acos(3.0 / max_range) - 1e-6
    np.testing.assert_allclose(ranges[visible], 3.0 / np.cos(angles[visible]), atol=1e-12)
    assert np.all(ranges[~visible] == max_range)
    # A segment starting in range and running out of range.
    outward = np.array([[3.0, 0.0, 3.0, 10.0]])
    ranges = cast_scan(0.0, 0.0, 0.0, 360, max_range, outward, NO_DISCS)
    assert ranges[180] == pytest.approx(3.0, abs=1e-12)
    assert ranges[181] == pytest.approx(3.0 / math.cos(math.radians(1)), abs=1e-12)
    assert ranges[179] == max_range


def test_scanning_robots_own_disc_is_ignored_but_others_are_seen() -> None:
    discs = np.array([[0.0, 0.0, 0.2], [2.0, 0.0, 0.2]])
    ranges = cast_scan(0.0, 0.0, 0.0, 360, 8.0, np.zeros((0, 4)), discs)
    assert ranges[180] == pytest.approx(1.8, abs=1e-12)
    assert ranges[0] == 8.0
    # Width of the other robot: beams within asin(0.2 / 2) of straight ahead hit it.
    hit = ranges < 8.0
    half_width = math.degrees(math.asin(0.1))
    expected = np.abs(np.arange(360) - 180) <= half_width
    np.testing.assert_array_equal(hit, expected)


def test_disc_hit_distances() -> None:
    # Disc of radius 1 at (5, 0): the beam at angle a hits at the near root of the quadratic.
    discs = np.array([[5.0, 0.0, 1.0]])
    ranges = cast_scan(0.0, 0.0, 0.0, 360, 10.0, np.zeros((0, 4)), discs)
    for offset in range(-11, 12):
        a = math.radians(offset)
        b = 5.0 * math.cos(a)
        expected = b - math.sqrt(b * b - 24.0) if b * b >= 24.0 else 10.0
        assert ranges[180 + offset] == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("n_beams", [4, 90, 360, 361])
def test_corner_hit_exactly_at_segment_end_points(n_beams: int) -> None:
    """A beam through the apex of a V (two segments sharing an end point) hits the apex."""
    rng = np.random.default_rng(n_beams)
    for _ in range(500):
        x, y = rng.uniform(-5.0, 5.0, 2)
        heading = rng.uniform(-4.0, 4.0)
        i = int(rng.integers(n_beams))
        a = heading - math.pi + i * 2 * math.pi / n_beams
        d = np.array([math.cos(a), math.sin(a)])
        normal = np.array([-d[1], d[0]])
        t = rng.uniform(0.5, 7.0)
        apex = np.array([x, y]) + t * d
        left = apex + d * rng.uniform(0.1, 1.0) + normal * rng.uniform(0.1, 1.0)
        right = apex + d * rng.uniform(0.1, 1.0) - normal * rng.uniform(0.1, 1.0)
        segments = np.array([[*apex, *left], [*right, *apex]])
        ranges = cast_scan(x, y, heading, n_beams, 8.0, segments, NO_DISCS)
        assert ranges[i] == pytest.approx(t, abs=1e-9)


def test_corner_of_an_axis_aligned_box() -> None:
    # The beam at 45 degrees from (0, 0) meets the box corner (1, 1) exactly.
    segments = np.array([[1.0, 1.0, 2.0, 1.0], [1.0, 2.0, 1.0, 1.0]])
    ranges = cast_scan(0.0, 0.0, 0.0, 8, 8.0, segments, NO_DISCS)
    assert ranges[5] == pytest.approx(math.sqrt(2.0), abs=1e-12)
    # The same corner with only one of the two edges present.
    for one in segments:
        ranges = cast_scan(0.0, 0.0, 0.0, 8, 8.0, one[None], NO_DISCS)
        assert ranges[5] == pytest.approx(math.sqrt(2.0), abs=1e-12)


def test_nearest_of_several_hits_wins() -> None:
    segments = np.array([[4.0, -1.0, 4.0, 1.0], [2.0, -1.0, 2.0, 1.0], [3.0, -1.0, 3.0, 1.0]])
    discs = np.array([[2.9, 0.0, 0.5]])
    ranges = cast_scan(0.0, 0.0, 0.0, 4, 8.0, segments, discs)
    assert ranges[2] == pytest.approx(2.0, abs=1e-12)
    discs = np.array([[1.0, 0.0, 0.5]])
    ranges = cast_scan(0.0, 0.0, 0.0, 4, 8.0, segments, discs)
    assert ranges[2] == pytest.approx(0.5, abs=1e-12)


def test_segments_behind_the_sensor_are_not_hit_forwards() -> None:
    segments = np.array([[-2.0, -1.0, -2.0, 1.0]])
    ranges = cast_scan(0.0, 0.0, 0.0, 4, 8.0, segments, NO_DISCS)
    np.testing.assert_allclose(ranges, [2.0, 8.0, 8.0, 8.0], atol=1e-12)


# --- line of sight -----------------------------------------------------------------------


def test_line_of_sight_cases() -> None:
    wall = np.array([[1.0, -1.0, 1.0, 1.0]])
    assert not line_of_sight(0.0, 0.0, 2.0, 0.0, wall)
    assert not line_of_sight(2.0, 0.0, 0.0, 0.0, wall)  # symmetric
    assert line_of_sight(0.0, 0.0, 0.5, 0.0, wall)  # stops short
    assert line_of_sight(0.0, 2.0, 2.0, 2.0, wall)  # passes beyond the end
    assert line_of_sight(0.0, -0.5, 0.0, 0.5, wall)  # parallel
    assert line_of_sight(0.0, 0.0, 2.0, 0.0, np.zeros((0, 4)))
    # Crossing through the wall's end point counts as blocked.
    assert not line_of_sight(0.0, 0.0, 2.0, 2.0, wall)


def test_line_of_sight_agrees_with_the_lidar() -> None:
    rng = np.random.default_rng(11)
    for _ in range(300):
        segments = rng.uniform(-5.0, 5.0, (int(rng.integers(1, 10)), 4))
        p, q = rng.uniform(-5.0, 5.0, (2, 2))
        distance = float(np.hypot(*(q - p)))
        heading = math.atan2(q[1] - p[1], q[0] - p[0]) + math.pi  # beam 0 points at q
        first_hit = cast_scan(p[0], p[1], heading, 4, 100.0, segments, NO_DISCS)[0]
        if abs(first_hit - distance) < 1e-9:
            continue  # q on a wall: ambiguous
        assert line_of_sight(p[0], p[1], q[0], q[1], segments) == (first_hit > distance)
