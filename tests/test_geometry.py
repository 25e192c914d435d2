"""SE(2) algebra, angle wrapping and the grid/world convention of docs/design.md §2."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrslam_env.geometry import (
    cell_to_world,
    compose,
    inverse,
    pose,
    transform_points,
    world_to_cell,
    wrap_angle,
    wrap_scalar,
)

TOL = 1e-12


def random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    xy = rng.uniform(-20.0, 20.0, (n, 2))
    theta = rng.uniform(-math.pi, math.pi, n)
    return np.column_stack([xy, theta])


def angle_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest absolute difference of two angles (insensitive to the +-pi seam)."""
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


def assert_same_pose(a: np.ndarray, b: np.ndarray, tol: float = 1e-9) -> None:
    np.testing.assert_allclose(a[..., :2], b[..., :2], atol=tol, rtol=0)
    assert np.all(angle_difference(a[..., 2], b[..., 2]) <= tol)


# --- SE(2) algebra -----------------------------------------------------------------------


def test_compose_with_inverse_is_identity_both_ways() -> None:
    a = random_poses(np.random.default_rng(0), 500)
    identity = np.zeros_like(a)
    assert_same_pose(compose(a, inverse(a)), identity)
    assert_same_pose(compose(inverse(a), a), identity)


def test_inverse_is_an_involution() -> None:
    a = random_poses(np.random.default_rng(1), 500)
    assert_same_pose(inverse(inverse(a)), a)


def test_identity_is_neutral() -> None:
    a = random_poses(np.random.default_rng(2), 100)
    identity = np.zeros(3)
    assert_same_pose(compose(identity, a), a, tol=TOL)
    assert_same_pose(compose(a, identity), a, tol=TOL)


def test_compose_is_associative() -> None:
    rng = np.random.default_rng(3)
    a, b, c = (random_poses(rng, 300) for _ in range(3))
    assert_same_pose(compose(compose(a, b), c), compose(a, compose(b, c)))


def test_inverse_of_product_reverses_order() -> None:
    rng = np.random.default_rng(4)
    a, b = random_poses(rng, 300), random_poses(rng, 300)
    assert_same_pose(inverse(compose(a, b)), compose(inverse(b), inverse(a)))


def test_compose_known_values() -> None:
    # world_from_robot: at (1, 2) facing +y; robot_from_sensor: 1 m ahead, facing the robot's
    # left. The sensor sits at (1, 3) facing -x.
    world_from_sensor = compose([1.0, 2.0, math.pi / 2], [1.0, 0.0, math.pi / 2])
    np.testing.assert_allclose(world_from_sensor, [1.0, 3.0, math.pi], atol=TOL)
    np.testing.assert_allclose(inverse([1.0, 0.0, math.pi / 2]), [0.0, 1.0, -math.pi / 2], atol=TOL)


def test_compose_wraps_the_heading() -> None:
    c = compose([0.0, 0.0, 3.0], [0.0, 0.0, 3.0])
    assert -math.pi < c[2] <= math.pi
    assert c[2] == pytest.approx(6.0 - 2 * math.pi, abs=TOL)


def test_compose_broadcasts_one_pose_against_many() -> None:
    rng = np.random.default_rng(5)
    a = random_poses(rng, 1)[0]
    b = random_poses(rng, 50)
    batched = compose(a, b)
    assert batched.shape == (50, 3)
    for k in range(50):
        assert_same_pose(batched[k], compose(a, b[k]), tol=TOL)


def test_transform_points_is_consistent_with_compose() -> None:
    rng = np.random.default_rng(6)
    for a_from_b in random_poses(rng, 50):
        points_in_b = rng.uniform(-10.0, 10.0, (40, 2))
        as_poses = np.column_stack([points_in_b, np.zeros(40)])
        expected = compose(a_from_b, as_poses)[:, :2]
        np.testing.assert_allclose(transform_points(a_from_b, points_in_b), expected, atol=1e-9)


def test_transform_points_matches_the_rotation_formula_and_round_trips() -> None:
    rng = np.random.default_rng(7)
    a_from_b = random_poses(rng, 1)[0]
    p = rng.uniform(-5.0, 5.0, (30, 2))
    c, s = math.cos(a_from_b[2]), math.sin(a_from_b[2])
    expected = np.column_stack(
        [c * p[:, 0] - s * p[:, 1] + a_from_b[0], s * p[:, 0] + c * p[:, 1] + a_from_b[1]]
    )
    mapped = transform_points(a_from_b, p)
    np.testing.assert_allclose(mapped, expected, atol=1e-12)
    np.testing.assert_allclose(transform_points(inverse(a_from_b), mapped), p, atol=1e-9)


def test_transform_points_of_a_composition_is_the_composition_of_maps() -> None:
    rng = np.random.default_rng(8)
    a_from_b, b_from_c = random_poses(rng, 2)
    p = rng.uniform(-5.0, 5.0, (30, 2))
    np.testing.assert_allclose(
        transform_points(compose(a_from_b, b_from_c), p),
        transform_points(a_from_b, transform_points(b_from_c, p)),
        atol=1e-9,
    )


def test_pose_builds_float64_and_wraps() -> None:
    p = pose(1, 2, 3 * math.pi)
    assert p.dtype == np.float64
    assert p.shape == (3,)
    np.testing.assert_allclose(p, [1.0, 2.0, math.pi], atol=1e-12)


# --- angle wrapping ----------------------------------------------------------------------


