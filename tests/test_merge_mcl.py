"""Partial-map MCL (mrslam_env.merge.mcl): the particle-scoring kernel against a slow
reference, resampling, clustering, skeleton sampling, and convergence on a known map."""

from __future__ import annotations

import math

import numpy as np
import pytest
from merge_fixtures import map_pair

from mrslam_env.geometry import mean_pose, wrap_angle
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.merge.mcl import (
    MclConfig,
    beam_log_likelihoods,
    kld_particle_count,
    localize_in_map,
    low_variance_resample,
    particle_clusters,
    prepare_localization_map,
    sample_near_skeleton,
    scan_endpoints,
    score_particles,
)
from mrslam_env.merge.skeleton import free_space_graph
from mrslam_env.merge.virtual import VirtualRobotConfig, virtual_robot_runs


@pytest.fixture(scope="module")
def office_map():
    m1, _ = map_pair("office", (5, 4), (9, 4), np.array([1.0, 2.0, 1.2]))
    return m1


def test_score_kernel_matches_a_slow_reference(office_map):
    config = MclConfig()
    prepared = prepare_localization_map(office_map, config=config)
    rng = np.random.default_rng(0)
    xmin, ymin, xmax, ymax = office_map.extent
    particles = np.column_stack(
        [
            rng.uniform(xmin - 1, xmax + 1, 300),
            rng.uniform(ymin - 1, ymax + 1, 300),
            rng.uniform(-np.pi, np.pi, 300),
        ]
    )
    endpoints = rng.uniform(-4, 4, size=(25, 2))
    mean_log, pose_log = score_particles(prepared, particles, endpoints, config)
    table = prepared.beam_log_likelihood
    for p, (x, y, theta) in enumerate(particles):
        c, s = math.cos(theta), math.sin(theta)
        total = 0.0
        for ex, ey in endpoints:
            cell = office_map.world_to_cell([[x + c * ex - s * ey, y + s * ex + c * ey]])
            inside = office_map.contains(cell)[0]
            total += (
                table[cell[0, 0], cell[0, 1]] if inside else math.log(config.unknown_likelihood)
            )
        assert mean_log[p] == pytest.approx(total / len(endpoints), abs=1e-5)
        cell = office_map.world_to_cell([[x, y]])
        state = (
            office_map.cells[cell[0, 0], cell[0, 1]] if office_map.contains(cell)[0] else UNKNOWN
        )
        expected = {FREE: 0.0, OCCUPIED: -config.occupied_pose_penalty}.get(
            state, -config.unknown_pose_penalty
        )
        assert pose_log[p] == pytest.approx(expected)


def test_likelihood_field_rewards_walls_and_is_neutral_in_unknown_space():
    cells = np.full((20, 20), FREE, dtype=np.int8)
    cells[:, 10] = OCCUPIED
    cells[:, 15:] = UNKNOWN
    config = MclConfig()
    table = beam_log_likelihoods(GridMap(cells=cells, resolution=0.05), config)
    assert table[5, 10] == pytest.approx(0.0, abs=1e-6)  # on the wall
    assert table[5, 0] == pytest.approx(math.log(config.z_rand), abs=5e-3)  # far, known free
    assert table[5, 19] == pytest.approx(math.log(config.unknown_likelihood), abs=1e-6)
    assert table[5, 11] > table[5, 13]  # nearer the wall, likelier


def test_low_variance_resample():
    rng = np.random.default_rng(1)
    assert np.all(low_variance_resample(np.array([0.0, 1.0, 0.0]), 7, rng) == 1)
    uniform = low_variance_resample(np.full(5, 0.2), 5, rng)
    assert sorted(uniform.tolist()) == [0, 1, 2, 3, 4]
    counts = np.bincount(low_variance_resample(np.array([0.25, 0.75]), 1000, rng), minlength=2)
    assert abs(counts[1] - 750) <= 1


