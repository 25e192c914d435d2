"""Relative-pose hypotheses from virtual runs localised in map 2 (docs/design.md §5 step 4).

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

A second, cheap proposal source, not in the paper: :func:`correlation_hypotheses` lines up
the two maps' wall orientations (:func:`relative_rotations`) and, for each such rotation,
scores every translation at once by FFT (:func:`placement_scores`). It finds small
overlaps that no short virtual run both crosses and converges on; being an exhaustive
search it also finds chance fits, so ``merge_maps`` accepts its placements under a stricter
overlap rule.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import fft as scipy_fft
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
from mrslam_env.validation import check_fields, require

FloatArray = NDArray[np.float64]

__all__ = [
    "CorrelationConfig",
    "Hypothesis",
    "HypothesisConfig",
    "HypothesisSet",
    "cluster_hypotheses",
    "correlation_hypotheses",
    "generate_hypotheses",
    "neighbour_placements",
    "placement_scores",
    "pool_hypotheses",
    "relative_pose",
    "relative_rotations",
    "scan_agreement",
    "wall_orientation_histogram",
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
    (both over all valid returns of all runs). True transforms contradict little; aliased
    wrong ones can contradict much while their support is high."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_fields(
            self,
            positive=(
                "translation_tolerance",
                "rotation_tolerance",
                "hit_distance",
                "miss_distance",
            ),
            non_negative=("contradiction_weight",),
            counts=("max_hypotheses",),
        )
        require(
            name,
            "miss_distance",
            self.miss_distance,
            self.miss_distance >= self.hit_distance,
            f">= hit_distance ({self.hit_distance})",
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
    """One hypothesis per particle cluster of ``mcl_result`` (docs/design.md §5 step 4).

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
    """Ranked ``map1_from_map2`` hypotheses by virtual robot motion (docs/design.md §5 steps 1–4).

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


# --- a second proposal source: wall correlation over the rotations the walls allow ----------


@dataclass(frozen=True, slots=True, kw_only=True)
class CorrelationConfig:
    """The correlation proposal source (:func:`correlation_hypotheses`).

    The virtual robot proposes a transform only when one of its short runs passes through
    the shared part *and* its particle filter converges there; on small overlaps in
    repetitive buildings that often fails although the true placement is plain to see. A
    coarse, exhaustive search over translations is cheap by FFT once the rotation is known,
    and the walls of a building tell the rotation up to their symmetry: the relative
    rotation lines up the two maps' histograms of wall orientation.
    """

    orientation_peaks: int = 2
    """Peaks of the wall-orientation cross-correlation (mod 180°) used; each gives two
    rotations, theta and theta + 180°. Two peaks cover rectilinear buildings (theta and
    theta + 90°)."""
    peak_separation: float = math.radians(10.0)
    """Two orientation peaks are at least this far apart, rad."""
    orientation_smoothing: float = 0.3
    """Standard deviation of the Gaussian smoothing of the walls before their orientation
    is measured, m. Thin rasterised walls at a slant read as staircases whose gradients
    lean towards the grid axes; a few cells of smoothing straighten them."""
    cell_factor: int = 2
    """The correlation grid is this many times coarser than the maps."""
    wall_sigma: float = 0.15
    """Width of the wall likelihood ``exp(-d² / 2 sigma²)`` around map 1's walls, m."""
    miss_distance: float = 0.3
    """A wall of one map on free space of the other farther than this from any of its
    walls contradicts, m."""
    contradiction_weight: float = 2.0
    """Score of a placement: wall likelihood summed over m2's walls, minus this weight
    times the contradictions (both directions), in coarse cells."""
    min_peak_distance: float = 1.0
    """Two kept placements of one rotation are at least this far apart (non-maximum
    suppression), m."""
    max_hypotheses: int = 4
    """At most this many placements are returned (best scores over all rotations)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=(
                "peak_separation",
                "orientation_smoothing",
                "wall_sigma",
                "miss_distance",
                "min_peak_distance",
            ),
            non_negative=("contradiction_weight",),
            counts=("orientation_peaks", "cell_factor", "max_hypotheses"),
        )


ORIENTATION_BINS = 180
"""Bins of the wall-orientation histogram over [0, 180°) (1° each)."""


def wall_orientation_histogram(
    grid: GridMap, smoothing: float = 0.3, bins: int = ORIENTATION_BINS
) -> FloatArray:
    """Histogram of wall orientations (mod 180°), weighted by gradient magnitude.

    The OCCUPIED mask is smoothed (Gaussian of standard deviation ``smoothing``, m) and
    differentiated (Sobel); each
    cell votes for the direction of its gradient, mod 180°, with the gradient's magnitude
    (linear interpolation between the two nearest bins).

    Returns
    -------
    ndarray of float64, shape (bins,)
        Bin ``k`` covers ``[k, k + 1) * 180° / bins``; sums to 1 (all zeros without walls).
    """
    sigma_cells = smoothing / grid.resolution
    occupied = ndimage.gaussian_filter(grid.occupied.astype(np.float64), sigma_cells)
    gy = ndimage.sobel(occupied, axis=0)
    gx = ndimage.sobel(occupied, axis=1)
    magnitude = np.hypot(gx, gy).ravel()
    keep = magnitude > 1e-3 * max(float(magnitude.max(initial=0.0)), 1e-12)
    if not keep.any():
        return np.zeros(bins)
    position = (np.arctan2(gy.ravel()[keep], gx.ravel()[keep]) % math.pi) * bins / math.pi
    lower = np.floor(position).astype(np.int64)
    upper_share = position - lower
    weights = magnitude[keep]
    histogram = np.bincount(lower % bins, weights * (1.0 - upper_share), minlength=bins)
    histogram += np.bincount((lower + 1) % bins, weights * upper_share, minlength=bins)
    return histogram / histogram.sum()


def relative_rotations(
    histogram1: FloatArray, histogram2: FloatArray, peaks: int, separation: float
) -> list[float]:
    """Rotations (rad) of map 2 that line its wall orientations up with map 1's.

    The circular cross-correlation ``c[k] = sum_j h1[j + k] h2[j]`` (mod 180°) is
    searched for its ``peaks`` highest local maxima at least ``separation`` apart (each
    refined by a parabola through its neighbours); each peak ``theta`` gives the two
    rotations ``theta`` and ``theta + pi``, wrapped to [-pi, pi).
    """
    bins = len(histogram1)
    spectrum = np.fft.rfft(histogram1) * np.conj(np.fft.rfft(histogram2))
    correlation = np.fft.irfft(spectrum, n=bins)
    bin_angle = math.pi / bins
    order = np.argsort(-correlation, kind="stable")
    chosen: list[float] = []
    for k in order:
        if len(chosen) >= peaks:
            break
        left, right = correlation[(k - 1) % bins], correlation[(k + 1) % bins]
        if correlation[k] < left or correlation[k] < right:
            continue
        curvature = left - 2.0 * correlation[k] + right
        offset = 0.5 * (left - right) / curvature if curvature < 0 else 0.0
        angle = (k + offset) * bin_angle
        if any(
            abs(float(wrap_angle(2.0 * (angle - other)))) < 2.0 * separation for other in chosen
        ):
            continue
        chosen.append(angle)
    return [float(wrap_angle(a + half)) for a in chosen for half in (0.0, math.pi)]


def _coarse_classes(
    points_free: FloatArray, points_occupied: FloatArray, resolution: float
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], FloatArray]:
    """Occupied and free masks of points binned on a grid of ``resolution`` (occupied
    wins a cell), and the grid's origin (x, y)."""
    everything = np.concatenate([points_free, points_occupied])
    origin = everything.min(axis=0) - 0.5 * resolution
    extent = np.floor((everything.max(axis=0) - origin) / resolution).astype(np.int64) + 1
    shape = (int(extent[1]), int(extent[0]))

    def mask(points: FloatArray) -> NDArray[np.bool_]:
        out = np.zeros(shape, dtype=bool)
        cells = np.floor((points - origin) / resolution).astype(np.int64)
        out[cells[:, 1], cells[:, 0]] = True
        return out

    occupied = mask(points_occupied)
    free = mask(points_free) & ~occupied
    return occupied, free, origin


