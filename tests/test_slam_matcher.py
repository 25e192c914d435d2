"""Scan-to-map matching (mrslam_env.slam.matcher, mrslam_env.slam.scan).

Oracles: scan normals against numpy's eigen-decomposition; bicubic interpolation against a
quadratic it must reproduce exactly and against finite differences; the correlative search
against a brute-force loop. Invariants on real scans (cast by the simulator's lidar in a
world): known pose perturbations are recovered, and in a featureless corridor the match
does not move along the corridor.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from slam_worlds import NO_DISCS, corridor_world, noisy_scan

from mrslam_env.geometry import compose, wrap_scalar
from mrslam_env.sim.lidar import cast_scan
from mrslam_env.sim.world import WorldSpec, box
from mrslam_env.slam.config import MatcherConfig
from mrslam_env.slam.grid import OccupancyGrid
from mrslam_env.slam.matcher import (
    HUBER,
    MIN_RIDGE_VALUE,
    _check_finite,
    _determinant,
    _normal_equations,
    _solve,
    correlative_search,
    interpolate,
    match_scan,
    point_sectors,
    refine_pose,
    translational_condition,
)
from mrslam_env.slam.scan import (
    NORMAL_HALF_WIDTH,
    NORMAL_MAX_GAP,
    NORMAL_MAX_HALF_WIDTH,
    NORMAL_MIN_SPAN,
    scan_normals,
    scan_points,
)


def room_world() -> WorldSpec:
    """An L-shaped room with furniture: every direction is constrained."""
    t = 0.1
    walls = [
        box(-t, -t, 8.0 + t, 0.0),
        box(-t, 5.0, 4.0 + t, 5.0 + t),
        box(4.0, 3.0, 8.0 + t, 3.0 + t),
        box(-t, -t, 0.0, 5.0 + t),
        box(8.0, -t, 8.0 + t, 3.0 + t),
        box(4.0, 3.0, 4.0 + t, 5.0 + t),
        box(1.0, 1.0, 1.6, 1.5),
        box(6.0, 0.8, 6.3, 1.9),
        box(2.5, 3.6, 3.2, 4.0),
    ]
    return WorldSpec.from_walls("room", walls, [[2.0, 2.0, 0.0]])


def mapped(world: WorldSpec, poses: list[np.ndarray], rng: np.random.Generator) -> OccupancyGrid:
    """A grid built from scans at known poses (world frame = map frame here)."""
    grid = OccupancyGrid()
    for pose in poses:
        for _ in range(2):
            grid.integrate_scan(pose, noisy_scan(world, pose, rng), 8.0)
    return grid


# --- the scan side --------------------------------------------------------------------------


def reference_normals(ranges: np.ndarray) -> np.ndarray:
    n = len(ranges)
    angles = -np.pi + np.arange(n) * (2 * np.pi / n)
    points = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])
    valid = (ranges >= 0.05) & (ranges < 8.0)
    normals = np.zeros((n, 2))
    for i in np.flatnonzero(valid):
        spacing = ranges[i] * (2 * np.pi / n)
        limit = NORMAL_MAX_GAP + max(2.0 * spacing, NORMAL_MIN_SPAN / 2)
        # As many beams either side as span NORMAL_MIN_SPAN, at least NORMAL_HALF_WIDTH.
        reach = NORMAL_HALF_WIDTH
        while reach < NORMAL_MAX_HALF_WIDTH and 2 * reach * spacing < NORMAL_MIN_SPAN:
            reach += 1
        members = [
            points[j]
            for j in ((i + k) % n for k in range(-reach, reach + 1))
            if valid[j] and np.linalg.norm(points[j] - points[i]) <= limit
        ]
        if len(members) < 3:
            continue
        eigenvalues, eigenvectors = np.linalg.eigh(np.cov(np.array(members).T, bias=True))
        if eigenvalues[1] <= 0 or eigenvalues[0] > eigenvalues[1] / 16:
            continue
        normal = eigenvectors[:, 0]
        normals[i] = -normal if normal @ points[i] > 0 else normal
    return normals


def test_scan_points_and_normals() -> None:
    rng = np.random.default_rng(0)
    world = room_world()
    pose = np.array([2.0, 2.0, 0.3])
    ranges = noisy_scan(world, pose, rng)
    ranges[::37] = 8.0
    points = scan_points(ranges, 8.0, 0.05)
    valid = (ranges >= 0.05) & (ranges < 8.0)
    angles = -np.pi + np.arange(360) * (2 * np.pi / 360)
    np.testing.assert_allclose(points[:, 0], (ranges * np.cos(angles))[valid])
    np.testing.assert_allclose(points[:, 1], (ranges * np.sin(angles))[valid])
    normals = scan_normals(ranges, 8.0, 0.05)
    expected = reference_normals(ranges)
    # Same normals (up to rounding) wherever both define one, and mostly defined.
    both = np.any(normals != 0, axis=1) & np.any(expected != 0, axis=1)
    assert both.sum() > 250
    np.testing.assert_allclose(normals[both], expected[both], atol=1e-6)
    assert np.array_equal(np.any(normals != 0, axis=1), np.any(expected != 0, axis=1))
    # Facing the sensor, unit length.
    assert np.all(np.einsum("ij,ij->i", normals[valid], points) <= 0)
    np.testing.assert_allclose(np.linalg.norm(normals[both], axis=1), 1.0)


def test_normals_of_a_wall_are_its_normal() -> None:
    world = room_world()
    ranges = cast_scan(2.0, 2.0, 0.0, 360, 8.0, world.segments, NO_DISCS)
    normals = scan_normals(ranges, 8.0, 0.05)
    # Beam 90 points at -90°: straight down onto the wall y = 0, whose normal faces +y.
    np.testing.assert_allclose(normals[90], [0.0, 1.0], atol=1e-9)
    # Beam 0 points at -180°: onto the wall x = 0, facing +x.
    np.testing.assert_allclose(normals[0], [1.0, 0.0], atol=1e-9)


def test_normals_of_a_rasterised_diagonal_wall_follow_the_wall_not_its_steps() -> None:
    # A 45° wall drawn as 5 cm steps (a wall of a map built into a world), 0.32 m from
    # the sensor. Five beams span 2 cm there: they fit single steps, 45° off the wall.
    # Fitted over NORMAL_MIN_SPAN of surface, the normals are the wall's.
    steps = [box(0.05 * i, 0.05 * i + 0.45, 0.05 * i + 0.1, 0.05 * i + 0.5) for i in range(-40, 41)]
    world = WorldSpec.from_walls("steps", steps, [[0.0, 0.0, 0.0]])
    ranges = cast_scan(0.0, 0.0, 0.0, 360, 8.0, world.segments, NO_DISCS)
    near = ranges < 1.0
    wall_normal = np.array([1.0, -1.0]) / math.sqrt(2.0)
    for span, median_max, defined_min in ((0.0, None, None), (NORMAL_MIN_SPAN, 2.0, 1.0)):
        normals = scan_normals(ranges, 8.0, 0.05, min_span=span)[near]
        defined = np.any(normals != 0, axis=1)
        off = np.degrees(np.arccos(np.clip(normals[defined] @ wall_normal, -1.0, 1.0)))
        if median_max is None:
            assert np.median(off) > 30.0  # the steps' faces
        else:
            assert defined.mean() >= defined_min
            assert np.median(off) < median_max
            assert np.percentile(off, 90) < 5.0


# --- interpolation ---------------------------------------------------------------------------


def test_bicubic_interpolation_reproduces_quadratics_and_has_the_right_gradient() -> None:
    rows, cols = 20, 30
    iy, ix = np.mgrid[0:rows, 0:cols].astype(np.float64)

    def quadratic(x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray | float:
        return 1.0 + 0.5 * x - 0.25 * y + 0.03 * x * x - 0.02 * x * y + 0.04 * y * y

    fields = quadratic(ix, iy)[None].astype(np.float32) / 8.0
    rng = np.random.default_rng(1)
    for gx, gy in rng.uniform([1.0, 1.0], [cols - 3.0, rows - 3.0], (200, 2)):
        value, d_gx, d_gy = interpolate(fields, 0, 8.0, gx, gy)
        assert value == pytest.approx(quadratic(gx, gy), rel=1e-5)
        h = 1e-5
        right, left = (
            interpolate(fields, 0, 8.0, gx + h, gy),
            interpolate(fields, 0, 8.0, gx - h, gy),
        )
        up, down = interpolate(fields, 0, 8.0, gx, gy + h), interpolate(fields, 0, 8.0, gx, gy - h)
        numeric_x = (right[0] - left[0]) / (2 * h)
        numeric_y = (up[0] - down[0]) / (2 * h)
        assert d_gx == pytest.approx(numeric_x, rel=1e-4, abs=1e-6)
        assert d_gy == pytest.approx(numeric_y, rel=1e-4, abs=1e-6)
    # Exact at the samples, zero where the stencil leaves the grid.
    at_sample = interpolate(fields, 0, 8.0, 5.0, 7.0)[0]
    assert at_sample == pytest.approx(quadratic(5.0, 7.0), rel=1e-6)
    assert interpolate(fields, 0, 8.0, 0.5, 5.0) == (0.0, 0.0, 0.0)
    assert interpolate(fields, 0, 8.0, 5.0, rows - 2.0) == (0.0, 0.0, 0.0)


# --- the correlative search -------------------------------------------------------------------


def reference_search(
    fields, scale, origin, resolution, points, sectors, pose, half_angle, angle_step,
    half_cells, step_cells, prior, inverse_variance, weight,
):  # fmt: skip
    """Every candidate scored with numpy, one at a time; the first best wins."""
    best = (-math.inf, None)
    k_max = int(half_angle / angle_step + 1e-9)
    j_max = half_cells // step_cells
    for k in range(-k_max, k_max + 1):
        theta = pose[2] + k * angle_step
        rotated = points @ np.array(
            [[math.cos(theta), math.sin(theta)], [-math.sin(theta), math.cos(theta)]]
        )
        for jy in range(-j_max, j_max + 1):
            for jx in range(-j_max, j_max + 1):
                x = pose[0] + jx * step_cells * resolution
                y = pose[1] + jy * step_cells * resolution
                cells_x = np.floor((rotated[:, 0] + pose[0] - origin[0]) / resolution).astype(int)
                cells_y = np.floor((rotated[:, 1] + pose[1] - origin[1]) / resolution).astype(int)
                values = fields[
                    sectors, cells_y + jy * step_cells, cells_x + jx * step_cells
                ].astype(np.float64)
                score = np.mean(np.minimum(values * scale, 1.0))
                d_theta = wrap_scalar(theta - prior[2])
                score -= weight * (
                    (x - prior[0]) ** 2 * inverse_variance[0]
                    + (y - prior[1]) ** 2 * inverse_variance[1]
                    + d_theta**2 * inverse_variance[2]
                )
                if score > best[0] + 1e-12:
                    best = (score, (x, y, theta))
    return best


def test_correlative_search_matches_brute_force() -> None:
    rng = np.random.default_rng(2)
    world = room_world()
    grid = mapped(world, [np.array([2.0, 2.0, 0.0]), np.array([6.5, 1.5, 2.0])], rng)
    for trial in range(4):
        truth = np.array([2.5 + 0.3 * trial, 2.0, 0.2 * trial])
        ranges = noisy_scan(world, truth, rng)
        points = scan_points(ranges, 8.0, 0.05)
        normals = scan_normals(ranges, 8.0, 0.05)[(ranges >= 0.05) & (ranges < 8.0)]
        sectors = point_sectors(points, normals, truth[2])
        start = truth + np.array([0.07, -0.04, 0.05])
        inverse_variance = np.array([100.0, 100.0, 50.0])
        expected_score, expected_pose = reference_search(
            grid.fine_fields, grid.fine_scale, grid.origin, grid.resolution, points, sectors,
            start, 0.08, 0.02, 3, 1, start, inverse_variance, 0.01,
        )  # fmt: skip
        x, y, theta, score = correlative_search(
            grid.fine_fields, grid.fine_scale, *grid.origin, grid.resolution, points, sectors,
            1, *start, 0.08, 0.02, 3, 1, start, inverse_variance, 0.01,
        )  # fmt: skip
        assert score == pytest.approx(expected_score, abs=1e-9)
        np.testing.assert_allclose([x, y, theta], expected_pose, atol=1e-12)


# --- refinement and the whole match ------------------------------------------------------------


def test_refinement_converges_to_the_true_pose() -> None:
    rng = np.random.default_rng(3)
    world = room_world()
    grid = mapped(world, [np.array([2.0, 2.0, 0.0]), np.array([6.0, 1.5, 1.0])], rng)
    truth = np.array([3.1, 1.9, 0.4])
    ranges = noisy_scan(world, truth, rng)
    valid = (ranges >= 0.05) & (ranges < 8.0)
    points = scan_points(ranges, 8.0, 0.05)
    normals = scan_normals(ranges, 8.0, 0.05)[valid]
    for offset in ([0.03, -0.02, 0.02], [-0.04, 0.0, -0.015], [0.0, 0.04, 0.0]):
        start = truth + offset
        x, y, theta, score, information = refine_pose(
            grid.fine_fields, grid.fine_scale, *grid.origin, grid.resolution, 0.05, points,
            normals, point_sectors(points, normals, start[2]), *start, start, np.zeros((3, 3)),
            0.02, 20,
        )  # fmt: skip
        assert math.hypot(x - truth[0], y - truth[1]) < 0.005
        assert abs(theta - truth[2]) < 0.002
        assert score > 0.6
        assert np.all(np.linalg.eigvalsh(information) > 0)


def test_normal_equations_match_a_slow_reference() -> None:
    rng = np.random.default_rng(9)
    world = room_world()
    grid = mapped(world, [np.array([2.0, 2.0, 0.0])], rng)
    truth = np.array([2.3, 2.1, 0.2])
    ranges = noisy_scan(world, truth, rng)
    valid = (ranges >= 0.05) & (ranges < 8.0)
    points = scan_points(ranges, 8.0, 0.05)
    normals = scan_normals(ranges, 8.0, 0.05)[valid]
    sectors = point_sectors(points, normals, truth[2])
    pose = truth + np.array([0.02, -0.01, 0.01])
    hessian, gradient = np.zeros((3, 3)), np.zeros(3)
    score = _normal_equations(
        grid.fine_fields, grid.fine_scale, *grid.origin, grid.resolution, 0.05, points,
        normals, sectors, *pose, hessian, gradient,
    )  # fmt: skip
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rotation = np.array([[c, -s], [s, c]])
    expected_h, expected_g, values = np.zeros((3, 3)), np.zeros(3), []
    for point, normal, sector in zip(points, normals, sectors, strict=True):
        world_point = rotation @ point + pose[:2]
        grid_point = (world_point - grid.origin) / grid.resolution - 0.5
        value, d_gx, d_gy = interpolate(grid.fine_fields, sector, grid.fine_scale, *grid_point)
        values.append(min(value, 1.0))
        if value < MIN_RIDGE_VALUE or not normal.any():
            continue
        n = rotation @ normal
        distance = -(0.05**2) * (np.array([d_gx, d_gy]) @ n) / (grid.resolution * value)
        weight = min(1.0, HUBER / abs(distance))
        lever = np.array([[0.0, -1.0], [1.0, 0.0]]) @ rotation @ point  # d(R p)/d theta
        jacobian = np.array([n[0], n[1], n @ lever])
        expected_h += weight * np.outer(jacobian, jacobian)
        expected_g += weight * jacobian * distance
    assert score == pytest.approx(np.mean(values), abs=1e-12)
    np.testing.assert_allclose(hessian, expected_h, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(gradient, expected_g, rtol=1e-9, atol=1e-12)
    assert np.abs(gradient).max() > 0.01  # the 2 cm / 0.01 rad offset is seen


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_match_recovers_known_perturbations(seed: int) -> None:
    rng = np.random.default_rng(seed)
    world = room_world()
    grid = mapped(world, [np.array([2.0, 2.0, 0.0]), np.array([6.5, 1.5, 2.5])], rng)
    config = MatcherConfig()
    for _ in range(6):
        truth = np.array([rng.uniform(1.5, 3.5), rng.uniform(1.8, 2.8), rng.uniform(-np.pi, np.pi)])
        # A few cm and a few degrees, as after a step of odometry.
        perturbation = np.array([*rng.uniform(-0.06, 0.06, 2), rng.uniform(-0.08, 0.08)])
        predicted = compose(truth, perturbation)
        result = match_scan(grid, noisy_scan(world, truth, rng), 8.0, predicted, 0.08, 0.1, config)
        assert result.accepted and result.reason == "ok", result.reason
        assert math.hypot(*(result.pose[:2] - truth[:2])) < 0.01
        assert abs(wrap_scalar(result.pose[2] - truth[2])) < math.radians(0.3)
        assert result.score > 0.6 and result.condition > 0.2 and result.n_points > 300
        covariance = result.covariance
        assert np.all(np.linalg.eigvalsh(covariance) > 0)
        assert math.sqrt(covariance[0, 0]) < 0.01  # the match is far more certain than odometry


def test_poor_matches_fall_back_to_odometry() -> None:
    rng = np.random.default_rng(7)
    world = room_world()
    grid = mapped(world, [np.array([2.0, 2.0, 0.0])], rng)
    config = MatcherConfig()
    predicted = np.array([2.05, 2.0, 0.02])
    # Few beams: only 20 returns.
    sparse = noisy_scan(world, np.array([2.0, 2.0, 0.0]), rng)
    sparse[np.arange(360) % 18 != 0] = 8.0
    result = match_scan(grid, sparse, 8.0, predicted, 0.05, 0.02, config)
    assert not result.accepted and result.reason == "few points"
    np.testing.assert_array_equal(result.pose, predicted)
    # A scan from elsewhere (the other end of the L, facing away): nothing lines up.
    elsewhere = noisy_scan(world, np.array([7.0, 1.5, 1.0]), rng)
    result = match_scan(grid, elsewhere, 8.0, predicted, 0.05, 0.02, config)
    assert not result.accepted and result.reason == "low score"
    np.testing.assert_array_equal(result.pose, predicted)
    assert result.score < config.min_score


def test_degenerate_corridor_keeps_odometry_along_the_corridor() -> None:
    rng = np.random.default_rng(8)
    world = corridor_world()
    grid = mapped(world, [np.array([0.0, 0.0, 0.0])], rng)
    truth = np.array([0.30, 0.03, 0.02])
    # Odometry overshoots along the corridor by 12 cm and is off across it by 2 cm.
    predicted = np.array([0.42, 0.05, 0.0])
    result = match_scan(
        grid, noisy_scan(world, truth, rng), 8.0, predicted, 0.3, 0.02, MatcherConfig()
    )
    assert result.accepted and result.reason == "degenerate"
    assert result.condition < 0.02
    assert result.pose[0] == pytest.approx(predicted[0], abs=0.005)  # no jump along x
    assert result.pose[1] == pytest.approx(truth[1], abs=0.01)  # corrected across
    assert result.pose[2] == pytest.approx(truth[2], abs=math.radians(0.3))
    # The information says why: nothing along x, plenty across.
    condition, weak = translational_condition(result.information)
    assert abs(weak[0]) > 0.99 and condition == result.condition
    assert result.covariance[0, 0] > 50.0 * result.covariance[1, 1]


def test_translational_condition() -> None:
    condition, weak = translational_condition(np.diag([4.0, 1.0, 9.0]))
    assert condition == pytest.approx(0.25)
    np.testing.assert_allclose(np.abs(weak), [0.0, 1.0])
    rotation = np.array([[math.cos(0.3), -math.sin(0.3)], [math.sin(0.3), math.cos(0.3)]])
    information = np.eye(3)
    information[:2, :2] = rotation @ np.diag([1e-6, 5.0]) @ rotation.T
    condition, weak = translational_condition(information)
    assert condition < 1e-6
    assert abs(weak @ rotation[:, 0]) == pytest.approx(1.0)
    assert translational_condition(np.zeros((3, 3)))[0] == 0.0


@numba.njit(cache=True)
def _numba_det_and_solve(a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
    return np.linalg.det(a), np.linalg.solve(a, b)


def test_refinement_solve_is_numbas_linalg_bit_for_bit() -> None:
    """The refinement's 3x3 determinant and solve give numba's np.linalg.det and
    np.linalg.solve to the bit (the same LAPACK calls), on systems shaped like its normal
    equations (J^T J over a few points, scaled over 12 decades) and on general ones."""
    rng = np.random.default_rng(3)
    lu, pivots, step = np.empty((3, 3)), np.empty(3, dtype=np.int32), np.empty(3)
    for trial in range(2000):
        jacobian = rng.normal(size=(int(rng.integers(3, 40)), 3)) * [1e-3, 1.0, 1e3]
        system = jacobian.T @ jacobian * 10.0 ** rng.uniform(-6, 6)
        if trial % 5 == 0:
            system = rng.normal(size=(3, 3))
        rhs = rng.normal(size=3)
        determinant, solution = _numba_det_and_solve(system, rhs)
        assert _determinant(system, lu, pivots) == determinant
        _solve(system, rhs, lu, pivots, step)
        np.testing.assert_array_equal(step, solution)
    singular = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    assert _determinant(singular, lu, pivots) == 0.0
    for bad in (np.array([0.0, math.nan, 0.0]), np.diag([1.0, math.inf, 1.0])):
        with pytest.raises(np.linalg.LinAlgError, match="infs or NaNs"):
            _check_finite(bad)
    _check_finite(np.eye(3))  # finite: no error
