"""The adaptive random walk (mrslam_env.merge.refine).

Invariants: the best psi never increases and is the least psi the walk was offered; the
result's psi is psi of its transform; a seeded walk is deterministic. Outcomes: from a
start ~0.3 m and ~5° off on realistic partial maps the walk lands within one cell and one
degree of the truth; a map against a copy of itself warped by a known transform, for
rotations all round the circle, likewise.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from merge_fixtures import map_pair

from mrslam_env.geometry import inverse, wrap_angle, wrap_scalar
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.dissimilarity import DissimilarityConfig, dissimilarity, distance_maps
from mrslam_env.merge.fuse import warp_map
from mrslam_env.merge.refine import (
    MIN_MOVES_TO_ADAPT,
    RandomWalkConfig,
    _from_pivot_parameters,
    _pivot,
    _to_pivot_parameters,
    _wrap,
    adapted_proposal,
    refine_random_walk,
)

CELL = 0.05
OFFICE_TRUTH = np.array([1.0, 2.0, 1.2])
WAREHOUSE_TRUTH = np.array([0.5, -1.0, 2.0])


@pytest.fixture(scope="module")
def office_pair() -> tuple[GridMap, GridMap]:
    return map_pair("office", (5, 4), (9, 4), OFFICE_TRUTH)


@pytest.fixture(scope="module")
def warehouse_pair() -> tuple[GridMap, GridMap]:
    return map_pair("warehouse", (6, 6), (9, 7), WAREHOUSE_TRUTH)


def perturbed(truth: np.ndarray, rng: np.random.Generator, metres: float, degrees: float):
    direction = rng.uniform(0.0, 2.0 * np.pi)
    sign = rng.choice([-1.0, 1.0])
    return truth + np.array(
        [metres * np.cos(direction), metres * np.sin(direction), sign * math.radians(degrees)]
    )


def errors(transform: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Translation error (m) and rotation error (degrees)."""
    return (
        float(np.hypot(*(transform[:2] - truth[:2]))),
        abs(math.degrees(float(wrap_angle(transform[2] - truth[2])))),
    )


# --- the proposal ---------------------------------------------------------------------------


def test_proposal_before_adaptation_is_the_initial_one() -> None:
    config = RandomWalkConfig(initial_std_xy=0.2, initial_std_theta=0.05)
    for count in range(MIN_MOVES_TO_ADAPT):
        mean, cholesky = adapted_proposal(np.full((count, 3), 0.3), config)
        np.testing.assert_array_equal(mean, np.zeros(3))
        np.testing.assert_allclose(cholesky @ cholesky.T, np.diag([0.04, 0.04, 0.0025]))
    mean, cholesky = adapted_proposal(np.zeros((0, 3)), config, fallback_scale=1e-6)
    floor = [config.min_std_xy, config.min_std_xy, config.min_std_theta]
    np.testing.assert_allclose(np.diag(cholesky), floor)  # a shrunken fallback stops at the floor


def test_adapted_proposal_is_the_moves_mean_and_covariance_plus_the_floor() -> None:
    rng = np.random.default_rng(0)
    config = RandomWalkConfig()
    moves = rng.normal([0.02, -0.01, 0.003], [0.05, 0.02, 0.01], size=(8, 3))
    mean, cholesky = adapted_proposal(moves, config)
    floor = np.array([config.min_std_xy, config.min_std_xy, config.min_std_theta])
    np.testing.assert_allclose(mean, moves.mean(axis=0))
    np.testing.assert_allclose(cholesky @ cholesky.T, np.cov(moves.T) + np.diag(floor**2))
    assert np.allclose(np.triu(cholesky, 1), 0.0)


def test_adapted_proposal_is_capped_per_axis_keeping_correlation() -> None:
    config = RandomWalkConfig(max_std_xy=0.1, max_std_theta=0.02)
    t = np.linspace(-1.0, 1.0, 6)
    moves = np.column_stack([3.0 * t, 3.0 * t, 0.001 * t])  # huge, perfectly correlated in x, y
    _, cholesky = adapted_proposal(moves, config)
    covariance = cholesky @ cholesky.T
    std = np.sqrt(np.diag(covariance))
    assert std[0] == pytest.approx(0.1) and std[1] == pytest.approx(0.1)
    assert std[2] < 0.02
    assert covariance[0, 1] / (std[0] * std[1]) > 0.99


# --- invariants ------------------------------------------------------------------------------