def _far_from_walls(
    occupied: NDArray[np.bool_], free: NDArray[np.bool_], resolution: float, distance: float
) -> tuple[NDArray[np.bool_], FloatArray]:
    """Free cells farther than ``distance`` (m) from any occupied cell, and the distance
    (m) of every cell to the nearest occupied cell."""
    if occupied.any():
        to_wall = ndimage.distance_transform_edt(~occupied) * resolution
    else:
        to_wall = np.full(occupied.shape, np.inf)
    return free & (to_wall > distance), to_wall


def placement_scores(
    target1_spectrum: NDArray[np.complex128],
    walls1_spectrum: NDArray[np.complex128],
    walls2: NDArray[np.bool_],
    far2: NDArray[np.bool_],
    contradiction_weight: float,
    shape: tuple[int, int],
) -> FloatArray:
    """Score of every translation of map 2's rotated grid over map 1's, by FFT.

    ``score[s] = sum_p walls2[p] target1[p + s] - w * sum_p far2[p] walls1[p + s]`` for
    every shift ``s = (rows, cols)``, where ``target1`` is map 1's wall likelihood minus
    ``w`` on its free space far from walls, ``walls1`` its wall mask, ``walls2`` and
    ``far2`` map 2's wall mask and free-far-from-walls mask, ``w`` the
    ``contradiction_weight``. Out-of-grid cells count zero.

    Parameters
    ----------
    target1_spectrum, walls1_spectrum : ndarray of complex128
        ``scipy.fft.rfft2(target1, shape)`` and ``rfft2(walls1, shape)``.
    walls2, far2 : ndarray of bool, shape (rows2, cols2)
        Map 2's masks on the coarse grid, rotated.
    contradiction_weight : float
    shape : tuple of int
        FFT shape, at least map 1's grid plus map 2's in each axis (no wrap-around).

    Returns
    -------
    ndarray of float64, shape ``shape``
        ``score[s]`` at index ``s mod shape`` (negative shifts at the end of each axis).
    """
    spectrum = np.conj(scipy_fft.rfft2(walls2.astype(np.float64), shape)) * target1_spectrum
    spectrum -= contradiction_weight * (
        np.conj(scipy_fft.rfft2(far2.astype(np.float64), shape)) * walls1_spectrum
    )
    return np.asarray(scipy_fft.irfft2(spectrum, shape), dtype=np.float64)