def test_low_variance_resample_is_the_searchsorted_of_the_running_sum():
    """The numba loop draws once and picks what numpy's cumsum + searchsorted pick,
    index for index (zero weights, long runs, one heavy particle)."""
    rng = np.random.default_rng(3)
    for trial in range(200):
        n = int(rng.integers(1, 3000))
        weights = rng.random(n) ** rng.uniform(1.0, 40.0)
        weights[rng.random(n) < 0.3] = 0.0
        if not weights.any():
            weights[0] = 1.0
        weights /= weights.sum()
        count = int(rng.integers(1, 2000))
        ours, numpy_rng = np.random.default_rng(trial), np.random.default_rng(trial)
        cumulative = np.cumsum(weights)
        cumulative[-1] = 1.0
        positions = (numpy_rng.random() + np.arange(count)) / count
        expected = np.searchsorted(cumulative, positions, side="left")
        np.testing.assert_array_equal(low_variance_resample(weights, count, ours), expected)
        assert ours.random() == numpy_rng.random()  # one draw each


def _numpy_clusters(particles, weights, radius, angle, max_clusters, min_weight):
    """The greedy mean shift of particle_clusters' docstring in numpy (geometry.mean_pose):
    the reference the numba loop must follow up to the order of its sums."""
    weights = weights / weights.sum()
    remaining = np.ones(len(particles), dtype=bool)
    bins = np.column_stack(
        [
            np.floor(particles[:, 0] / radius),
            np.floor(particles[:, 1] / radius),
            np.floor((particles[:, 2] + np.pi) / angle),
        ]
    ).astype(np.int64)
    key = np.unique(bins, axis=0, return_inverse=True)[1].ravel()
    found = []
    while len(found) < max_clusters:
        left = float(weights[remaining].sum())
        if left <= 0 or left < min_weight:
            break
        heaviest = np.argmax(np.bincount(key[remaining], weights[remaining], key.max() + 1))
        members = remaining & (key == heaviest)
        centre = mean_pose(particles[members], weights[members])
        for _ in range(3):
            offsets = particles[:, :2] - centre[:2]
            turns = np.abs(wrap_angle(particles[:, 2] - centre[2]))
            near = remaining & ((offsets**2).sum(axis=1) <= radius**2) & (turns <= angle)
            if not near.any():
                break
            members = near
            centre = mean_pose(particles[members], weights[members])
        remaining &= ~members
        if weights[members].sum() < min_weight:
            break
        found.append((centre, float(weights[members].sum()), int(members.sum())))
    return sorted(found, key=lambda cluster: -cluster[1])