def test_best_psi_never_increases_and_is_the_least_psi_accepted(office_pair) -> None:
    m1, m2 = office_pair
    rng = np.random.default_rng(1)
    start = perturbed(OFFICE_TRUTH, rng, 0.3, 5.0)
    result = refine_random_walk(m1, m2, start, rng=rng, trace=True)
    trace = result.trace
    assert trace is not None
    n = result.iterations
    assert trace.candidates.shape == (n, 3) and trace.candidate_psi.shape == (n,)
    assert trace.accepted.shape == (n,) and trace.best_psi.shape == (n,)
    assert np.all(np.diff(trace.best_psi) <= 0.0)
    accepted_psi = np.where(trace.accepted, trace.candidate_psi, np.inf)
    expected_best = np.minimum.accumulate(np.minimum(accepted_psi, result.initial_psi))
    np.testing.assert_array_equal(trace.best_psi, expected_best)
    assert result.psi == trace.best_psi[-1] <= result.initial_psi
    assert result.accepted_moves == int(trace.accepted.sum())
    assert result.psi == pytest.approx(dissimilarity(m1, m2, result.transform), rel=1e-12)
    assert result.initial_psi == pytest.approx(dissimilarity(m1, m2, start), rel=1e-12)
    np.testing.assert_allclose(result.initial_transform, start)
    # Each candidate's psi is psi of that candidate.
    for k in range(0, n, 50):
        assert trace.candidate_psi[k] == pytest.approx(
            dissimilarity(m1, m2, trace.candidates[k]), rel=1e-12
        )


def test_seeded_walk_is_deterministic(office_pair) -> None:
    m1, m2 = office_pair
    start = OFFICE_TRUTH + np.array([0.2, -0.1, 0.05])
    config = RandomWalkConfig(iterations=120)
    runs = [
        refine_random_walk(
            m1, m2, start, config=config, rng=np.random.default_rng(seed), trace=True
        )
        for seed in (5, 5, 6)
    ]
    assert runs[0].trace is not None and runs[1].trace is not None and runs[2].trace is not None
    np.testing.assert_array_equal(runs[0].transform, runs[1].transform)
    np.testing.assert_array_equal(runs[0].trace.candidates, runs[1].trace.candidates)
    assert not np.array_equal(runs[0].trace.candidates, runs[2].trace.candidates)


def _python_walk(m1, m2, start, config, rng, d1, d2):
    """The walk of refine_random_walk's docstring as a plain numpy loop (psi from
    :func:`dissimilarity`, the kernel the walk calls, checked against the definition in
    tests/test_merge_dissimilarity.py): the oracle the numba loop must follow bit for bit."""
    cost = config.dissimilarity

    def psi_of(transform):
        return dissimilarity(m1, m2, transform, distances1=d1, distances2=d2, config=cost)

    pivot = _pivot(m2, d2)
    current_psi = best_psi = psi_of(start)
    current = _to_pivot_parameters(start, pivot)
    best, best_transform = current.copy(), start.copy()
    moves: list[np.ndarray] = []
    fallback, rejections, taken = 1.0, 0, 0
    proposal = None
    for _ in range(config.iterations):
        if proposal is None:
            proposal = adapted_proposal(np.asarray(moves).reshape(-1, 3), config, fallback)
        mean, cholesky = proposal
        normal = rng.standard_normal(3)
        move = mean + (
            cholesky[:, 0] * normal[0] + cholesky[:, 1] * normal[1] + cholesky[:, 2] * normal[2]
        )
        worse_ok = rng.random() < config.worse_move_probability
        candidate = current + move
        candidate[2] = wrap_scalar(candidate[2])
        transform = _from_pivot_parameters(candidate, pivot)
        psi = psi_of(transform)
        if math.isfinite(psi) and (psi <= current_psi or worse_ok):
            moves = [*moves, move][-config.memory :]
            proposal, taken, rejections = None, taken + 1, 0
            current, current_psi = candidate, psi
            if psi < best_psi:
                best, best_psi, best_transform = candidate.copy(), psi, transform
        else:
            rejections += 1
            if rejections >= config.stall_iterations:
                moves, proposal, rejections = [], None, 0
                fallback *= 0.5
                current, current_psi = best.copy(), best_psi
    return best_transform, best_psi, taken


@pytest.mark.parametrize(
    "cost",
    [
        DissimilarityConfig(),
        DissimilarityConfig(wall_sides=True),
        DissimilarityConfig(restrict_to_overlap=False),
        DissimilarityConfig(restrict_to_overlap=False, wall_sides=True),
    ],
    ids=["overlap", "wall-sides", "faithful", "faithful-wall-sides"],
)
def test_kernel_walk_is_the_numpy_walk_bit_for_bit(office_pair, cost) -> None:
    """The numba loop draws the same numbers and makes the same moves as the numpy loop,
    so every transform and psi is equal, not close, for every psi variant."""
    m1, m2 = office_pair
    d1, d2 = distance_maps(m1, sides=True), distance_maps(m2, sides=True)
    config = RandomWalkConfig(iterations=150, stall_iterations=10, dissimilarity=cost)
    for seed in range(3):
        start = perturbed(OFFICE_TRUTH, np.random.default_rng(seed), 0.3, 5.0)
        ours, numpy_rng = np.random.default_rng(seed), np.random.default_rng(seed)
        result = refine_random_walk(
            m1, m2, start, config=config, rng=ours, distances1=d1, distances2=d2
        )
        transform, psi, taken = _python_walk(m1, m2, start, config, numpy_rng, d1, d2)
        np.testing.assert_array_equal(result.transform, transform)
        assert result.psi == psi and result.accepted_moves == taken
        assert ours.random() == numpy_rng.random()  # the generator is left where numpy's is