def test_wrap_angle_range_and_equivalence() -> None:
    rng = np.random.default_rng(9)
    a = np.concatenate([rng.uniform(-100.0, 100.0, 10_000), rng.normal(0.0, 1e-3, 100)])
    w = wrap_angle(a)
    assert np.all(w > -math.pi)
    assert np.all(w <= math.pi)
    # Same direction as the input.
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-9)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)


def test_wrap_angle_keeps_in_range_values_unchanged() -> None:
    # Up to one rounding of ``a + pi`` (wrap_angle is not bit-exact on in-range input).
    a = np.random.default_rng(10).uniform(-3.14, 3.14, 1000)
    np.testing.assert_allclose(wrap_angle(a), a, rtol=0, atol=1e-15)
    assert [wrap_scalar(float(v)) for v in a] == a.tolist()


@pytest.mark.parametrize("angle", [math.pi, -math.pi, 3 * math.pi, -3 * math.pi])
def test_wrap_angle_maps_both_seams_to_plus_pi(angle: float) -> None:
    assert float(wrap_angle(angle)) == pytest.approx(math.pi, abs=1e-12)
    assert wrap_scalar(angle) == pytest.approx(math.pi, abs=1e-12)


def test_wrap_angle_exact_pi_values() -> None:
    # +pi is kept exactly, -pi becomes exactly +pi: no value of -pi ever comes out.
    assert float(wrap_angle(math.pi)) == math.pi
    assert float(wrap_angle(-math.pi)) == math.pi
    assert wrap_scalar(math.pi) == math.pi
    assert wrap_scalar(-math.pi) == math.pi
    assert float(wrap_angle(0.0)) == 0.0
    assert float(wrap_angle(2 * math.pi)) == 0.0


def test_wrap_angle_preserves_shape() -> None:
    a = np.zeros((3, 4, 2))
    assert wrap_angle(a).shape == (3, 4, 2)
    assert np.ndim(wrap_angle(1.0)) == 0


def test_wrap_scalar_agrees_with_wrap_angle() -> None:
    rng = np.random.default_rng(11)
    a = np.concatenate(
        [
            rng.uniform(-50.0, 50.0, 5000),
            math.pi + rng.normal(0.0, 1e-9, 200),
            -math.pi + rng.normal(0.0, 1e-9, 200),
        ]
    )
    vector = wrap_angle(a)
    scalar = np.array([wrap_scalar(float(v)) for v in a])
    assert np.all(scalar > -math.pi)
    assert np.all(scalar <= math.pi)
    assert isinstance(wrap_scalar(1.0), float)
    # Equal up to rounding; near the seam the two may land on opposite sides of it only if
    # the representation differs by rounding, which is still the same direction.
    assert np.all(angle_difference(vector, scalar) <= 1e-12)
    np.testing.assert_allclose(
        scalar[np.abs(vector) < 3.1], vector[np.abs(vector) < 3.1], atol=1e-12
    )


# --- grid convention ---------------------------------------------------------------------


def test_cell_centre_follows_design_convention() -> None:
    origin = (-1.5, 2.0)
    res = 0.25
    cells = np.array([[0, 0], [0, 1], [1, 0], [3, 7]])  # (iy, ix)
    centres = cell_to_world(cells, origin, res)
    expected = np.array(
        [
            [-1.5 + 0.125, 2.0 + 0.125],
            [-1.5 + 0.375, 2.0 + 0.125],  # ix = column = x
            [-1.5 + 0.125, 2.0 + 0.375],  # iy = row = y, row 0 lowest y
            [-1.5 + 7.5 * 0.25, 2.0 + 3.5 * 0.25],
        ]
    )
    np.testing.assert_allclose(centres, expected, atol=1e-12)


def test_world_to_cell_row_zero_is_lowest_y() -> None:
    origin = (0.0, 0.0)
    low = world_to_cell([0.05, 0.01], origin, 0.1)
    high = world_to_cell([0.05, 0.95], origin, 0.1)
    np.testing.assert_array_equal(low, [0, 0])
    np.testing.assert_array_equal(high, [9, 0])
    # Points left of / below the origin get negative (unclipped) indices.
    np.testing.assert_array_equal(world_to_cell([-0.01, -0.25], origin, 0.1), [-3, -1])
    assert world_to_cell([0.05, 0.01], origin, 0.1).dtype == np.int64


def test_world_to_cell_cell_to_world_round_trip() -> None:
    rng = np.random.default_rng(12)
    for _ in range(20):
        origin = rng.uniform(-10.0, 10.0, 2)
        res = rng.uniform(0.01, 1.0)
        cells = rng.integers(-500, 500, (200, 2))
        back = world_to_cell(cell_to_world(cells, origin, res), origin, res)
        np.testing.assert_array_equal(back, cells)


def test_points_map_to_the_cell_whose_square_contains_them() -> None:
    rng = np.random.default_rng(13)
    origin = np.array([0.3, -0.7])
    res = 0.05
    points = rng.uniform(-3.0, 3.0, (2000, 2))
    cells = world_to_cell(points, origin, res)
    centres = cell_to_world(cells, origin, res)
    assert np.all(np.abs(points - centres) <= res / 2 + 1e-12)


def test_world_to_cell_shapes() -> None:
    pts = np.zeros((4, 5, 2))
    assert world_to_cell(pts, (0.0, 0.0), 1.0).shape == (4, 5, 2)
    assert cell_to_world(np.zeros((4, 5, 2), dtype=np.int64), (0.0, 0.0), 1.0).shape == (4, 5, 2)