def _local_maxima(score: FloatArray, radius_cells: int, count: int) -> list[tuple[int, int]]:
    """Up to ``count`` highest local maxima of ``score`` (cells), at least
    ``radius_cells`` apart (a maximum filter of that half-width)."""
    size = 2 * radius_cells + 1
    peaks = (score == ndimage.maximum_filter(score, size=size, mode="wrap")) & (score > 0)
    rows, cols = np.nonzero(peaks)
    order = np.argsort(-score[rows, cols], kind="stable")[:count]
    return [(int(rows[i]), int(cols[i])) for i in order]


def correlation_hypotheses(
    m1: GridMap,
    m2: GridMap,
    config: CorrelationConfig | None = None,
    *,
    rotations: list[float] | None = None,
) -> list[Hypothesis]:
    """``map1_from_map2`` placements by correlating walls (a proposal source besides the
    virtual robot).

    For each rotation from :func:`relative_rotations`, map 2's cells are rotated and
    binned on a grid ``cell_factor`` times coarser than the maps, and every translation is
    scored at once by FFT cross-correlation: the wall likelihood of map 1 summed over map
    2's walls, minus ``contradiction_weight`` times the walls of either map that fall on
    the other's free space far from its walls. The best local maxima over all rotations
    are returned. Deterministic.

    Parameters
    ----------
    m1, m2 : GridMap
        The maps, same resolution.
    config : CorrelationConfig, optional
    rotations : list of float, optional
        The rotations (rad) to try instead of those of :func:`relative_rotations` (e.g.
        the Hough spectrum's, :func:`~mrslam_env.merge.spectrum.hough_rotations`).

    Returns
    -------
    list of Hypothesis
        Best score first, at most ``max_hypotheses``; ``weight`` is the placement's score
        divided by the best one's, ``votes`` 0 (no virtual run voted). Empty when a map has
        no wall.
    """
    config = config or CorrelationConfig()
    if not math.isclose(m1.resolution, m2.resolution, rel_tol=1e-6):
        raise ValueError(
            f"maps must have the same resolution, got {m1.resolution} m and {m2.resolution} m"
        )
    if not (m1.occupied.any() and m2.occupied.any()):
        return []
    resolution = m1.resolution * config.cell_factor
    occupied1, free1, origin1 = _coarse_classes(
        m1.cell_to_world(np.argwhere(m1.free)).reshape(-1, 2),
        m1.cell_to_world(np.argwhere(m1.occupied)),
        resolution,
    )
    far1, to_wall1 = _far_from_walls(occupied1, free1, resolution, config.miss_distance)
    likelihood1 = np.exp(-0.5 * (to_wall1 / config.wall_sigma) ** 2)
    target1 = likelihood1 - config.contradiction_weight * far1
    free2 = m2.cell_to_world(np.argwhere(m2.free)).reshape(-1, 2)
    occupied2 = m2.cell_to_world(np.argwhere(m2.occupied))
    diagonal = math.ceil(math.hypot(*m2.shape) * m2.resolution / resolution) + 2
    shape = (
        int(scipy_fft.next_fast_len(occupied1.shape[0] + diagonal)),
        int(scipy_fft.next_fast_len(occupied1.shape[1] + diagonal)),
    )
    spectrum_target1 = scipy_fft.rfft2(target1, shape)
    spectrum_occupied1 = scipy_fft.rfft2(occupied1.astype(np.float64), shape)
    radius = max(1, round(config.min_peak_distance / resolution))
    found: list[tuple[float, FloatArray]] = []
    if rotations is None:
        histogram1 = wall_orientation_histogram(m1, config.orientation_smoothing)
        histogram2 = wall_orientation_histogram(m2, config.orientation_smoothing)
        rotations = relative_rotations(
            histogram1, histogram2, config.orientation_peaks, config.peak_separation
        )
    for theta in rotations:
        rotation = np.array([0.0, 0.0, theta])
        occupied2r, free2r, origin2 = _coarse_classes(
            transform_points(rotation, free2).reshape(-1, 2),
            transform_points(rotation, occupied2),
            resolution,
        )
        far2, _ = _far_from_walls(occupied2r, free2r, resolution, config.miss_distance)
        score = placement_scores(
            spectrum_target1,
            spectrum_occupied1,
            occupied2r,
            far2,
            config.contradiction_weight,
            shape,
        )
        for row, col in _local_maxima(score, radius, config.max_hypotheses):
            shift_row = row if row < shape[0] - diagonal else row - shape[0]
            shift_col = col if col < shape[1] - diagonal else col - shape[1]
            translation = origin1 - origin2 + resolution * np.array([shift_col, shift_row])
            found.append(
                (float(score[row, col]), np.array([translation[0], translation[1], theta]))
            )
    found.sort(key=lambda item: -item[0])
    if not found:
        return []
    best = found[0][0]
    return [
        Hypothesis(map1_from_map2=transform, weight=value / best, votes=0)
        for value, transform in found[: config.max_hypotheses]
    ]


