"""The virtual robot: simulated lidar runs along the skeleton of map 1 (docs/design.md §5 step 2).

A simulated robot drives along the skeleton of m1, heading along its path, and takes a
scan of m1 every ``step`` metres by exact ray casting in the grid; the odometry between
its poses is known exactly (the robot is virtual) unless noise is asked for. The scans
then drive Monte Carlo localisation in m2 (:mod:`mrslam_env.merge.mcl`).

The paper drives one long run; a run only localises while it passes through the part of
m1 that m2 also covers, so a small overlap is easily missed. Here
:func:`virtual_robot_runs` makes **many short runs** that start on different skeleton
branches spread over all of m1 (farthest-point selection of branch pieces), so that
whichever part of m1 overlaps m2, some run passes through it.

A beam of a virtual scan returns the distance to the first OCCUPIED cell it enters. If it
first enters an UNKNOWN cell, or leaves the grid, it is invalid (NaN): m1 does not know
what is there. A beam that crosses only FREE cells up to ``max_range`` returns
``max_range`` — a genuine "no return" seen through known free space.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import compose, inverse, wrap_angle
from mrslam_env.gridmap import OCCUPIED, UNKNOWN, GridMap
from mrslam_env.merge.skeleton import SkeletonConfig, SkeletonGraph, free_space_graph
from mrslam_env.slam.raycast import dda_start
from mrslam_env.validation import check_fields, require

FloatArray = NDArray[np.float64]

__all__ = [
    "VirtualRobotConfig",
    "VirtualRun",
    "odometry_between",
    "run_paths",
    "simulate_scan",
    "simulate_scans",
    "virtual_robot_runs",
]


_CORNER_TIE = 1e-9
"""Parametric distance (a fraction of the beam, so 6e-9 m at 6 m) within which a beam
counts as passing through a cell corner (:func:`_cast_beam`); rounding leaves ~1e-14."""


@numba.njit(cache=True)
def _cast_beam(
    cells: NDArray[np.int8],
    origin_x: float,
    origin_y: float,
    resolution: float,
    x: float,
    y: float,
    angle: float,
    max_range: float,
) -> float:
    """Range of one beam (see module doc): entry distance of the first OCCUPIED cell,
    NaN at the first UNKNOWN or out-of-grid cell, ``max_range`` otherwise."""
    rows, cols = cells.shape
    x1 = x + max_range * math.cos(angle)
    y1 = y + max_range * math.sin(angle)
    ix, iy, step_x, step_y, t_max_x, t_max_y, t_delta_x, t_delta_y, n_steps = dda_start(
        x, y, x1, y1, origin_x, origin_y, resolution
    )
    t_entry = 0.0
    for k in range(n_steps + 1):
        if k > 0:
            # A beam through a cell corner (t_max_x == t_max_y) enters the y neighbour
            # first, and so does one that misses the corner by less than _CORNER_TIE: the
            # virtual robot drives from cell centres along diagonals, so its beams at
            # multiples of 45 degrees pass exactly through corners, and which side the last
            # bit of its heading (np.arctan2, whose SIMD code differs between CPUs) or of
            # cos/sin puts them on must not decide whether a beam is valid (issue 36).
            if t_max_x < t_max_y - _CORNER_TIE:
                t_entry = t_max_x
                ix += step_x
                t_max_x += t_delta_x
            else:
                t_entry = t_max_y
                iy += step_y
                t_max_y += t_delta_y
            if t_entry > 1.0:
                break
        if iy < 0 or iy >= rows or ix < 0 or ix >= cols:
            return math.nan
        value = cells[iy, ix]
        if value == OCCUPIED:
            return t_entry * max_range
        if value == UNKNOWN:
            return math.nan
    return max_range


@numba.njit(cache=True)
def _cast_scans(
    cells: NDArray[np.int8],
    origin_x: float,
    origin_y: float,
    resolution: float,
    poses: FloatArray,
    beam_angles: FloatArray,
    max_range: float,
    out: FloatArray,
) -> None:
    for p in range(poses.shape[0]):
        for b in range(beam_angles.shape[0]):
            out[p, b] = _cast_beam(
                cells,
                origin_x,
                origin_y,
                resolution,
                poses[p, 0],
                poses[p, 1],
                poses[p, 2] + beam_angles[b],
                max_range,
            )


def simulate_scans(
    grid: GridMap, poses: ArrayLike, beam_angles: ArrayLike, max_range: float
) -> FloatArray:
    """Simulated scans of ``grid`` from several poses.

    Parameters
    ----------
    grid : GridMap
        The map scanned (its own frame: poses are in the coordinates of ``grid.origin``).
    poses : array_like, shape (T, 3)
        Sensor poses ``(x, y, theta)``, metres and radians.
    beam_angles : array_like, shape (B,)
        Beam directions relative to the heading, radians.
    max_range : float
        Maximum range, metres (> 0).

    Returns
    -------
    ndarray of float64, shape (T, B)
        Ranges in metres: NaN for beams that first meet UNKNOWN or the grid's edge,
        ``max_range`` for beams that meet nothing (module doc).
    """
    if not (math.isfinite(max_range) and max_range > 0):
        raise ValueError(f"max_range must be a finite number > 0 m, got {max_range}")
    poses = np.ascontiguousarray(np.atleast_2d(np.asarray(poses, dtype=np.float64)))
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise ValueError(f"poses must have shape (T, 3), got {poses.shape}")
    angles = np.ascontiguousarray(np.asarray(beam_angles, dtype=np.float64).ravel())
    out = np.empty((poses.shape[0], angles.shape[0]), dtype=np.float64)
    _cast_scans(
        np.ascontiguousarray(grid.cells),
        grid.origin[0],
        grid.origin[1],
        grid.resolution,
        poses,
        angles,
        float(max_range),
        out,
    )
    return out


def simulate_scan(
    grid: GridMap, pose: ArrayLike, beam_angles: ArrayLike, max_range: float
) -> FloatArray:
    """One simulated scan of ``grid`` from ``pose`` (3,); ranges (B,) as in
    :func:`simulate_scans`."""
    return simulate_scans(
        grid, np.asarray(pose, dtype=np.float64).reshape(1, 3), beam_angles, max_range
    )[0]


@dataclass(frozen=True, slots=True, kw_only=True)
class VirtualRobotConfig:
    """The virtual robot's runs along the skeleton of map 1 and its lidar."""

    n_beams: int = 120
    """Beams per virtual scan over the full circle (beam i at ``-pi + i 2 pi / n``)."""
    max_range: float = 6.0
    """Virtual lidar range, m."""
    step: float = 0.25
    """Distance driven between two scans, m."""
    run_length: float = 4.0
    """Length of one run along the skeleton, m (shorter where the skeleton ends)."""
    min_run_length: float = 1.0
    """Runs that cannot reach this length are dropped, m."""
    max_runs: int = 16
    """At most this many runs, chosen spread over the map."""
    heading_smoothing: float = 0.3
    """Half-window of the path over which the heading (path tangent) is taken, m."""
    min_valid_beams: float = 0.15
    """Scans with a smaller fraction of valid (non-NaN) beams are still kept, but a run
    whose mean fraction is below this is dropped (it sees almost nothing of m1)."""
    odometry_translation_noise: float = 0.0
    """Std of the odometry's translation error per metre driven, m/m (0: exact)."""
    odometry_rotation_noise: float = 0.0
    """Std of the odometry's heading error per metre driven, rad/m (0: exact)."""
    skeleton: SkeletonConfig = field(default_factory=SkeletonConfig)
    """How the skeleton of m1 is built."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_fields(
            self,
            positive=("max_range", "step", "run_length"),
            non_negative=(
                "min_run_length",
                "heading_smoothing",
                "min_valid_beams",
                "odometry_translation_noise",
                "odometry_rotation_noise",
            ),
            counts=("n_beams", "max_runs"),
        )
        require(
            name,
            "min_run_length",
            self.min_run_length,
            self.min_run_length <= self.run_length,
            f"<= run_length ({self.run_length})",
        )
        beams = self.min_valid_beams
        require(name, "min_valid_beams", beams, beams <= 1, "<= 1")
        skeleton = self.skeleton
        require(
            name, "skeleton", skeleton, isinstance(skeleton, SkeletonConfig), "a SkeletonConfig"
        )


@dataclass(frozen=True, slots=True)
class VirtualRun:
    """One drive of the virtual robot along the skeleton of m1.

    Attributes
    ----------
    poses_in_map1 : ndarray of float64, shape (T, 3)
        True poses in m1's frame, metres and radians.
    odometry : ndarray of float64, shape (T - 1, 3)
        Measured motion between consecutive poses, in the earlier pose's frame
        (``inverse(pose_k) ∘ pose_k+1``, plus noise if configured).
    ranges : ndarray of float64, shape (T, B)
        Virtual scans; NaN for invalid beams (see :func:`simulate_scan`).
    beam_angles : ndarray of float64, shape (B,)
        Beam directions relative to the heading, radians.
    max_range : float
        Lidar range, metres.
    branch : int
        Index of the skeleton edge the run starts on.
    """

    poses_in_map1: FloatArray
    odometry: FloatArray
    ranges: FloatArray
    beam_angles: FloatArray
    max_range: float
    branch: int

    @property
    def length(self) -> float:
        """Distance driven, metres."""
        return float(np.hypot(*np.diff(self.poses_in_map1[:, :2], axis=0).T).sum())


def odometry_between(poses: FloatArray) -> FloatArray:
    """Relative motions (T - 1, 3) ``inverse(pose_k) ∘ pose_k+1`` of a pose sequence (T, 3)."""
    poses = np.asarray(poses, dtype=np.float64)
    return compose(inverse(poses[:-1]), poses[1:])


def _walk(
    graph: SkeletonGraph, start_edge: int, reverse: bool, offset: float, length: float
) -> NDArray[np.int64]:
    """Cells of a walk of ``length`` cells along the graph, starting ``offset`` cells into
    an edge, continuing through junctions along the straightest next edge."""
    edge = graph.edges[start_edge]
    cells = edge.cells[::-1] if reverse else edge.cells
    steps = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(cells, axis=0).T))])
    first = int(np.searchsorted(steps, offset))
    path = [cells[first:]]
    walked = steps[-1] - steps[min(first, len(steps) - 1)]
    used = {start_edge}
    node = edge.start if reverse else edge.end
    while walked < length:
        current = np.concatenate(path)
        if len(current) < 2:
            break
        tail = current[-min(len(current), 8) :]
        direction = tail[-1] - tail[0]
        best, best_cos, best_reverse = -1, -2.0, False
        for index, candidate in enumerate(graph.edges):
            if index in used or len(candidate.cells) < 2:
                continue
            for flip, at in ((False, candidate.start), (True, candidate.end)):
                if at != node:
                    continue
                seq = candidate.cells[::-1] if flip else candidate.cells
                ahead = seq[min(len(seq) - 1, 8)] - seq[0]
                norm = float(np.hypot(*direction) * np.hypot(*ahead))
                cos = float(direction @ ahead) / norm if norm > 0 else -1.0
                if cos > best_cos:
                    best, best_cos, best_reverse = index, cos, flip
        if best < 0:
            break
        used.add(best)
        nxt = graph.edges[best]
        seq = nxt.cells[::-1] if best_reverse else nxt.cells
        path.append(seq[1:])
        walked += float(np.hypot(*np.diff(seq, axis=0).T).sum())
        node = nxt.start if best_reverse else nxt.end
    return np.concatenate(path)


def _resample_path(points: FloatArray, spacing: float, length: float) -> FloatArray:
    """Points every ``spacing`` along a polyline (N, 2), up to ``length``."""
    seg = np.hypot(*np.diff(points, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = min(s[-1], length)
    samples = np.arange(0.0, total + 1e-9, spacing)
    return np.column_stack(
        [np.interp(samples, s, points[:, 0]), np.interp(samples, s, points[:, 1])]
    )


def _path_headings(points: FloatArray, dense: FloatArray, half_window: float) -> FloatArray:
    """Heading of the path tangent at each of ``points`` (T, 2), from the dense path."""
    seg = np.hypot(*np.diff(dense, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    # Arc length of each sample point (samples were taken on this same polyline).
    nearest = np.argmin(((dense[None, :, :] - points[:, None, :]) ** 2).sum(axis=2), axis=1)
    s_points = s[nearest]
    ahead = np.clip(s_points + half_window, 0, s[-1])
    behind = np.clip(s_points - half_window, 0, s[-1])
    ax, ay = np.interp(ahead, s, dense[:, 0]), np.interp(ahead, s, dense[:, 1])
    bx, by = np.interp(behind, s, dense[:, 0]), np.interp(behind, s, dense[:, 1])
    return np.arctan2(ay - by, ax - bx)


def run_paths(
    graph: SkeletonGraph, grid: GridMap, config: VirtualRobotConfig
) -> list[tuple[int, FloatArray]]:
    """Candidate run paths along the skeleton, spread over the map.

    Every edge is cut into pieces of ``run_length``; each piece starts a walk (continued
    through junctions when the edge ends early, in both directions). Farthest-point
    selection on the walks' midpoints keeps at most ``max_runs`` of them.

    Returns
    -------
    list of (branch, poses)
        Edge index and poses (T, 3) in the grid's frame, heading along the path.
    """
    res = grid.resolution
    length_cells = config.run_length / res
    candidates: list[tuple[int, FloatArray]] = []
    for index, edge in enumerate(graph.edges):
        if len(edge.cells) < 2:
            continue
        edge_length = edge.length
        offsets = np.arange(0.0, max(edge_length - 0.5 * length_cells, 0.0) + 1e-9, length_cells)
        for offset in offsets:
            for reverse in (False, True):
                cells = _walk(graph, index, reverse, offset, length_cells)
                if len(cells) < 2:
                    continue
                dense = grid.cell_to_world(cells)
                points = _resample_path(dense, config.step, config.run_length)
                if (
                    len(points) < 2
                    or (len(points) - 1) * config.step < config.min_run_length - 1e-9
                ):
                    continue
                headings = _path_headings(points, dense, config.heading_smoothing)
                candidates.append((index, np.column_stack([points, headings])))
    if not candidates:
        return []
    middles = np.array([poses[len(poses) // 2, :2] for _, poses in candidates])
    starts = np.array([poses[0, :2] for _, poses in candidates])
    keys = np.hstack([middles, 0.5 * starts])
    chosen = [int(np.argmax(np.array([len(p) for _, p in candidates])))]
    distance = np.linalg.norm(keys - keys[chosen[0]], axis=1)
    while len(chosen) < min(config.max_runs, len(candidates)):
        nxt = int(np.argmax(distance))
        if distance[nxt] <= 0:
            break
        chosen.append(nxt)
        distance = np.minimum(distance, np.linalg.norm(keys - keys[nxt], axis=1))
    return [candidates[i] for i in chosen]


def _noisy_odometry(
    odometry: FloatArray, config: VirtualRobotConfig, rng: np.random.Generator
) -> FloatArray:
    if config.odometry_translation_noise == 0 and config.odometry_rotation_noise == 0:
        return odometry
    distance = np.hypot(odometry[:, 0], odometry[:, 1])
    noisy = odometry.copy()
    noisy[:, :2] += (
        rng.normal(size=(len(odometry), 2))
        * (config.odometry_translation_noise * distance)[:, None]
    )
    noisy[:, 2] = wrap_angle(
        noisy[:, 2] + rng.normal(size=len(odometry)) * config.odometry_rotation_noise * distance
    )
    return noisy


def virtual_robot_runs(
    m1: GridMap,
    *,
    config: VirtualRobotConfig | None = None,
    rng: np.random.Generator,
    graph: SkeletonGraph | None = None,
) -> list[VirtualRun]:
    """Many short virtual-robot runs along the skeleton of ``m1`` (docs/design.md §5 step 2).

    Parameters
    ----------
    m1 : GridMap
        The map the virtual robot drives in and scans.
    config : VirtualRobotConfig, optional
        Run and lidar parameters.
    rng : numpy.random.Generator
        Odometry noise (unused when the odometry is exact).
    graph : SkeletonGraph, optional
        Skeleton graph of ``m1`` (:func:`~mrslam_env.merge.skeleton.free_space_graph`);
        computed with ``config.skeleton`` when omitted.

    Returns
    -------
    list of VirtualRun
        Possibly empty (no skeleton long enough, or nothing of m1 visible).
    """
    config = config or VirtualRobotConfig()
    if graph is None:
        graph = free_space_graph(m1, config.skeleton)
    angles = -np.pi + np.arange(config.n_beams, dtype=np.float64) * (2.0 * np.pi / config.n_beams)
    runs: list[VirtualRun] = []
    for branch, poses in run_paths(graph, m1, config):
        ranges = simulate_scans(m1, poses, angles, config.max_range)
        if np.isfinite(ranges).mean() < config.min_valid_beams:
            continue
        odometry = _noisy_odometry(odometry_between(poses), config, rng)
        runs.append(
            VirtualRun(
                poses_in_map1=poses,
                odometry=odometry,
                ranges=ranges,
                beam_angles=angles,
                max_range=float(config.max_range),
                branch=branch,
            )
        )
    return runs