def test_kernel_wrap_is_wrap_scalar() -> None:
    angles = [0.0, -0.0, math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 2 * math.pi, 1e-300]
    angles += list(np.random.default_rng(0).uniform(-40.0, 40.0, 2000))
    angles += [k * math.pi / 2 + d for k in range(-9, 10) for d in (0.0, 1e-15, -1e-15)]
    for angle in angles:
        assert _wrap(angle) == wrap_scalar(angle), angle


def test_precomputed_distance_maps_do_not_change_the_walk(office_pair) -> None:
    m1, m2 = office_pair
    start = OFFICE_TRUTH + np.array([0.1, 0.1, -0.03])
    config = RandomWalkConfig(iterations=60)
    plain = refine_random_walk(m1, m2, start, config=config, rng=np.random.default_rng(2))
    given = refine_random_walk(
        m1,
        m2,
        start,
        config=config,
        rng=np.random.default_rng(2),
        distances1=distance_maps(m1),
        distances2=distance_maps(m2),
    )
    np.testing.assert_array_equal(plain.transform, given.transform)


def test_a_start_without_overlap_stays_put(office_pair) -> None:
    m1, m2 = office_pair
    start = OFFICE_TRUTH + np.array([200.0, 0.0, 0.0])
    result = refine_random_walk(
        m1, m2, start, config=RandomWalkConfig(iterations=30), rng=np.random.default_rng(0)
    )
    assert math.isinf(result.initial_psi) and math.isinf(result.psi)
    np.testing.assert_allclose(result.transform, start)


# --- outcomes --------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("pair", ["office", "warehouse"])
def test_walk_converges_from_a_perturbed_start(pair, seed, office_pair, warehouse_pair) -> None:
    m1, m2 = office_pair if pair == "office" else warehouse_pair
    truth = OFFICE_TRUTH if pair == "office" else WAREHOUSE_TRUTH
    rng = np.random.default_rng(seed)
    start = perturbed(truth, rng, 0.3, 5.0)
    result = refine_random_walk(m1, m2, start, rng=rng)
    translation_error, rotation_error = errors(result.transform, truth)
    assert translation_error <= CELL, result
    assert rotation_error <= 1.0, result
    assert result.psi <= dissimilarity(m1, m2, truth) + 0.05


@pytest.mark.parametrize("degrees", [0.0, 37.0, 90.0, 145.0, 180.0, -120.0, -90.0, -20.0])
def test_walk_recovers_a_warped_copy_all_round_the_circle(office_pair, degrees: float) -> None:
    m1, _ = office_pair
    truth = np.array([0.83, -1.21, math.radians(degrees)])
    m2 = warp_map(m1, inverse(truth))  # m1 seen from a frame placed at `truth`
    rng = np.random.default_rng(int(degrees) % 97)
    start = perturbed(truth, rng, 0.3, 5.0)
    result = refine_random_walk(m1, m2, start, rng=rng)
    translation_error, rotation_error = errors(result.transform, truth)
    assert translation_error <= CELL, result
    assert rotation_error <= 1.0, result


def test_faithful_psi_can_be_chosen(office_pair) -> None:
    m1, _ = office_pair
    config = RandomWalkConfig(
        iterations=150, dissimilarity=DissimilarityConfig(restrict_to_overlap=False)
    )
    start = np.array([0.1, -0.1, 0.03])
    result = refine_random_walk(m1, m1, start, config=config, rng=np.random.default_rng(0))
    translation_error, rotation_error = errors(result.transform, np.zeros(3))
    assert translation_error <= CELL and rotation_error <= 1.0


# --- bad input -------------------------------------------------------------------------------


def test_bad_input_raises_one_line_value_errors(office_pair) -> None:
    m1, m2 = office_pair
    coarse = GridMap(cells=m2.cells, resolution=0.1, origin=m2.origin)
    rng = np.random.default_rng(0)
    for start, other, words in (
        ([0.0, np.nan, 0.0], m2, "finite"),
        ([0.0, 0.0], m2, "shape"),
        ([0.0, 0.0, 0.0], coarse, "different resolutions"),
    ):
        with pytest.raises(ValueError, match=words) as error:
            refine_random_walk(m1, other, start, rng=rng)
        assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("iterations", 0),
        ("memory", 2.5),
        ("stall_iterations", 0),
        ("initial_std_xy", 0.0),
        ("min_std_theta", math.nan),
        ("max_std_xy", -1.0),
        ("worse_move_probability", 1.5),
    ],
)
def test_config_errors_name_field_and_value(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=rf"RandomWalkConfig\.{field} .*{value!r}"):
        RandomWalkConfig(**{field: value})  # type: ignore[arg-type]


def test_config_floor_must_not_exceed_cap() -> None:
    with pytest.raises(ValueError, match=r"RandomWalkConfig\.min_std_xy must be <= max_std_xy"):
        RandomWalkConfig(min_std_xy=2.0, max_std_xy=1.0)
