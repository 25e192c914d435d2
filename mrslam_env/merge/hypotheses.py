"""Relative-pose hypotheses from virtual runs localised in map 2 (DESIGN §5 step 4).

While the virtual robot is at ``xi1`` in m1 (it knows this pose exactly) and a particle
cluster puts it at ``xi2`` in m2, the maps are related by ``T1 = T21 · T2`` (paper eq. 8),
so ``map1_from_map2 = T21 = T1 · T2⁻¹`` (eq. 9) — :func:`relative_pose`.

Every cluster of every run gives a hypothesis (:func:`cluster_hypotheses`). Runs are short
and many; a run that never passed through the overlap converges, if at all, somewhere
arbitrary, whereas all runs that did pass through it agree. :func:`pool_hypotheses`
therefore merges hypotheses that agree (compared by where they put a pivot point of m2,
so that a small rotation far from m2's origin is not mistaken for a large translation)
and counts the distinct runs that voted for each. Each pooled hypothesis is then checked
against **all** runs' scans (:func:`scan_agreement`): the fraction of beam endpoints that
land on m2's walls (support) and of those that land in m2's known free space far from any
wall (contradiction). The ranking combines both with the votes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from mrslam_env.geometry import compose, inverse, transform_points, wrap_angle
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.mcl import (
    MclConfig,
    MclResult,
    localize_in_map,
    prepare_localization_map,
)
from mrslam_env.merge.skeleton import SkeletonGraph, free_space_graph
from mrslam_env.merge.virtual import VirtualRobotConfig, VirtualRun, virtual_robot_runs

FloatArray = NDArray[np.float64]

__all__ = [
    "Hypothesis",
    "HypothesisConfig",
    "HypothesisSet",
    "cluster_hypotheses",
    "generate_hypotheses",
    "pool_hypotheses",
    "relative_pose",
    "scan_agreement",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class HypothesisConfig:
    """Pooling, checking and ranking of hypotheses."""

    translation_tolerance: float = 0.5
    """Hypotheses that put m2's pivot within this distance of each other agree, m."""
    rotation_tolerance: float = 0.15
    """... and whose rotations differ by at most this, rad."""
    max_hypotheses: int = 10
    """At most this many pooled hypotheses are returned."""
    hit_distance: float = 0.1
    """A beam endpoint this close to an OCCUPIED cell of m2 agrees, m."""
    miss_distance: float = 0.3
    """A beam endpoint in m2's FREE space farther than this from any OCCUPIED cell
    contradicts, m."""
    contradiction_weight: float = 5.0
    """The ranking score is ``support - contradiction_weight * contradicting fraction``
    (both over all valid returns of all runs). True transforms were seen with
    contradiction <= 0.012, aliased wrong ones up to 0.2 with high support."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        for attr in (
            "translation_tolerance",
            "rotation_tolerance",
            "hit_distance",
            "miss_distance",
        ):
            value = getattr(self, attr)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name}.{attr} must be a finite number > 0, got {value!r}")
        value = self.contradiction_weight
        if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
            raise ValueError(
                f"{name}.contradiction_weight must be a finite number >= 0, got {value!r}"
            )
        value = self.max_hypotheses
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
            raise ValueError(f"{name}.max_hypotheses must be an int >= 1, got {value!r}")
        if self.miss_distance < self.hit_distance:
            raise ValueError(
                f"{name}.miss_distance must be >= hit_distance ({self.hit_distance}), "
                f"got {self.miss_distance!r}"
            )


@dataclass(frozen=True, slots=True)
class Hypothesis:
    """A relative-pose hypothesis between the maps.

    Attributes
    ----------
    map1_from_map2 : ndarray of float64, shape (3,)
        The transform ``(x, y, theta)``, metres and radians.
    support : float
        Fraction of all valid beam returns of all runs that land on m2's walls under this
        transform (0..1; 0 until checked by :func:`scan_agreement`).
    contradiction : float
        Fraction of all valid beam returns that land in m2's known free space far from
        any wall (0..1).
    votes : int
        Number of distinct runs whose particles support it.
    weight : float
        Summed particle weight fraction over those runs.
    run_ids : tuple of int
        The runs that voted.
    spread : ndarray of float64, shape (2,)
        Weighted RMS position (m) and heading (rad) spread of the particles behind it.
    """

    map1_from_map2: FloatArray
    support: float = 0.0
    contradiction: float = 0.0
    votes: int = 1
    weight: float = 0.0
    run_ids: tuple[int, ...] = ()
    spread: FloatArray = field(default_factory=lambda: np.zeros(2))

    def score(self, contradiction_weight: float = 5.0) -> float:
        """Ranking score ``support - contradiction_weight * contradiction``."""
        return self.support - contradiction_weight * self.contradiction


@dataclass(frozen=True, slots=True)
class HypothesisSet:
    """Outcome of :func:`generate_hypotheses`.

    Attributes
    ----------
    hypotheses : list of Hypothesis
        Ranked, best first (possibly empty).
    runs : list of VirtualRun
        The virtual runs in m1.
    skeleton1, skeleton2 : SkeletonGraph
        Skeleton graphs of m1 and m2.
    timings : dict of str to float
        Seconds per stage.
    mcl_results : list of MclResult
        One per run, only with ``trace=True`` (with particle histories).
    """

    hypotheses: list[Hypothesis]
    runs: list[VirtualRun]
    skeleton1: SkeletonGraph
    skeleton2: SkeletonGraph
    timings: dict[str, float]
    mcl_results: list[MclResult] = field(default_factory=list)


def relative_pose(pose_in_map1: ArrayLike, pose_in_map2: ArrayLike) -> FloatArray:
    """``map1_from_map2 = T1 · T2⁻¹`` (paper eq. 9) from one pose seen in both maps.

    Parameters
    ----------
    pose_in_map1, pose_in_map2 : array_like, shape (3,) or (N, 3)
        The same robot pose ``xi1`` in m1's frame and ``xi2`` in m2's frame.
    """
    return compose(np.asarray(pose_in_map1, dtype=np.float64), inverse(pose_in_map2))


def cluster_hypotheses(
    mcl_result: MclResult, pose_in_map1: ArrayLike, run_id: int = 0
) -> list[Hypothesis]:
    """One hypothesis per particle cluster of ``mcl_result`` (DESIGN §5 step 4).

    Parameters
    ----------
    mcl_result : MclResult
        MCL of a run in m2; its clusters are poses ``xi2`` at the run's last scan.
    pose_in_map1 : array_like, shape (3,)
        The virtual robot's pose ``xi1`` in m1 at that scan.
    run_id : int
        Index of the run, recorded in the hypotheses.

    Returns
    -------
    list of Hypothesis
        Heaviest cluster first; ``weight`` is the cluster's particle weight fraction.
    """
    xi1 = np.asarray(pose_in_map1, dtype=np.float64)
    return [
        Hypothesis(
            map1_from_map2=relative_pose(xi1, cluster.pose),
            weight=cluster.weight,
            votes=1,
            run_ids=(run_id,),
            spread=cluster.spread,
        )
        for cluster in mcl_result.clusters
    ]


def _pivot_distance(a: FloatArray, b: FloatArray, pivot: FloatArray) -> float:
    pa = transform_points(a, pivot[None])[0]
    pb = transform_points(b, pivot[None])[0]
    return float(np.hypot(*(pa - pb)))


def pool_hypotheses(
    hypotheses: list[Hypothesis],
    translation_tol: float,
    rotation_tol: float,
    *,
    pivot: ArrayLike = (0.0, 0.0),
) -> list[Hypothesis]:
    """Merge agreeing hypotheses and rank them by votes, then weight.

    Two hypotheses agree when their rotations differ by at most ``rotation_tol`` and they
    put the ``pivot`` point of m2 within ``translation_tol`` of each other in m1. Greedy,
    heaviest first: each hypothesis joins the first pooled one it agrees with, whose
    transform becomes the weight-averaged transform (circular mean rotation).

    Parameters
    ----------
    hypotheses : list of Hypothesis
        From :func:`cluster_hypotheses` over several runs.
    translation_tol : float
        Metres.
    rotation_tol : float
        Radians.
    pivot : array_like, shape (2,)
        A point of m2 (its frame), e.g. the centre of its known area.

    Returns
    -------
    list of Hypothesis
        ``votes`` counts distinct runs, ``weight`` sums particle weight, ``support`` and
        ``contradiction`` keep the best member's; sorted by (votes, weight) descending.
    """
    pivot_point = np.asarray(pivot, dtype=np.float64).reshape(2)
    groups: list[list[Hypothesis]] = []
    centres: list[FloatArray] = []
    for hypothesis in sorted(hypotheses, key=lambda h: -h.weight):
        for index, centre in enumerate(centres):
            turn = abs(float(wrap_angle(hypothesis.map1_from_map2[2] - centre[2])))
            if turn <= rotation_tol and (
                _pivot_distance(hypothesis.map1_from_map2, centre, pivot_point) <= translation_tol
            ):
                groups[index].append(hypothesis)
                centres[index] = _mean_transform(groups[index], pivot_point)
                break
        else:
            groups.append([hypothesis])
            centres.append(np.asarray(hypothesis.map1_from_map2, dtype=np.float64).copy())
    pooled = []
    for group, centre in zip(groups, centres, strict=True):
        runs = tuple(sorted({run for h in group for run in h.run_ids}))
        weights = np.array([h.weight for h in group])
        spreads = np.array([h.spread for h in group])
        best = max(group, key=lambda h: h.support)
        pooled.append(
            Hypothesis(
                map1_from_map2=centre,
                support=best.support,
                contradiction=best.contradiction,
                votes=len(runs),
                weight=float(weights.sum()),
                run_ids=runs,
                spread=(weights @ spreads) / weights.sum()
                if weights.sum() > 0
                else spreads.mean(0),
            )
        )
    pooled.sort(key=lambda h: (-h.votes, -h.weight))
    return pooled


def _mean_transform(group: list[Hypothesis], pivot: FloatArray) -> FloatArray:
    """Weighted mean of transforms: circular mean rotation, and the translation that puts
    the pivot at the mean of where the members put it."""
    weights = np.array([max(h.weight, 1e-12) for h in group])
    weights = weights / weights.sum()
    transforms = np.array([h.map1_from_map2 for h in group])
    theta = math.atan2(
        float(weights @ np.sin(transforms[:, 2])), float(weights @ np.cos(transforms[:, 2]))
    )
    placed = np.array([transform_points(t, pivot[None])[0] for t in transforms])
    target = weights @ placed
    c, s = math.cos(theta), math.sin(theta)
    rotated = np.array([c * pivot[0] - s * pivot[1], s * pivot[0] + c * pivot[1]])
    return np.array([target[0] - rotated[0], target[1] - rotated[1], theta])


@numba.njit(cache=True)
def _agreement_counts(
    poses: FloatArray,
    ranges: FloatArray,
    angles: FloatArray,
    max_range: float,
    distance: NDArray[np.float32],
    cells: NDArray[np.int8],
    origin_x: float,
    origin_y: float,
    resolution: float,
    hit_distance: float,
    miss_distance: float,
) -> tuple[int, int, int]:
    """(valid returns, agreeing, contradicting) over scans at ``poses`` in m2."""
    rows, cols = distance.shape
    inv = 1.0 / resolution
    valid = 0
    agree = 0
    contra = 0
    for k in range(poses.shape[0]):
        x, y, th = poses[k, 0], poses[k, 1], poses[k, 2]
        for b in range(angles.shape[0]):
            r = ranges[k, b]
            if not (r < max_range):  # NaN or no return
                continue
            valid += 1
            a = th + angles[b]
            ex = x + r * math.cos(a)
            ey = y + r * math.sin(a)
            jx = math.floor((ex - origin_x) * inv)
            jy = math.floor((ey - origin_y) * inv)
            if jy < 0 or jy >= rows or jx < 0 or jx >= cols:
                continue
            d = distance[jy, jx]
            if d <= hit_distance:
                agree += 1
            elif cells[jy, jx] == 0 and d > miss_distance:
                contra += 1
    return valid, agree, contra


def scan_agreement(
    m2: GridMap,
    runs: list[VirtualRun],
    map1_from_map2: ArrayLike,
    *,
    hit_distance: float = 0.1,
    miss_distance: float = 0.3,
    occupied_distance: NDArray[np.float32] | None = None,
) -> tuple[float, float]:
    """How well all runs' scans fit m2 if ``map1_from_map2`` were true.

    Each run's poses are carried into m2 (``inverse(map1_from_map2) ∘ pose_in_map1``) and
    every valid return's endpoint is looked up in m2.

    Parameters
    ----------
    m2 : GridMap
        Map 2.
    runs : list of VirtualRun
        Runs in m1.
    map1_from_map2 : array_like, shape (3,)
        The hypothesis.
    hit_distance, miss_distance : float
        See :class:`HypothesisConfig`, metres.
    occupied_distance : ndarray of float32, shape m2.shape, optional
        Distance from each cell to the nearest OCCUPIED cell of m2 in metres (computed
        when omitted; pass it to check many hypotheses).

    Returns
    -------
    support : float
        Agreeing / valid returns (0 when there are none).
    contradiction : float
        Contradicting / valid returns.
    """
    if occupied_distance is None:
        occupied_distance = _occupied_distance(m2)
    map2_from_map1 = inverse(np.asarray(map1_from_map2, dtype=np.float64))
    valid = agree = contra = 0
    for run in runs:
        poses = compose(map2_from_map1, run.poses_in_map1)
        v, a, c = _agreement_counts(
            np.ascontiguousarray(poses),
            run.ranges,
            run.beam_angles,
            run.max_range,
            occupied_distance,
            m2.cells,
            m2.origin[0],
            m2.origin[1],
            m2.resolution,
            hit_distance,
            miss_distance,
        )
        valid, agree, contra = valid + v, agree + a, contra + c
    if valid == 0:
        return 0.0, 0.0
    return agree / valid, contra / valid


def _occupied_distance(m2: GridMap) -> NDArray[np.float32]:
    occupied = m2.occupied
    if not occupied.any():
        return np.full(m2.shape, np.inf, dtype=np.float32)
    return (ndimage.distance_transform_edt(~occupied) * m2.resolution).astype(np.float32)


def generate_hypotheses(
    m1: GridMap,
    m2: GridMap,
    *,
    virtual: VirtualRobotConfig | None = None,
    mcl: MclConfig | None = None,
    pooling: HypothesisConfig | None = None,
    rng: np.random.Generator,
    trace: bool = False,
) -> HypothesisSet:
    """Ranked ``map1_from_map2`` hypotheses by virtual robot motion (DESIGN §5 steps 1–4).

    Skeletons of both maps; many short virtual runs along m1's skeleton; partial-map MCL
    of each run in m2; one hypothesis per particle cluster (``T1 · T2⁻¹``); pooled and
    voted across runs; each pooled hypothesis checked against all runs' scans; ranked.

    Parameters
    ----------
    m1, m2 : GridMap
        The maps, with the same resolution (the caller resamples).
    virtual, mcl, pooling : optional
        Stage configurations (defaults if omitted).
    rng : numpy.random.Generator
        All randomness.
    trace : bool
        Keep each run's MCL result with particle histories.

    Returns
    -------
    HypothesisSet
        Hypotheses best first: sorted by ``support - contradiction_weight *
        contradiction``, ties by votes. Empty when no run could be made.

    Raises
    ------
    ValueError
        Different resolutions, or a map with no free space.
    """
    virtual = virtual or VirtualRobotConfig()
    mcl = mcl or MclConfig()
    pooling = pooling or HypothesisConfig()
    if not math.isclose(m1.resolution, m2.resolution, rel_tol=1e-6):
        raise ValueError(
            f"maps must have the same resolution, got {m1.resolution} m and {m2.resolution} m"
        )
    for name, grid in (("map 1", m1), ("map 2", m2)):
        if not grid.free.any():
            raise ValueError(f"{name} has no free space")
    timings: dict[str, float] = {}
    started = time.perf_counter()
    skeleton1 = free_space_graph(m1, virtual.skeleton)
    skeleton2 = free_space_graph(m2, mcl.skeleton)
    timings["skeleton"] = time.perf_counter() - started

    started = time.perf_counter()
    runs = virtual_robot_runs(m1, config=virtual, rng=rng, graph=skeleton1)
    timings["virtual_runs"] = time.perf_counter() - started

    started = time.perf_counter()
    prepared = prepare_localization_map(m2, config=mcl, skeleton=skeleton2)
    candidates: list[Hypothesis] = []
    results: list[MclResult] = []
    for run_id, run in enumerate(runs):
        result = localize_in_map(prepared, run, config=mcl, rng=rng, trace=trace)
        candidates.extend(cluster_hypotheses(result, run.poses_in_map1[-1], run_id))
        if trace:
            results.append(result)
    timings["mcl"] = time.perf_counter() - started

    started = time.perf_counter()
    pivot = m2.cell_to_world(np.argwhere(~m2.unknown).mean(axis=0))
    pooled = pool_hypotheses(
        candidates, pooling.translation_tolerance, pooling.rotation_tolerance, pivot=pivot
    )
    occupied_distance = _occupied_distance(m2)
    checked = []
    for hypothesis in pooled[: 3 * pooling.max_hypotheses]:
        support, contradiction = scan_agreement(
            m2,
            runs,
            hypothesis.map1_from_map2,
            hit_distance=pooling.hit_distance,
            miss_distance=pooling.miss_distance,
            occupied_distance=occupied_distance,
        )
        checked.append(replace(hypothesis, support=support, contradiction=contradiction))
    checked.sort(key=lambda h: (-h.score(pooling.contradiction_weight), -h.votes))
    timings["pooling"] = time.perf_counter() - started
    return HypothesisSet(
        hypotheses=checked[: pooling.max_hypotheses],
        runs=runs,
        skeleton1=skeleton1,
        skeleton2=skeleton2,
        timings=timings,
        mcl_results=results,
    )