def test_particle_clusters_follow_the_numpy_mean_shift():
    """Blobs, uniform clutter and a heavy tail of weights: the same clusters (members
    counted exactly), poses and weights equal up to the order of the sums."""
    rng = np.random.default_rng(7)
    for trial in range(60):
        n = 20000 if trial % 6 == 0 else 1500
        k = int(rng.integers(1, 8))
        centres = np.column_stack([rng.uniform(-10, 10, (k, 2)), rng.uniform(-np.pi, np.pi, k)])
        particles = centres[rng.integers(0, k, n)]
        particles = particles + rng.normal(size=(n, 3)) * [0.3, 0.3, 0.2] * rng.uniform(0.2, 3)
        if trial % 3 == 0:  # half of them scattered over the whole map
            particles[n // 2 :, :2] = rng.uniform(-10, 10, (n - n // 2, 2))
        particles[:, 2] = wrap_angle(particles[:, 2])
        weights = np.exp(rng.normal(size=n) * rng.uniform(0, 10))
        ours = particle_clusters(
            particles, weights, radius=0.5, angle=0.3, max_clusters=5, min_weight=0.03
        )
        expected = _numpy_clusters(particles, weights, 0.5, 0.3, 5, 0.03)
        assert [c.count for c in ours] == [count for _, _, count in expected]
        for cluster, (pose, weight, _) in zip(ours, expected, strict=True):
            np.testing.assert_allclose(cluster.pose, pose, rtol=0, atol=1e-12)
            assert cluster.weight == pytest.approx(weight, abs=1e-12)


def test_particle_clusters_find_two_blobs_across_the_heading_wrap():
    rng = np.random.default_rng(2)
    a = np.column_stack(
        [rng.normal(1, 0.05, 600), rng.normal(2, 0.05, 600), rng.normal(np.pi, 0.05, 600)]
    )
    b = np.column_stack(
        [rng.normal(-3, 0.05, 300), rng.normal(0, 0.05, 300), rng.normal(0.5, 0.05, 300)]
    )
    noise = np.column_stack([rng.uniform(-10, 10, (100, 2)), rng.uniform(-np.pi, np.pi, 100)])
    particles = np.vstack([a, b, noise])
    particles[:, 2] = wrap_angle(particles[:, 2])
    clusters = particle_clusters(
        particles, np.ones(len(particles)), radius=0.5, angle=0.3, max_clusters=5, min_weight=0.05
    )
    assert len(clusters) == 2
    assert clusters[0].weight == pytest.approx(0.6, abs=0.02)
    assert clusters[1].weight == pytest.approx(0.3, abs=0.02)
    np.testing.assert_allclose(clusters[0].pose[:2], [1, 2], atol=0.02)
    assert abs(wrap_angle(clusters[0].pose[2] - np.pi)) < 0.02
    np.testing.assert_allclose(clusters[1].pose, [-3, 0, 0.5], atol=0.02)
    assert clusters[0].spread[0] < 0.15 and clusters[0].spread[1] < 0.1
    assert particle_clusters(np.zeros((0, 3)), np.zeros(0), radius=1, angle=1, max_clusters=3) == []


def test_initial_particles_lie_near_the_skeleton_in_free_space(office_map):
    config = MclConfig()
    graph = free_space_graph(office_map, config.skeleton)
    prepared = prepare_localization_map(office_map, config=config, skeleton=graph)
    particles = sample_near_skeleton(prepared, 3000, config, np.random.default_rng(3))
    assert particles.shape == (3000, 3)
    cells = office_map.world_to_cell(particles[:, :2])
    assert office_map.free[cells[:, 0], cells[:, 1]].all()
    skeleton_points = office_map.cell_to_world(np.argwhere(graph.skeleton))
    gaps = np.min(
        np.hypot(*(particles[:, None, :2] - skeleton_points[None]).transpose(2, 0, 1)), axis=1
    )
    assert gaps.max() <= config.skeleton_radius + office_map.resolution
    # Headings: a share along the skeleton, the rest spread over the whole circle.
    assert np.histogram(particles[:, 2], bins=8, range=(-np.pi, np.pi))[0].min() > 50


def test_mcl_converges_on_a_map_it_fully_knows(office_map):
    runs = virtual_robot_runs(office_map, config=VirtualRobotConfig(), rng=np.random.default_rng(0))
    config = MclConfig()
    prepared = prepare_localization_map(office_map, config=config)
    localised = 0
    for index, run in enumerate(runs[:6]):
        result = localize_in_map(
            prepared, run, config=config, rng=np.random.default_rng(index), trace=True
        )
        assert config.min_particles <= len(result.particles) <= config.n_particles
        assert result.weights.sum() == pytest.approx(1.0)
        assert len(result.history) == len(run.ranges)
        truth = run.poses_in_map1[-1]
        top = result.clusters[0]
        if result.converged and (
            np.hypot(*(top.pose[:2] - truth[:2])) <= 0.1
            and abs(wrap_angle(top.pose[2] - truth[2])) <= math.radians(2)
        ):
            localised += 1
    # Some short runs in a symmetric room may stay ambiguous; most must localise.
    assert localised >= 4


def test_bad_input():
    with pytest.raises(ValueError, match="no free space"):
        prepare_localization_map(
            GridMap(cells=np.full((5, 5), UNKNOWN, dtype=np.int8), resolution=0.05),
            config=MclConfig(),
        )
    with pytest.raises(ValueError, match=r"MclConfig\.unknown_likelihood"):
        MclConfig(z_rand=0.2, unknown_likelihood=0.1)
    with pytest.raises(ValueError, match=r"MclConfig\.n_particles"):
        MclConfig(n_particles=0)
    with pytest.raises(ValueError, match=r"MclConfig\.kld_error"):
        MclConfig(kld_error=-0.1)


def test_kld_count_follows_fox_bound():
    """The particle count is Fox's (2003) bound on the occupied histogram bins, clipped."""
    config = MclConfig(n_particles=5000, min_particles=10)
    rng = np.random.default_rng(4)

    def particles_in_bins(k: int) -> np.ndarray:
        # k distinct bins: one particle at the centre of each 0.5 m bin along x, repeated.
        centres = (np.arange(k) + 0.5) * config.kld_bin_size
        x = np.repeat(centres, 7)
        theta = np.full(len(x), 0.5 * config.kld_bin_angle - np.pi)
        return np.column_stack([x, np.zeros(len(x)) + 0.25, theta])[rng.permutation(len(x))]

    for k, expected in ((2, 66), (20, 363), (100, 1347)):
        # (k - 1) / (2 eps) (1 - a + sqrt(a) z)^3, a = 2 / (9 (k - 1)), eps 0.05, z 2.326
        a = 2.0 / (9.0 * (k - 1))
        bound = (k - 1) / 0.1 * (1.0 - a + math.sqrt(a) * 2.326) ** 3
        assert math.ceil(bound) == expected
        assert kld_particle_count(particles_in_bins(k), config) == expected
    assert kld_particle_count(particles_in_bins(1), config) == config.min_particles
    assert kld_particle_count(particles_in_bins(1000), config) == config.n_particles
    few = MclConfig(n_particles=20)  # fewer than min_particles: n_particles wins
    assert kld_particle_count(particles_in_bins(1), few) == 20
    fixed = MclConfig(kld_error=0.0)
    assert kld_particle_count(particles_in_bins(1), fixed) == fixed.n_particles


def test_kld_count_matches_numpy_bins():
    """The bin count behind the KLD bound is numpy's distinct-row count of the bins."""
    from mrslam_env.merge.mcl import _occupied_bins

    rng = np.random.default_rng(5)
    for n in (0, 1, 30, 2000):
        particles = np.column_stack(
            [rng.normal(-3, 4, n), rng.normal(2, 3, n), rng.uniform(-np.pi, np.pi, n)]
        )
        bins = np.column_stack(
            [
                np.floor(particles[:, 0] / 0.5),
                np.floor(particles[:, 1] / 0.5),
                np.floor((particles[:, 2] + np.pi) / 0.2),
            ]
        )
        assert _occupied_bins(particles, 0.5, 0.2) == len(np.unique(bins, axis=0))


def test_converged_filter_keeps_fewer_particles(office_map):
    """Once the particles gather in a few poses, KLD-sampling keeps far fewer of them;
    with ``kld_error = 0`` the count stays ``n_particles``."""
    runs = virtual_robot_runs(office_map, config=VirtualRobotConfig(), rng=np.random.default_rng(0))
    prepared = prepare_localization_map(office_map, config=MclConfig())
    counts = []
    for config in (MclConfig(), MclConfig(kld_error=0.0)):
        result = localize_in_map(prepared, runs[0], config=config, rng=np.random.default_rng(0))
        assert result.converged
        counts.append(len(result.particles))
    assert counts[0] <= 0.5 * MclConfig().n_particles
    assert counts[1] == MclConfig().n_particles


def test_scan_endpoints_skip_invalid_and_no_return_beams(office_map):
    runs = virtual_robot_runs(office_map, rng=np.random.default_rng(0))
    run = runs[0]
    endpoints = scan_endpoints(run, 0, 1000)
    ranges = run.ranges[0]
    usable = np.isfinite(ranges) & (ranges < run.max_range)
    assert len(endpoints) == usable.sum()
    np.testing.assert_allclose(np.hypot(*endpoints.T), ranges[usable])
    assert len(scan_endpoints(run, 0, 10)) == min(10, usable.sum())


def test_numba_wrap_and_cluster_window_match_numpy_bit_for_bit():
    """The kernels behind the particle sampling and clustering wrap angles exactly as
    :func:`~mrslam_env.geometry.wrap_angle` does, so the filter draws the same particles."""
    import numba

    from mrslam_env.merge.mcl import _within_kernel, _wrap

    @numba.njit
    def _wrap_angles(angles: np.ndarray) -> np.ndarray:
        out = np.empty(angles.shape[0])
        for i in range(angles.shape[0]):
            out[i] = _wrap(angles[i])
        return out

    rng = np.random.default_rng(3)
    angles = np.concatenate(
        [
            rng.uniform(-20.0, 20.0, 50_000),
            np.array([0.0, -0.0, math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 2 * math.pi]),
            np.nextafter(np.array([math.pi, -math.pi]), 0.0),
        ]
    )
    assert np.array_equal(_wrap_angles(angles).view(np.int64), wrap_angle(angles).view(np.int64))
    particles = np.column_stack(
        [rng.uniform(-2, 2, 5000), rng.uniform(-2, 2, 5000), rng.uniform(-4, 4, 5000)]
    )
    for centre in (np.array([0.1, -0.2, 3.0]), np.array([0.0, 0.0, -math.pi])):
        dx = particles[:, 0] - centre[0]
        dy = particles[:, 1] - centre[1]
        expected = (dx * dx + dy * dy <= 0.5 * 0.5) & (
            np.abs(wrap_angle(particles[:, 2] - centre[2])) <= 0.3
        )
        among = np.ones(len(particles), dtype=np.bool_)
        within = _within_kernel(particles, *centre, 0.5 * 0.5, 0.3, among)
        assert np.array_equal(within, expected)


def test_numba_motion_update_and_cluster_seeds_match_numpy_bit_for_bit():
    """The motion update is ``compose(particles, odometry + noise)`` bit for bit, and the
    cluster seed (bin ranks, heaviest remaining bin) is ``np.unique`` / ``np.bincount`` /
    ``np.argmax``'s, so the filter gives the same particles and clusters as numpy would."""
    from mrslam_env.geometry import compose
    from mrslam_env.merge.mcl import _heaviest_bin_members, _ranks, predict_particles

    rng = np.random.default_rng(4)
    config = MclConfig()
    particles = np.column_stack(
        [rng.uniform(-30, 30, 3000), rng.uniform(-30, 30, 3000), rng.uniform(-np.pi, np.pi, 3000)]
    )
    for odometry in (np.array([0.25, 0.01, 0.05]), np.array([0.0, 0.0, -3.1])):
        moved = predict_particles(particles, odometry, config, np.random.default_rng(9))
        draws = np.random.default_rng(9)
        distance = float(np.hypot(odometry[0], odometry[1]))
        noisy = np.empty((len(particles), 3))
        xy_std = config.motion_xy_noise + config.motion_xy_noise_per_m * distance
        theta_std = config.motion_theta_noise + config.motion_theta_noise_per_rad * abs(odometry[2])
        noisy[:, :2] = odometry[:2] + xy_std * draws.normal(size=(len(particles), 2))
        noisy[:, 2] = odometry[2] + theta_std * draws.normal(size=len(particles))
        expected = compose(particles, noisy)
        assert np.array_equal(moved.view(np.int64), expected.view(np.int64))
    key = rng.integers(0, 500, 4000) * 7
    assert np.array_equal(_ranks(key, 3500), np.unique(key, return_inverse=True)[1])
    weights = np.where(rng.random(4000) < 0.5, 0.25, rng.random(4000))  # ties between bins
    bins = _ranks(key, 3500)
    for _ in range(3):
        remaining = rng.random(4000) < 0.7
        heaviest = np.argmax(np.bincount(bins[remaining], weights=weights[remaining]))
        expected = remaining & (bins == heaviest)
        assert np.array_equal(_heaviest_bin_members(bins, weights, remaining), expected)
