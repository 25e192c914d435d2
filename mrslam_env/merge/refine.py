"""Refinement of a relative pose by Birk & Carpin's adaptive random walk (docs/design.md §5 step 6).

Birk & Carpin, "Merging occupancy grid maps from multiple robots" (Proc. IEEE 94(7), 2006),
and Algorithm 3 of the virtual-robot paper: starting from a hypothesis ``t_0``, propose
``s = t_k + v`` with ``v ~ N(mu_k, Sigma_k)``, where ``mu_k`` and ``Sigma_k`` are the mean and
covariance of the last ``M`` accepted moves; accept ``s`` when its dissimilarity psi
(:func:`mrslam_env.merge.dissimilarity.dissimilarity`) is no worse, and rarely when it is;
keep the best transform seen. Accepted moves that keep improving make the proposal grow and
drift along the productive direction; near the optimum only small moves are accepted and
the proposal shrinks to a floor, so the walk settles to a fraction of a cell.

Two changes to the textbook walk, both needed in practice (on realistic partial map pairs
started a few tenths of a metre and a few degrees off, the textbook walk often ends more
than a cell or a degree away):

- **Walk about m2's centroid.** The walk's coordinates are ``(p_x, p_y, theta)``, where
  ``p`` is where the centroid of m2's known cells lands in map 1, instead of the raw
  ``(x, y, theta)`` of ``map1_from_map2``. A rotation about map 2's frame origin, often
  metres from its content, also swings the content sideways, so raw proposals couple
  rotation and translation strongly; about the centroid they are nearly independent.
- **Stall restarts.** The adapted proposal only changes when a move is accepted, so a walk
  whose last accepted moves were large keeps proposing large moves that are never
  accepted again. After ``stall_iterations`` rejections in a row the walk forgets its
  moves, returns to the best transform and halves its fallback proposal.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import wrap_scalar
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.dissimilarity import (
    DissimilarityConfig,
    DistanceMaps,
    _check_has_known,
    _checked_distances,
    _psi,
    _psi_tables,
    _PsiTables,
    check_same_resolution,
    check_transform,
)
from mrslam_env.validation import check_fields, require

__all__ = [
    "RandomWalkConfig",
    "RandomWalkResult",
    "RandomWalkTrace",
    "adapted_proposal",
    "refine_random_walk",
]

MIN_MOVES_TO_ADAPT = 3
"""Accepted moves needed before their mean and covariance replace the initial proposal."""


@dataclass(frozen=True, slots=True, kw_only=True)
class RandomWalkConfig:
    """The adaptive random walk: length, memory, proposal sizes, worse-move acceptance."""

    iterations: int = 400
    """Proposals evaluated (one psi each)."""
    memory: int = 10
    """M: the last M accepted moves set the proposal's mean and covariance."""
    initial_std_xy: float = 0.1
    """Proposal standard deviation in x and y before adaptation, m (of the landing point
    of m2's centroid, see the module docstring)."""
    initial_std_theta: float = math.radians(2.0)
    """Proposal standard deviation in theta before adaptation, rad (about m2's centroid)."""
    min_std_xy: float = 0.01
    """Floor added (in quadrature) to the adapted x and y standard deviations, m, so the
    proposal never collapses."""
    min_std_theta: float = math.radians(0.1)
    """Floor added (in quadrature) to the adapted theta standard deviation, rad."""
    max_std_xy: float = 1.0
    """Cap on the adapted x and y standard deviations, m."""
    max_std_theta: float = math.radians(20.0)
    """Cap on the adapted theta standard deviation, rad."""
    stall_iterations: int = 25
    """After this many rejections in a row the remembered moves are forgotten, the walk
    returns to the best transform and the fallback proposal (used until enough new moves
    are accepted) halves, down to the floor. Without it a walk whose last accepted moves
    were large keeps proposing large moves that are never accepted."""
    worse_move_probability: float = 0.01
    """Probability of accepting a proposal with a higher (finite) psi, so the walk can
    leave a shallow local minimum; the best transform is kept regardless."""
    dissimilarity: DissimilarityConfig = field(default_factory=DissimilarityConfig)
    """The psi variant minimised (overlap-restricted by default)."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_fields(
            self,
            positive=(
                "initial_std_xy",
                "initial_std_theta",
                "min_std_xy",
                "min_std_theta",
                "max_std_xy",
                "max_std_theta",
            ),
            non_negative=("worse_move_probability",),
            counts=("iterations", "memory", "stall_iterations"),
        )
        for low, high in (("min_std_xy", "max_std_xy"), ("min_std_theta", "max_std_theta")):
            floor, cap = getattr(self, low), getattr(self, high)
            require(name, low, floor, floor <= cap, f"<= {high} ({cap!r})")
        p = self.worse_move_probability
        require(name, "worse_move_probability", p, p <= 1.0, "in [0, 1]")
        psi = self.dissimilarity
        require(
            name,
            "dissimilarity",
            psi,
            isinstance(psi, DissimilarityConfig),
            "a DissimilarityConfig",
        )


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class RandomWalkTrace:
    """Every proposal of a random walk, for the recorder (``merge/refine/*``).

    Attributes
    ----------
    candidates : ndarray of float64, shape (K, 3)
        Proposed ``map1_from_map2`` per iteration, metres and radians.
    candidate_psi : ndarray of float64, shape (K,)
        Their psi (``inf`` where the maps barely overlap).
    accepted : ndarray of bool, shape (K,)
        Whether the walk moved to the proposal.
    best_psi : ndarray of float64, shape (K,)
        Best psi found up to and including each iteration; never increases.
    """

    candidates: NDArray[np.float64]
    candidate_psi: NDArray[np.float64]
    accepted: NDArray[np.bool_]
    best_psi: NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class RandomWalkResult:
    """Outcome of :func:`refine_random_walk`.

    Attributes
    ----------
    transform : ndarray of float64, shape (3,)
        Best ``map1_from_map2`` found (the initial one if nothing was better).
    psi : float
        Its dissimilarity, cells.
    initial_transform : ndarray of float64, shape (3,)
    initial_psi : float
        psi of the start, cells (``inf`` if the maps barely overlap there).
    iterations : int
        Proposals evaluated.
    accepted_moves : int
        Proposals the walk moved to.
    trace : RandomWalkTrace or None
        Every proposal, when asked for.
    """

    transform: NDArray[np.float64]
    psi: float
    initial_transform: NDArray[np.float64]
    initial_psi: float
    iterations: int
    accepted_moves: int
    trace: RandomWalkTrace | None = None


def adapted_proposal(
    moves: NDArray[np.float64], config: RandomWalkConfig, fallback_scale: float = 1.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean and Cholesky factor of the proposal ``N(mu_k, Sigma_k)`` from accepted moves.

    Birk & Carpin's adaptation: ``mu_k`` and ``Sigma_k`` are the sample mean and covariance
    of the last M accepted moves; ``Sigma_k`` gets the floor ``diag(min_std**2)`` added and
    is scaled down per axis where its standard deviation exceeds the cap (correlations kept).
    With fewer than ``MIN_MOVES_TO_ADAPT`` moves the proposal is ``N(0, diag(initial_std**2))``.

    Parameters
    ----------
    moves : ndarray of float64, shape (n, 3)
        The last accepted moves ``(dx, dy, dtheta)``, metres and radians, n <= M.
    config : RandomWalkConfig

    Returns
    -------
    mean : ndarray of float64, shape (3,)
    cholesky : ndarray of float64, shape (3, 3)
        Lower-triangular L with ``L @ L.T = Sigma_k``.
    """
    if len(moves) < MIN_MOVES_TO_ADAPT:
        initial = np.array([config.initial_std_xy, config.initial_std_xy, config.initial_std_theta])
        floor = np.array([config.min_std_xy, config.min_std_xy, config.min_std_theta])
        return np.zeros(3), np.diag(np.maximum(initial * fallback_scale, floor))
    mean = moves.mean(axis=0)
    centred = moves - mean
    covariance = centred.T @ centred / (len(moves) - 1)
    floor = np.array([config.min_std_xy, config.min_std_xy, config.min_std_theta])
    covariance += np.diag(floor**2)
    cap = np.array([config.max_std_xy, config.max_std_xy, config.max_std_theta])
    scale = np.minimum(1.0, cap / np.sqrt(np.diag(covariance)))
    covariance *= np.outer(scale, scale)
    return mean, np.linalg.cholesky(covariance)


def _pivot(m2: GridMap, distances2: DistanceMaps) -> NDArray[np.float64]:
    """Centroid (x, y) of m2's known cells in map 2's frame, metres."""
    cells = np.concatenate([distances2.free_cells, distances2.occupied_cells])
    return np.asarray(m2.cell_to_world(cells.mean(axis=0)), dtype=np.float64)


def _to_pivot_parameters(
    map1_from_map2: NDArray[np.float64], pivot: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``(p_x, p_y, theta)``: where the pivot of map 2 lands in map 1, and the rotation."""
    c, s = math.cos(map1_from_map2[2]), math.sin(map1_from_map2[2])
    px = c * pivot[0] - s * pivot[1] + map1_from_map2[0]
    py = s * pivot[0] + c * pivot[1] + map1_from_map2[1]
    return np.array([px, py, map1_from_map2[2]])


def _from_pivot_parameters(
    parameters: NDArray[np.float64], pivot: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Inverse of :func:`_to_pivot_parameters`: ``t = p - R(theta) pivot``."""
    c, s = math.cos(parameters[2]), math.sin(parameters[2])
    x = parameters[0] - (c * pivot[0] - s * pivot[1])
    y = parameters[1] - (s * pivot[0] + c * pivot[1])
    return np.array([x, y, parameters[2]])


def refine_random_walk(
    m1: GridMap,
    m2: GridMap,
    initial: ArrayLike,
    *,
    config: RandomWalkConfig | None = None,
    rng: np.random.Generator,
    distances1: DistanceMaps | None = None,
    distances2: DistanceMaps | None = None,
    trace: bool = False,
) -> RandomWalkResult:
    """Minimise psi over ``map1_from_map2`` by the adaptive random walk (paper Algorithm 3).

    Parameters
    ----------
    m1, m2 : GridMap
        Two maps of one resolution, each with a known cell.
    initial : array_like, shape (3,)
        Starting ``map1_from_map2`` (a hypothesis), metres and radians.
    config : RandomWalkConfig, optional
    rng : numpy.random.Generator
        The only source of randomness; the same seed gives the same walk.
    distances1, distances2 : DistanceMaps, optional
        Precomputed ``distance_maps`` of m1 and m2 (computed here otherwise).
    trace : bool, default False
        Keep every proposal in ``result.trace``.

    Returns
    -------
    RandomWalkResult
        The best transform and its psi; its psi never exceeds ``initial_psi``.

    Raises
    ------
    ValueError
        Different resolutions, empty or all-unknown maps, or a non-finite start.
    """
    config = config or RandomWalkConfig()
    start = check_transform(initial).copy()
    start[2] = wrap_scalar(start[2])
    check_same_resolution(m1, m2)
    _check_has_known(m1, "map 1")
    _check_has_known(m2, "map 2")
    cost = config.dissimilarity
    d1 = _checked_distances(m1, distances1, "distances1", sides=cost.wall_sides)
    d2 = _checked_distances(m2, distances2, "distances2", sides=cost.wall_sides)

    tables = _psi_tables(m1, m2, d1, d2, cost)
    initial_psi = _psi(start[0], start[1], start[2], tables)
    pivot = _pivot(m2, d2)
    current = _to_pivot_parameters(start, pivot)
    best, best_transform = current.copy(), start.copy()
    psis = np.array([initial_psi, initial_psi])  # current, best
    counters = np.zeros(2, dtype=np.int64)  # rejections in a row, accepted moves
    move = np.zeros(3)
    moves: deque[NDArray[np.float64]] = deque(maxlen=config.memory)
    fallback_scale = 1.0
    n = config.iterations
    size = n if trace else 0
    candidates, candidate_psi = np.empty((size, 3)), np.empty(size)
    accepted, best_history = np.zeros(size, dtype=np.bool_), np.empty(size)
    k = 0
    while k < n:
        # Only accepted moves and stalls change the proposal: the kernel walks until one.
        mean, cholesky = adapted_proposal(np.asarray(moves).reshape(-1, 3), config, fallback_scale)
        k, event = _walk_until_adapted(
            k, n, np.ascontiguousarray(mean), np.ascontiguousarray(cholesky), rng,
            config.worse_move_probability, config.stall_iterations, pivot[0], pivot[1],
            current, best, best_transform, psis, counters, move, tables,
            trace, candidates, candidate_psi, accepted, best_history,
        )  # fmt: skip
        if event == _ACCEPTED:
            moves.append(move.copy())
        elif event == _STALLED:
            # The remembered moves no longer lead anywhere: forget them, go back to the
            # best transform (done by the kernel) and search around it with a smaller
            # fallback proposal.
            moves.clear()
            fallback_scale *= 0.5
    best_psi = psis[1]
    accepted_moves = int(counters[1])

    walk_trace = None
    if trace:
        walk_trace = RandomWalkTrace(
            candidates=candidates,
            candidate_psi=candidate_psi,
            accepted=accepted,
            best_psi=best_history,
        )
    return RandomWalkResult(
        transform=best_transform,
        psi=float(best_psi),
        initial_transform=start,
        initial_psi=float(initial_psi),
        iterations=n,
        accepted_moves=accepted_moves,
        trace=walk_trace,
    )


# --- the walk as a numba kernel -----------------------------------------------------------------
#
# The loop above runs in :func:`_walk_until_adapted`, which returns to Python only when the
# proposal changes (an accepted move or a stall, about one iteration in ten), so that
# :func:`adapted_proposal` stays numpy (its covariance and Cholesky factor come from BLAS and
# LAPACK, whose rounding a numba loop would not reproduce). The kernel draws from the same
# generator in the same order (numba's ``Generator`` gives numpy's stream) and evaluates psi
# with :func:`~mrslam_env.merge.dissimilarity._psi`, the kernel behind ``dissimilarity``: the
# walk is the Python walk's bit for bit (tests/test_merge_refine.py).

_ACCEPTED = 1
_STALLED = 2


@numba.njit(cache=True)
def _wrap(angle: float) -> float:
    """:func:`~mrslam_env.geometry.wrap_scalar` bit for bit: CPython's ``math.remainder``
    (exact, from ``fmod``), then -pi to pi."""
    period = 2.0 * math.pi
    absolute = abs(angle)
    m = np.fmod(absolute, period)
    c = period - m
    if m < c:
        r = m
    elif m > c:
        r = -c
    else:
        r = m - 2.0 * np.fmod(0.5 * (absolute - m), period)
    wrapped = math.copysign(1.0, angle) * r
    return math.pi if wrapped <= -math.pi else wrapped


@numba.njit(cache=True, inline="always")
def _copy3(source: NDArray[np.float64], target: NDArray[np.float64]) -> None:
    """``target[:] = source`` for 3-vectors, as a loop: the slice copy's shape check makes
    numba compile its string formatting, seconds of a first run."""
    for j in range(3):
        target[j] = source[j]


@numba.njit(cache=True)
def _walk_until_adapted(
    k: int,
    n: int,
    mean: NDArray[np.float64],
    cholesky: NDArray[np.float64],
    rng: np.random.Generator,
    worse_move_probability: float,
    stall_iterations: int,
    pivot_x: float,
    pivot_y: float,
    current: NDArray[np.float64],
    best: NDArray[np.float64],
    best_transform: NDArray[np.float64],
    psis: NDArray[np.float64],
    counters: NDArray[np.int64],
    move: NDArray[np.float64],
    tables: _PsiTables,
    trace: bool,
    candidates: NDArray[np.float64],
    candidate_psi: NDArray[np.float64],
    accepted: NDArray[np.bool_],
    best_history: NDArray[np.float64],
) -> tuple[int, int]:
    """Iterations ``k, k + 1, ...`` of :func:`refine_random_walk` under the proposal
    ``N(mean, cholesky cholesky^T)``, until the proposal must change: returns the next
    iteration and :data:`_ACCEPTED` (the move is in ``move``), :data:`_STALLED`, or 0 at
    ``n``. ``current``, ``best`` (pivot parameters), ``best_transform``, ``psis``
    (current, best) and ``counters`` (rejections in a row, accepted moves) are updated in
    place."""
    normal = np.empty(3)
    step = np.empty(3)
    while k < n:
        for j in range(3):
            normal[j] = rng.standard_normal()
        for i in range(3):  # written out, not BLAS: the same float on every machine
            step[i] = mean[i] + (
                cholesky[i, 0] * normal[0] + cholesky[i, 1] * normal[1] + cholesky[i, 2] * normal[2]
            )
        worse_ok = rng.random() < worse_move_probability
        candidate = current + step
        candidate[2] = _wrap(candidate[2])
        c, s = math.cos(candidate[2]), math.sin(candidate[2])
        x = candidate[0] - (c * pivot_x - s * pivot_y)
        y = candidate[1] - (s * pivot_x + c * pivot_y)
        psi = _psi(x, y, candidate[2], tables)
        take = math.isfinite(psi) and (psi <= psis[0] or worse_ok)
        event = 0
        if take:
            _copy3(step, move)
            counters[1] += 1
            counters[0] = 0
            _copy3(candidate, current)
            psis[0] = psi
            if psi < psis[1]:
                _copy3(candidate, best)
                psis[1] = psi
                best_transform[0] = x
                best_transform[1] = y
                best_transform[2] = candidate[2]
            event = _ACCEPTED
        else:
            counters[0] += 1
            if counters[0] >= stall_iterations:
                counters[0] = 0
                _copy3(best, current)
                psis[0] = psis[1]
                event = _STALLED
        if trace:
            candidates[k, 0] = x
            candidates[k, 1] = y
            candidates[k, 2] = candidate[2]
            candidate_psi[k] = psi
            accepted[k] = take
            best_history[k] = psis[1]
        k += 1
        if event:
            return k, event
    return k, 0