def neighbour_placements(
    m1: GridMap,
    m2: GridMap,
    transform: ArrayLike,
    pivot: ArrayLike,
    config: CorrelationConfig | None = None,
    *,
    radius: float,
    separation: float,
    count: int,
) -> list[FloatArray]:
    """The best ``count`` other placements of map 2 near ``transform``: local maxima of the
    wall correlation (:func:`correlation_hypotheses`) at ``transform``'s rotation, about
    ``separation`` apart (m; the local-maximum window is ``separation`` rounded to the
    correlation's cells: 0.4 m for 0.5 m at 0.2 m cells) and putting ``pivot`` (a point
    of m2, its frame) at least ``separation`` and less than ``radius`` (m) from where
    ``transform`` puts it; best score first.

    Where a building repeats with a short period (a lattice of pillars, shelf aisles), the
    placement one period off may fit as well as the truth and overlap more, so it is the
    one proposed; the truth, with fewer walls in common, lies on the slope of its
    correlation peak and is suppressed by the default ``min_peak_distance``. Searching the
    neighbourhood at the finer ``separation`` shows it, and the merge then judges it as a
    rival.
    """
    if count <= 0:
        return []
    t = np.asarray(transform, dtype=np.float64)
    point = np.asarray(pivot, dtype=np.float64).reshape(1, 2)
    at = transform_points(t, point)[0]
    search = replace(
        config or CorrelationConfig(), min_peak_distance=separation, max_hypotheses=10**6
    )
    found = []
    for placement in correlation_hypotheses(m1, m2, search, rotations=[float(t[2])]):
        apart = float(np.hypot(*(transform_points(placement.map1_from_map2, point)[0] - at)))
        if separation <= apart < radius:
            found.append(placement.map1_from_map2)
            if len(found) >= count:
                break
    return found
