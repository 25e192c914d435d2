"""Partial-map Monte Carlo localisation of a virtual run in map 2 (docs/design.md §5 step 3).

The virtual robot's scans of m1 (:mod:`mrslam_env.merge.virtual`) drive a particle filter
in m2 (Thrun et al., *Probabilistic Robotics*, §8.3), with the paper's sample-space
limitation and a measurement model for a *partial* map:

* **Initial particles** lie only near the skeleton of m2 (paper §3.2), within
  ``skeleton_radius`` of a skeleton cell, in FREE cells. A fraction takes its heading
  along the skeleton (either way — the virtual robot drives along m1's skeleton, which
  in the overlap runs where m2's does), the rest any heading. Many more particles are
  drawn for the first scan than are kept afterwards.
* **Motion update**: each particle is moved by the run's odometry plus Gaussian noise
  that grows with the motion.
* **Measurement model**: a likelihood field of m2 (Thrun et al. §6.4) tabulated per cell,
  ``p = (1 - z_rand) exp(-d² / 2 sigma²) + z_rand`` with ``d`` the distance to the
  nearest OCCUPIED cell (scipy EDT). A beam ending in UNKNOWN space or outside m2 carries
  little evidence: it gets ``max(unknown_likelihood, p)`` (``p`` still rewards ending
  right behind a mapped wall). Invalid (NaN) and no-return beams are skipped. A particle
  standing in an OCCUPIED cell is all but ruled out, one in UNKNOWN space penalised. The
  per-scan weight is ``exp(evidence_per_scan * mean log p)``: a mean over beams, so that
  the many correlated beams of one scan do not collapse the filter in one step.
* **Resampling**: low-variance resampling after the first scan and whenever the
  effective sample size drops below ``resample_threshold * N``; while not converged a few
  particles are re-drawn near the skeleton (the run may only enter the overlap later).
  How many are kept is KLD-sampling's bound (Fox, IJRR 2003): enough that, with
  probability ``1 - delta``, the Kullback-Leibler distance between the particles and the
  posterior is below ``kld_error``, given the ``k`` histogram bins the posterior occupies
  (:func:`kld_particle_count`). A spread-out filter keeps ``n_particles``; once it has
  gathered in a few poses it keeps a few hundred.
* **Convergence**: the particles are clustered in (x, y, theta)
  (:func:`particle_clusters`); the filter has converged when at most ``max_clusters``
  clusters hold ``converged_fraction`` of the weight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.merge.skeleton import SkeletonConfig, SkeletonGraph, free_space_graph
from mrslam_env.merge.virtual import VirtualRun
from mrslam_env.validation import check_fields, require

FloatArray = NDArray[np.float64]

__all__ = [
    "LocalizationMap",
    "MclConfig",
    "MclResult",
    "ParticleCluster",
    "beam_log_likelihoods",
    "kld_particle_count",
    "localize_in_map",
    "low_variance_resample",
    "particle_clusters",
    "predict_particles",
    "prepare_localization_map",
    "sample_near_skeleton",
    "scan_endpoints",
    "score_particles",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class MclConfig:
    """Partial-map MCL (module doc)."""

    n_particles: int = 1500
    """Most particles kept after a resampling (KLD-sampling picks the count, below)."""
    min_particles: int = 100
    """Fewest particles kept after a resampling (``n_particles`` if that is fewer)."""
    kld_error: float = 0.05
    """KLD-sampling's bound on the Kullback-Leibler distance between the particles and the
    posterior they stand for (Fox 2003, epsilon); 0 keeps ``n_particles`` always."""
    kld_quantile: float = 2.326
    """Upper standard normal quantile of KLD-sampling's confidence (z at 1 - delta = 0.99)."""
    kld_bin_size: float = 0.5
    """x, y size of the KLD-sampling histogram's bins, m."""
    kld_bin_angle: float = math.radians(10.0)
    """Heading size of the KLD-sampling histogram's bins, rad."""
    initial_particles: int = 10000
    """Particles drawn near the skeleton and weighed by the first scan."""
    skeleton_radius: float = 0.3
    """Initial particles lie within this distance of a skeleton cell, m."""
    aligned_heading_fraction: float = 0.6
    """Fraction of sampled particles heading along the skeleton (either way); the rest
    take any heading."""
    aligned_heading_std: float = 0.15
    """Std of the heading of aligned particles around the skeleton's direction, rad."""
    sigma_hit: float = 0.12
    """Std of the likelihood field around OCCUPIED cells, m."""
    z_rand: float = 0.05
    """Likelihood floor of a beam ending far from any wall in known space (0 < z < 1)."""
    unknown_likelihood: float = 0.3
    """Likelihood of a beam ending in UNKNOWN space or outside m2 (z_rand < u < 1)."""
    beams_per_scan: int = 60
    """At most this many valid beams of each scan are used (evenly spread)."""
    evidence_per_scan: float = 8.0
    """Multiplier of a scan's mean beam log-likelihood in the particle log-weight."""
    unknown_pose_penalty: float = 1.0
    """Log-weight penalty for a particle standing in UNKNOWN space or outside m2, per scan."""
    occupied_pose_penalty: float = 12.0
    """Log-weight penalty for a particle standing in an OCCUPIED cell, per scan."""
    motion_xy_noise: float = 0.03
    """Std of the motion noise in x and y per step, m."""
    motion_xy_noise_per_m: float = 0.1
    """Growth of the x, y motion noise per metre driven, m/m."""
    motion_theta_noise: float = 0.02
    """Std of the heading motion noise per step, rad."""
    motion_theta_noise_per_rad: float = 0.1
    """Growth of the heading motion noise per radian turned, rad/rad."""
    resample_threshold: float = 0.5
    """Resample when the effective sample size drops below this fraction of N."""
    injection_fraction: float = 0.05
    """Fraction of particles re-drawn near the skeleton after each resampling while not
    converged."""
    cluster_radius: float = 0.5
    """x, y radius of a particle cluster, m."""
    cluster_angle: float = 0.3
    """Heading half-width of a particle cluster, rad."""
    max_clusters: int = 5
    """Convergence allows at most this many clusters; also the most clusters reported."""
    converged_fraction: float = 0.8
    """Weight fraction the clusters must hold for convergence."""
    min_cluster_weight: float = 0.03
    """Clusters lighter than this weight fraction are not reported."""
    skeleton: SkeletonConfig = field(default_factory=SkeletonConfig)
    """How the skeleton of m2 is built when not given."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        fractions = (
            "aligned_heading_fraction",
            "resample_threshold",
            "injection_fraction",
            "converged_fraction",
            "min_cluster_weight",
        )
        check_fields(
            self,
            positive=(
                "sigma_hit",
                "evidence_per_scan",
                "cluster_radius",
                "cluster_angle",
                "z_rand",
                "unknown_likelihood",
                "kld_quantile",
                "kld_bin_size",
                "kld_bin_angle",
            ),
            non_negative=(
                "kld_error",
                "skeleton_radius",
                "aligned_heading_std",
                "motion_xy_noise",
                "motion_xy_noise_per_m",
                "motion_theta_noise",
                "motion_theta_noise_per_rad",
                "unknown_pose_penalty",
                "occupied_pose_penalty",
                *fractions,
            ),
            counts=(
                "n_particles",
                "min_particles",
                "initial_particles",
                "beams_per_scan",
                "max_clusters",
            ),
        )
        for attr in fractions:
            value = getattr(self, attr)
            require(name, attr, value, value <= 1, "in [0, 1]")
        require(name, "z_rand", self.z_rand, self.z_rand < 1, "in (0, 1)")
        unknown = self.unknown_likelihood
        require(
            name,
            "unknown_likelihood",
            unknown,
            self.z_rand < unknown < 1,
            f"in (z_rand={self.z_rand}, 1)",
        )
        skeleton = self.skeleton
        require(
            name, "skeleton", skeleton, isinstance(skeleton, SkeletonConfig), "a SkeletonConfig"
        )


@dataclass(frozen=True, slots=True)
class LocalizationMap:
    """Map 2 prepared for MCL: everything that does not depend on the run.

    Attributes
    ----------
    grid : GridMap
        Map 2.
    beam_log_likelihood : ndarray of float32, shape (rows, cols)
        Log-likelihood of a beam ending in each cell (module doc).
    pose_log_penalty : ndarray of float32, shape (rows, cols)
        Log-weight added for a particle standing in each cell (0 for FREE).
    unknown_log_likelihood : float
        Log-likelihood of a beam ending outside the grid.
    sample_cells : ndarray of int64, shape (S, 2)
        Skeleton cells ``(row, col)`` to sample particles near (all FREE cells when the
        skeleton is empty).
    sample_headings : ndarray of float64, shape (S,)
        Skeleton direction at each sample cell, radians (mod pi); NaN where unknown.
    free : ndarray of bool, shape (rows, cols)
        FREE cells of m2.
    """

    grid: GridMap
    beam_log_likelihood: NDArray[np.float32]
    pose_log_penalty: NDArray[np.float32]
    unknown_log_likelihood: float
    sample_cells: NDArray[np.int64]
    sample_headings: FloatArray
    free: NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class ParticleCluster:
    """A cluster of particles: one pose hypothesis of the virtual robot in m2.

    Attributes
    ----------
    pose : ndarray of float64, shape (3,)
        Weighted mean pose in m2 (circular mean heading).
    weight : float
        Fraction of the total particle weight in the cluster.
    count : int
        Number of particles.
    spread : ndarray of float64, shape (2,)
        Weighted RMS distance to the mean (m) and RMS heading deviation (rad).
    """

    pose: FloatArray
    weight: float
    count: int
    spread: FloatArray


@dataclass(frozen=True, slots=True)
class MclResult:
    """Outcome of :func:`localize_in_map`.

    Attributes
    ----------
    particles : ndarray of float64, shape (N, 3)
        Final particles in m2 at the run's last pose.
    weights : ndarray of float64, shape (N,)
        Normalised weights.
    converged : bool
        Whether the particles converged (module doc) at some scan of the run.
    converged_at : int
        Index of the first scan after which they had converged, -1 if never.
    clusters : list of ParticleCluster
        Final clusters, heaviest first.
    mean_log_likelihood : float
        Weighted mean over particles of the last scan's mean beam log-likelihood.
    history : list of ndarray, shape (N, 3)
        Particles after each scan's update (only with ``trace=True``).
    """

    particles: FloatArray
    weights: FloatArray
    converged: bool
    converged_at: int
    clusters: list[ParticleCluster]
    mean_log_likelihood: float
    history: list[FloatArray] = field(default_factory=list)


def beam_log_likelihoods(grid: GridMap, config: MclConfig) -> NDArray[np.float32]:
    """Per-cell log-likelihood of a beam ending there (the likelihood field, module doc).

    Returns
    -------
    ndarray of float32, shape grid.shape
    """
    occupied = grid.occupied
    if occupied.any():
        distance = ndimage.distance_transform_edt(~occupied) * grid.resolution
        field_value = np.exp(-0.5 * (distance / config.sigma_hit) ** 2)
    else:
        field_value = np.zeros(grid.shape)
    likelihood = (1.0 - config.z_rand) * field_value + config.z_rand
    likelihood = np.where(
        grid.unknown, np.maximum(likelihood, config.unknown_likelihood), likelihood
    )
    return np.log(likelihood).astype(np.float32)


def _skeleton_headings(graph: SkeletonGraph, shape: tuple[int, int]) -> FloatArray:
    """Direction (radians, mod pi) of the skeleton at each of its cells, NaN elsewhere."""
    heading = np.full(shape, np.nan)
    for edge in graph.edges:
        cells = edge.cells
        if len(cells) < 3:
            continue
        k = np.arange(len(cells))
        ahead = cells[np.minimum(k + 4, len(cells) - 1)]
        behind = cells[np.maximum(k - 4, 0)]
        d = (ahead - behind).astype(np.float64)
        heading[cells[:, 0], cells[:, 1]] = np.arctan2(d[:, 0], d[:, 1])
    return heading


def prepare_localization_map(
    m2: GridMap, *, config: MclConfig, skeleton: SkeletonGraph | None = None
) -> LocalizationMap:
    """Precompute the likelihood field, pose penalties and skeleton samples of m2.

    Parameters
    ----------
    m2 : GridMap
        The map to localise in.
    config : MclConfig
        Model parameters.
    skeleton : SkeletonGraph, optional
        Skeleton graph of m2; built with ``config.skeleton`` when omitted.

    Raises
    ------
    ValueError
        If m2 has no FREE cell.
    """
    free = m2.free
    if not free.any():
        raise ValueError("map 2 has no free space to localise in")
    graph = skeleton if skeleton is not None else free_space_graph(m2, config.skeleton)
    if graph.skeleton.shape != m2.shape:
        raise ValueError(
            f"skeleton shape {graph.skeleton.shape} does not match map 2 shape {m2.shape}"
        )
    sample_cells = np.argwhere(graph.skeleton)
    headings = _skeleton_headings(graph, m2.shape)
    if len(sample_cells) == 0:
        sample_cells = np.argwhere(free)
    penalty = np.where(
        m2.cells == FREE,
        0.0,
        np.where(m2.cells == OCCUPIED, -config.occupied_pose_penalty, -config.unknown_pose_penalty),
    ).astype(np.float32)
    return LocalizationMap(
        grid=m2,
        beam_log_likelihood=beam_log_likelihoods(m2, config),
        pose_log_penalty=penalty,
        unknown_log_likelihood=float(np.log(config.unknown_likelihood)),
        sample_cells=sample_cells.astype(np.int64),
        sample_headings=headings[sample_cells[:, 0], sample_cells[:, 1]],
        free=free,
    )


def sample_near_skeleton(
    prepared: LocalizationMap, count: int, config: MclConfig, rng: np.random.Generator
) -> FloatArray:
    """Particles (count, 3) in FREE cells within ``skeleton_radius`` of the skeleton of m2
    (the paper's sample-space limitation), headings along the skeleton or uniform.

    The random draws are made here, in a fixed order; :func:`_place_samples` (numba) turns
    them into particles with the same float operations as numpy would."""
    grid = prepared.grid
    out = np.empty((0, 3))
    attempts = 0
    while len(out) < count and attempts < 20:
        attempts += 1
        n = count - len(out) + 16  # the cells that miss FREE space are made up next round
        pick = rng.integers(0, len(prepared.sample_cells), size=n)
        unit_radius = rng.random(n)
        angle = rng.uniform(-np.pi, np.pi, n)
        align_draw = rng.random(n)
        skeleton_heading = prepared.sample_headings[pick]
        aligned = (align_draw < config.aligned_heading_fraction) & np.isfinite(skeleton_heading)
        heading = rng.uniform(-np.pi, np.pi, n)
        flip_draw = rng.random(n)
        noise = rng.normal(size=int(aligned.sum()))
        fresh = _place_samples(
            prepared.sample_cells,
            pick,
            unit_radius,
            angle,
            aligned,
            skeleton_heading,
            heading,
            flip_draw,
            noise,
            prepared.free,
            float(grid.origin[0]),
            float(grid.origin[1]),
            float(grid.resolution),
            float(config.skeleton_radius),
            float(config.aligned_heading_std),
        )
        out = np.vstack([out, fresh])
    if len(out) < count:  # the skeleton is all but enclosed by non-free cells
        free_cells = np.argwhere(prepared.free)
        pick = rng.integers(0, len(free_cells), size=count - len(out))
        points = grid.cell_to_world(free_cells[pick])
        fill = np.column_stack([points, rng.uniform(-np.pi, np.pi, len(pick))])
        out = np.vstack([out, fill])
    return out[:count]


@numba.njit(cache=True)
def _place_samples(
    sample_cells: NDArray[np.int64],
    pick: NDArray[np.int64],
    unit_radius: FloatArray,
    angle: FloatArray,
    aligned: NDArray[np.bool_],
    skeleton_heading: FloatArray,
    heading: FloatArray,
    flip_draw: FloatArray,
    noise: FloatArray,
    free: NDArray[np.bool_],
    origin_x: float,
    origin_y: float,
    resolution: float,
    skeleton_radius: float,
    heading_std: float,
) -> FloatArray:
    """The particles of one round of :func:`sample_near_skeleton` that land in FREE cells:
    a point at ``skeleton_radius * sqrt(unit_radius)`` and ``angle`` from the centre of
    the picked skeleton cell; the aligned ones (in order, one ``noise`` each) head along
    the skeleton, turned by pi where ``flip_draw >= 0.5``, the others ``heading``."""
    rows, cols = free.shape
    n = pick.shape[0]
    kept = np.empty((n, 3))
    count = 0
    next_noise = 0
    for i in range(n):
        cell = pick[i]
        centre_x = origin_x + (sample_cells[cell, 1] + 0.5) * resolution
        centre_y = origin_y + (sample_cells[cell, 0] + 0.5) * resolution
        radius = skeleton_radius * math.sqrt(unit_radius[i])
        x = centre_x + radius * math.cos(angle[i])
        y = centre_y + radius * math.sin(angle[i])
        theta = heading[i]
        if aligned[i]:
            flip = 0.0 if flip_draw[i] < 0.5 else math.pi
            theta = skeleton_heading[i] + flip + heading_std * noise[next_noise]
            next_noise += 1
        ix = math.floor((x - origin_x) / resolution)
        iy = math.floor((y - origin_y) / resolution)
        if 0 <= iy < rows and 0 <= ix < cols and free[iy, ix]:
            kept[count, 0] = x
            kept[count, 1] = y
            kept[count, 2] = _wrap(theta)
            count += 1
    return kept[:count].copy()


def scan_endpoints(run: VirtualRun, index: int, beams_per_scan: int) -> FloatArray:
    """Endpoints (M, 2) of scan ``index``'s usable beams in the robot frame, metres.

    Usable: valid (not NaN) and a return (shorter than ``max_range``); at most
    ``beams_per_scan`` of them, evenly spread over the scan.
    """
    ranges = run.ranges[index]
    usable = np.flatnonzero(np.isfinite(ranges) & (ranges < run.max_range))
    if len(usable) > beams_per_scan:
        usable = usable[np.linspace(0, len(usable) - 1, beams_per_scan).round().astype(np.int64)]
    r, a = ranges[usable], run.beam_angles[usable]
    return np.column_stack([r * np.cos(a), r * np.sin(a)])


@numba.njit(cache=True)
def _score_particles(
    particles: FloatArray,
    endpoints: FloatArray,
    table: NDArray[np.float32],
    penalty: NDArray[np.float32],
    outside: float,
    origin_x: float,
    origin_y: float,
    resolution: float,
    mean_log: FloatArray,
    pose_log: FloatArray,
) -> None:
    rows, cols = table.shape
    inv = 1.0 / resolution
    m = endpoints.shape[0]
    for p in range(particles.shape[0]):
        x, y, th = particles[p, 0], particles[p, 1], particles[p, 2]
        ix = math.floor((x - origin_x) * inv)
        iy = math.floor((y - origin_y) * inv)
        if 0 <= iy < rows and 0 <= ix < cols:
            pose_log[p] = penalty[iy, ix]
        else:
            pose_log[p] = -1.0e9  # replaced by the caller's unknown penalty
        c, s = math.cos(th), math.sin(th)
        total = 0.0
        for j in range(m):
            ex = x + c * endpoints[j, 0] - s * endpoints[j, 1]
            ey = y + s * endpoints[j, 0] + c * endpoints[j, 1]
            jx = math.floor((ex - origin_x) * inv)
            jy = math.floor((ey - origin_y) * inv)
            if 0 <= jy < rows and 0 <= jx < cols:
                total += table[jy, jx]
            else:
                total += outside
        mean_log[p] = total / m if m > 0 else 0.0


def score_particles(
    prepared: LocalizationMap, particles: FloatArray, endpoints: FloatArray, config: MclConfig
) -> tuple[FloatArray, FloatArray]:
    """Measurement model for all particles × beams (numba kernel).

    Parameters
    ----------
    prepared : LocalizationMap
        Map 2's tables.
    particles : ndarray, shape (N, 3)
        Poses in m2.
    endpoints : ndarray, shape (M, 2)
        Beam endpoints in the robot frame (:func:`scan_endpoints`).
    config : MclConfig
        Penalties.

    Returns
    -------
    mean_log : ndarray, shape (N,)
        Mean beam log-likelihood per particle (0 when M = 0).
    pose_log : ndarray, shape (N,)
        Log-weight penalty of where each particle stands.
    """
    grid = prepared.grid
    n = len(particles)
    mean_log = np.empty(n)
    pose_log = np.empty(n)
    _score_particles(
        np.ascontiguousarray(particles, dtype=np.float64),
        np.ascontiguousarray(endpoints, dtype=np.float64),
        prepared.beam_log_likelihood,
        prepared.pose_log_penalty,
        prepared.unknown_log_likelihood,
        grid.origin[0],
        grid.origin[1],
        grid.resolution,
        mean_log,
        pose_log,
    )
    pose_log[pose_log < -1.0e8] = -config.unknown_pose_penalty
    return mean_log, pose_log


def predict_particles(
    particles: FloatArray, odometry: FloatArray, config: MclConfig, rng: np.random.Generator
) -> FloatArray:
    """Motion update: compose each particle with the odometry (3,) plus noise."""
    n = len(particles)
    distance = float(np.hypot(odometry[0], odometry[1]))
    xy_std = config.motion_xy_noise + config.motion_xy_noise_per_m * distance
    theta_std = config.motion_theta_noise + config.motion_theta_noise_per_rad * abs(odometry[2])
    xy_noise = rng.normal(size=(n, 2))
    theta_noise = rng.normal(size=n)
    return _move_particles(
        np.ascontiguousarray(particles, dtype=np.float64),
        np.asarray(odometry, dtype=np.float64),
        xy_std,
        theta_std,
        xy_noise,
        theta_noise,
    )


@numba.njit(cache=True)
def _move_particles(
    particles: FloatArray,
    odometry: FloatArray,
    xy_std: float,
    theta_std: float,
    xy_noise: FloatArray,
    theta_noise: FloatArray,
) -> FloatArray:
    """``compose(particles, odometry + noise)`` with the float operations of
    :func:`~mrslam_env.geometry.compose`, bit for bit."""
    out = np.empty((particles.shape[0], 3))
    for i in range(particles.shape[0]):
        bx = odometry[0] + xy_std * xy_noise[i, 0]
        by = odometry[1] + xy_std * xy_noise[i, 1]
        bt = odometry[2] + theta_std * theta_noise[i]
        c, s = math.cos(particles[i, 2]), math.sin(particles[i, 2])
        out[i, 0] = particles[i, 0] + c * bx - s * by
        out[i, 1] = particles[i, 1] + s * bx + c * by
        out[i, 2] = _wrap(particles[i, 2] + bt)
    return out


def low_variance_resample(
    weights: FloatArray, count: int, rng: np.random.Generator
) -> NDArray[np.int64]:
    """Indices (count,) drawn by low-variance (systematic) resampling of normalised weights
    (Thrun et al., Table 4.4)."""
    weights = np.ascontiguousarray(weights, dtype=np.float64)
    if weights.size == 0:  # the kernel reads weights[-1] without bounds checks
        raise ValueError("low_variance_resample: no weights to resample from")
    return _low_variance_indices(weights, count, rng.random())


@numba.njit(cache=True)
def _low_variance_indices(weights: FloatArray, count: int, start: float) -> NDArray[np.int64]:
    """The loop of :func:`low_variance_resample`, with numpy's float operations: the
    running sum (the last set to 1), the positions ``(start + k) / count`` and for each
    the first index whose running sum reaches it (``searchsorted``, side left)."""
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    out = np.empty(count, dtype=np.int64)
    index = 0
    for k in range(count):
        position = (start + k) / count
        while cumulative[index] < position:
            index += 1
        out[k] = index
    return out


def kld_particle_count(particles: FloatArray, config: MclConfig) -> int:
    """How many particles KLD-sampling keeps (Fox, IJRR 2003, eq. 11): with ``k`` the
    number of bins of a (``kld_bin_size``, ``kld_bin_size``, ``kld_bin_angle``) histogram
    the particles occupy, ``(k - 1) / (2 epsilon) (1 - a + sqrt(a) z)^3`` with
    ``a = 2 / (9 (k - 1))``, ``epsilon = kld_error`` and ``z = kld_quantile``; clipped to
    ``[min_particles, n_particles]`` (``n_particles`` wins). ``kld_error = 0`` gives
    ``n_particles``.

    ``particles`` is a resampling at the largest count: ``k`` counted on it is in practice
    at least what the smaller set occupies (not guaranteed: the smaller set is drawn
    anew), so the count errs on the large side.
    """
    if config.kld_error == 0:
        return config.n_particles
    k = _occupied_bins(particles, config.kld_bin_size, config.kld_bin_angle)
    bound = 0.0
    if k > 1:
        a = 2.0 / (9.0 * (k - 1))
        z = config.kld_quantile
        bound = (k - 1) / (2.0 * config.kld_error) * (1.0 - a + math.sqrt(a) * z) ** 3
    return int(min(max(math.ceil(bound), config.min_particles), config.n_particles))


@numba.njit(cache=True)
def _occupied_bins(particles: FloatArray, size: float, angle: float) -> int:
    """Number of distinct (size, size, angle) histogram bins the particles fall in."""
    n = particles.shape[0]
    key = np.empty(n, dtype=np.int64)
    bins = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        bins[i, 0] = math.floor(particles[i, 0] / size)
        bins[i, 1] = math.floor(particles[i, 1] / size)
        bins[i, 2] = math.floor((particles[i, 2] + math.pi) / angle)
    if n:
        # Packed 21 bits each, counted from the lowest bin: exact while the particles
        # span fewer than 2**21 bins a dimension (1,000 km at 0.5 m).
        low_x, low_y, low_t = bins[:, 0].min(), bins[:, 1].min(), bins[:, 2].min()
        for i in range(n):
            bx, by, bt = bins[i, 0] - low_x, bins[i, 1] - low_y, bins[i, 2] - low_t
            if bx >= 1 << 21 or by >= 1 << 21 or bt >= 1 << 21:
                raise ValueError("KLD bins: the particles span more than 2**21 bins")
            key[i] = (bx << 42) | (by << 21) | bt
    key.sort()
    distinct = 1 if n else 0
    for i in range(1, n):
        if key[i] != key[i - 1]:
            distinct += 1
    return distinct


def particle_clusters(
    particles: FloatArray,
    weights: FloatArray,
    *,
    radius: float,
    angle: float,
    max_clusters: int,
    min_weight: float = 0.0,
) -> list[ParticleCluster]:
    """Greedy mean-shift clustering of particles in (x, y, theta).

    The heaviest cell of a (radius, radius, angle) histogram seeds a cluster; its centre
    moves to the weighted mean of the particles within ``radius`` and ``angle`` (three
    mean-shift steps); those particles form the cluster and are removed. Repeats up to
    ``max_clusters`` times while the remaining weight is at least ``min_weight``.

    Returns
    -------
    list of ParticleCluster
        Heaviest first; weights are fractions of the total weight.
    """
    particles = np.ascontiguousarray(particles, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    total = float(weights.sum())
    if len(particles) == 0 or total <= 0:
        return []
    weights = np.ascontiguousarray(weights / total)
    bins = np.column_stack(
        [
            np.floor(particles[:, 0] / radius),
            np.floor(particles[:, 1] / radius),
            np.floor((particles[:, 2] + np.pi) / angle),
        ]
    ).astype(np.int64)
    bins -= bins.min(axis=0)
    span = bins.max(axis=0) + 1
    key = (bins[:, 0] * span[1] + bins[:, 1]) * span[2] + bins[:, 2]
    bin_index = _ranks(key, int(span[0] * span[1] * span[2]))
    poses, found = _cluster_loop(
        particles, weights, bin_index, radius, angle, max_clusters, min_weight
    )
    clusters = [
        ParticleCluster(poses[k].copy(), float(w), int(n), np.array([xy, turn]))
        for k, (w, n, xy, turn) in enumerate(found)
    ]
    clusters.sort(key=lambda cluster: -cluster.weight)
    return clusters


_TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, inline="always")
def _wrap(angle: float) -> float:
    """:func:`~mrslam_env.geometry.wrap_angle` of one angle, bit for bit (numba's float
    ``%`` and numpy's ``mod`` both take the sign of the divisor)."""
    return math.pi - (math.pi - angle) % _TWO_PI


@numba.njit(cache=True)
def _within_kernel(
    particles: FloatArray,
    centre_x: float,
    centre_y: float,
    centre_theta: float,
    radius_squared: float,
    angle: float,
    among: NDArray[np.bool_],
) -> NDArray[np.bool_]:
    """The particles of ``among`` within ``sqrt(radius_squared)`` (x, y) and ``angle``
    (heading) of the centre."""
    out = np.empty(particles.shape[0], dtype=np.bool_)
    for i in range(particles.shape[0]):
        dx = particles[i, 0] - centre_x
        dy = particles[i, 1] - centre_y
        out[i] = (
            among[i]
            and (dx * dx + dy * dy <= radius_squared)
            and (abs(_wrap(particles[i, 2] - centre_theta)) <= angle)
        )
    return out


@numba.njit(cache=True, error_model="numpy")
def _weighted_mean_pose(
    particles: FloatArray, weights: FloatArray, members: NDArray[np.bool_]
) -> tuple[float, float, float]:
    """:func:`~mrslam_env.geometry.mean_pose` of the members (weights normalised over
    them first; headings by their unit vectors), summed in index order."""
    total = 0.0
    for i in range(particles.shape[0]):
        if members[i]:
            total += weights[i]
    x = y = sin_sum = cos_sum = 0.0
    for i in range(particles.shape[0]):
        if members[i]:
            w = weights[i] / total
            x += w * particles[i, 0]
            y += w * particles[i, 1]
            sin_sum += w * math.sin(particles[i, 2])
            cos_sum += w * math.cos(particles[i, 2])
    return x, y, math.atan2(sin_sum, cos_sum)


@numba.njit(cache=True, error_model="numpy")
def _cluster_loop(
    particles: FloatArray,
    weights: FloatArray,
    bin_index: NDArray[np.int64],
    radius: float,
    angle: float,
    max_clusters: int,
    min_weight: float,
) -> tuple[FloatArray, FloatArray]:
    """The greedy mean shift of :func:`particle_clusters` on normalised weights: the
    clusters' poses (K, 3) and their weight, particle count and spreads (K, 4), in the
    order found."""
    n = particles.shape[0]
    remaining = np.ones(n, dtype=np.bool_)
    poses = np.empty((max_clusters, 3))
    found = np.empty((max_clusters, 4))
    count = 0
    while count < max_clusters:
        left = 0.0
        for i in range(n):
            if remaining[i]:
                left += weights[i]
        if left <= 0 or left < min_weight:
            break
        members = _heaviest_bin_members(bin_index, weights, remaining)
        x, y, theta = _weighted_mean_pose(particles, weights, members)
        for _ in range(3):
            near = _within_kernel(particles, x, y, theta, radius * radius, angle, remaining)
            if not near.any():
                break
            members = near
            x, y, theta = _weighted_mean_pose(particles, weights, members)
        total = 0.0
        size = 0
        offset_sum = 0.0
        turn_sum = 0.0
        for i in range(n):
            if members[i]:
                dx, dy = particles[i, 0] - x, particles[i, 1] - y
                turn = _wrap(particles[i, 2] - theta)
                total += weights[i]
                size += 1
                offset_sum += weights[i] * (dx * dx + dy * dy)
                turn_sum += weights[i] * turn * turn
                remaining[i] = False
        if total < min_weight:
            break  # seeds come heaviest bin first: what is left is scattered
        poses[count, 0], poses[count, 1], poses[count, 2] = x, y, theta
        found[count, 0], found[count, 1] = total, size
        found[count, 2] = math.sqrt(offset_sum / total)
        found[count, 3] = math.sqrt(turn_sum / total)
        count += 1
    return poses[:count], found[:count]


_DENSE_KEYS = 4_000_000
"""Above this many possible bin keys, :func:`_ranks` sorts instead of counting."""


def _ranks(key: NDArray[np.int64], key_count: int) -> NDArray[np.int64]:
    """``np.unique(key, return_inverse=True)[1]`` for keys in ``[0, key_count)``: each
    key's rank among the distinct keys (by counting when the key range is small)."""
    if key_count > _DENSE_KEYS:
        return np.unique(key, return_inverse=True)[1].astype(np.int64)
    return _dense_ranks(key, key_count)


@numba.njit(cache=True)
def _dense_ranks(key: NDArray[np.int64], key_count: int) -> NDArray[np.int64]:
    rank = np.zeros(key_count, dtype=np.int64)
    for i in range(key.shape[0]):
        rank[key[i]] = 1
    distinct = 0
    for k in range(key_count):
        if rank[k]:
            rank[k] = distinct
            distinct += 1
    out = np.empty(key.shape[0], dtype=np.int64)
    for i in range(key.shape[0]):
        out[i] = rank[key[i]]
    return out


@numba.njit(cache=True)
def _heaviest_bin_members(
    bin_index: NDArray[np.int64], weights: FloatArray, remaining: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """The remaining particles of the bin whose remaining weight is the largest (the
    first such bin on a tie): ``np.bincount`` then ``np.argmax``, summed in the same
    order."""
    bins = 0
    for i in range(bin_index.shape[0]):
        if remaining[i] and bin_index[i] + 1 > bins:
            bins = bin_index[i] + 1
    total = np.zeros(bins)
    for i in range(bin_index.shape[0]):
        if remaining[i]:
            total[bin_index[i]] += weights[i]
    best = 0
    for b in range(bins):
        if total[b] > total[best]:
            best = b
    out = np.empty(bin_index.shape[0], dtype=np.bool_)
    for i in range(bin_index.shape[0]):
        out[i] = remaining[i] and bin_index[i] == best
    return out


def localize_in_map(
    m2: GridMap | LocalizationMap,
    run: VirtualRun,
    *,
    config: MclConfig | None = None,
    rng: np.random.Generator,
    skeleton: SkeletonGraph | None = None,
    trace: bool = False,
) -> MclResult:
    """Partial-map MCL of a virtual run's scans in m2 (docs/design.md §5 step 3, paper §3–4.1).

    Parameters
    ----------
    m2 : GridMap or LocalizationMap
        The map to localise in, or its prepared tables (:func:`prepare_localization_map`,
        to share them between runs).
    run : VirtualRun
        Scans and odometry of the virtual robot.
    config : MclConfig, optional
        Filter parameters.
    rng : numpy.random.Generator
        Sampling, motion noise and resampling.
    skeleton : SkeletonGraph, optional
        Skeleton graph of m2 (when ``m2`` is a GridMap); built when omitted.
    trace : bool
        Keep the particles after every scan in :attr:`MclResult.history`.

    Returns
    -------
    MclResult
        Particles at the run's last pose.
    """
    config = config or MclConfig()
    prepared = (
        m2
        if isinstance(m2, LocalizationMap)
        else prepare_localization_map(m2, config=config, skeleton=skeleton)
    )
    n_scans = len(run.ranges)
    if n_scans == 0:
        raise ValueError("the virtual run has no scans")
    particles = sample_near_skeleton(prepared, config.initial_particles, config, rng)
    log_weights = np.zeros(len(particles))
    history: list[FloatArray] = []
    converged_at = -1
    mean_log = np.zeros(len(particles))
    clusters: list[ParticleCluster] = []
    for k in range(n_scans):
        if k > 0:
            particles = predict_particles(particles, run.odometry[k - 1], config, rng)
        endpoints = scan_endpoints(run, k, config.beams_per_scan)
        mean_log, pose_log = score_particles(prepared, particles, endpoints, config)
        log_weights = log_weights + config.evidence_per_scan * mean_log + pose_log
        log_weights -= log_weights.max()
        weights = np.exp(log_weights)
        weights /= weights.sum()
        last = k == n_scans - 1
        if converged_at < 0 or last:  # once converged, only the final clusters matter
            clusters = particle_clusters(
                particles,
                weights,
                radius=config.cluster_radius,
                angle=config.cluster_angle,
                max_clusters=config.max_clusters,
                min_weight=config.min_cluster_weight,
            )
            held = sum(cluster.weight for cluster in clusters)
            if held >= config.converged_fraction and converged_at < 0:
                converged_at = k
        effective = 1.0 / float(weights @ weights)
        if not last and (k == 0 or effective < config.resample_threshold * len(particles)):
            keep = low_variance_resample(weights, config.n_particles, rng)
            count = kld_particle_count(particles[keep], config)
            if count < len(keep):
                keep = low_variance_resample(weights, count, rng)
            particles = particles[keep]
            log_weights = np.zeros(len(particles))
            if converged_at < 0 and config.injection_fraction > 0:
                n_new = round(config.injection_fraction * len(particles))
                if n_new:
                    slots = rng.choice(len(particles), size=n_new, replace=False)
                    # Fresh particles start where the run is now: the paper's sample space.
                    particles[slots] = sample_near_skeleton(prepared, n_new, config, rng)
        if trace:
            history.append(particles.copy())
    weights = np.exp(log_weights - log_weights.max())
    weights /= weights.sum()
    return MclResult(
        particles=particles,
        weights=weights,
        converged=converged_at >= 0,
        converged_at=converged_at,
        clusters=clusters,
        mean_log_likelihood=float(weights @ mean_log) if len(mean_log) == len(weights) else 0.0,
        history=history,
    )
