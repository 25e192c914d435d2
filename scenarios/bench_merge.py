"""The map-merging benchmark behind ``mrslam bench merge``.

Pairs (made the way the paper made its pairs)
---------------------------------------------
The project's simulator drives one robot (:class:`agents.wander.WanderPolicy`, onboard
:class:`~mrslam_env.slam.slam.RobotSlam` in ``slam`` mode) from a random reachable start with
a random heading; each run's map is in its own map frame (= its start pose). Several such
runs per world are independent: a pair is two of them, and its ground truth is
``map1_from_map2 = inverse(start1) ∘ start2`` (true world start poses). Each run's map is
saved at several checkpoints (env steps), so one run gives maps of several sizes; pairs take
any checkpoint of two *different* runs (pairs may share a run, preferably not). Starts are
half spread out (farthest-point sampling: far-apart starts give the no-overlap pairs) and
half uniformly random. The default set (6 worlds x 8 runs x 1500 steps) takes about
70 s to simulate on one core. The truth is exact for the map frames; the maps themselves
carry their SLAM's drift (a few centimetres), as real pairs do.

The **overlap** of a pair is computed from the ground truth: both maps' known cells (FREE
or OCCUPIED) are resampled (nearest cell) onto one raster at the maps' resolution (the
world frame at generation, map 1's frame in :func:`true_overlap`), and ``overlap =
|known1 ∧ known2| / min(|known1|, |known2|)``: the share of the smaller map's known area
that the other map also knows.

Pairs are chosen to fill overlap bins (default ``[0.2, 0.35)``, ``[0.35, 0.5)``,
``[0.5, 0.65)``, ``[0.65, 0.85)``) over the worlds (every built-in scenario and two
procedural layouts) in turn, plus **no-overlap** pairs (``overlap < 0.02``): about a fifth
of the set. Generated pairs are cached as ROS map files plus ``manifest.json`` in
``<cache>/<key>/`` where the key holds :data:`GENERATOR_VERSION`, the pair count, the seed
and a digest of the whole :class:`PairGenerationConfig`.

Methods
-------
Each is ``(m1, m2, rng) -> map1_from_map2 (3,) or None`` (None = "no confident merge"):

``ours``         :func:`mrslam_env.merge.pipeline.merge_maps` (virtual robot + MCL +
                 random-walk refinement, DESIGN §5)
``random-walk``  Birk & Carpin alone: :func:`mrslam_env.merge.refine.refine_random_walk`
                 from several random initial transforms, best psi kept, accepted when its
                 acceptance index reaches :attr:`RandomWalkBaselineConfig.acceptance_threshold`
``features``     ROS ``multirobot_map_merge`` (:mod:`scenarios.merge_baselines`; needs the
                 ``baselines`` extra, i.e. OpenCV)

A method whose module is missing is reported as skipped, not as an error.

Scoring
-------
Translation error ``|t_est - t_true|`` (m) and rotation error ``|wrap(theta_est -
theta_true)|`` (deg). On an overlapping pair: **success** when both are within 0.25 m and
2°, **wrong** when a transform is returned outside that tolerance, **refused** when None.
On a no-overlap pair: **correct refusal** for None, **wrong** for any transform.

Aliasing
--------
Some pairs cannot be merged from the two maps alone: in a repetitive or symmetric building
a wrong placement fits as well as the true one. The CLI labels every overlapping pair with
:func:`scenarios.aliasing.aliasing`, an exhaustive placement search that uses the truth
only to tell the true placement from the rest (``clear``: the maps single out the truth;
``close``; ``misleading``), and the summary adds the success rate on the ``clear`` pairs
with overlap >= 30 %.

Some pairs no method can decide: :func:`scenarios.twins.world_twin` finds a second start
in the world from which map 2 would look the same (a point-symmetric building, identical
rooms), so the same two maps have a second ground truth. The CLI marks those
``undecidable`` and reports the success rate on the decidable pairs with overlap >= 30 %
and the ceiling the undecidable ones set.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import statistics
import time
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from agents.wander import WanderPolicy
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.geometry import compose, inverse, wrap_scalar
from mrslam_env.gridmap import UNKNOWN, GridMap
from mrslam_env.mapio import load_map, save_map
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from mrslam_env.slam.config import SlamConfig
from mrslam_env.slam.slam import RobotSlam
from mrslam_env.worlds import build_world

FloatArray = NDArray[np.float64]
MergeMethod = Callable[[GridMap, GridMap, np.random.Generator], FloatArray | None]

__all__ = [
    "DEFAULT_METHODS",
    "DEFAULT_WORLDS",
    "GENERATOR_VERSION",
    "MergePair",
    "PairGenerationConfig",
    "RandomWalkBaselineConfig",
    "Tolerance",
    "cell_agreement",
    "classify_outcome",
    "format_aliasing_breakdown",
    "format_merge_table",
    "format_scenario_breakdown",
    "format_twin_breakdown",
    "generate_pairs",
    "grid_footprint",
    "load_or_generate_pairs",
    "load_pairs",
    "merge_pair_from_runs",
    "method_features",
    "method_ours",
    "method_random_walk",
    "pose_errors",
    "reachable_starts",
    "resample_cells",
    "resolve_methods",
    "run_merge_benchmark",
    "simulate_run",
    "summarize",
    "true_overlap",
    "write_rows",
]

GENERATOR_VERSION = 1
"""Bump when pair generation changes, so cached pairs are rebuilt."""

DEFAULT_WORLDS = ("office", "warehouse", "maze", "twin_wings", "procedural-1", "procedural-2")
DEFAULT_METHODS = ("ours", "random-walk", "features")
DEFAULT_CACHE = Path("runs") / "bench-merge-pairs"

OUTCOMES = ("success", "wrong", "refused", "correct_refusal")


# --------------------------------------------------------------------------------------
# Configuration


@dataclass(frozen=True, slots=True, kw_only=True)
class PairGenerationConfig:
    """How benchmark pairs are generated (module docstring)."""

    n_pairs: int = 40
    """Pairs in the set (overlapping and no-overlap)."""
    seed: int = 0
    """Seeds the starts, the env (sensor noise) and the wander policies."""
    worlds: tuple[str, ...] = DEFAULT_WORLDS
    """Scenario names; pairs are spread over them in turn."""
    runs_per_world: int = 8
    """Independent single-robot runs per world; pairs combine two different runs."""
    checkpoints: tuple[int, ...] = (60, 150, 300, 600, 1000, 1500)
    """Env steps (0.1 s each) after which a run's map is saved, increasing."""
    overlap_bins: tuple[float, ...] = (0.2, 0.35, 0.5, 0.65, 0.85)
    """Edges of the overlap bins that overlapping pairs fill in turn, increasing in (0, 1]."""
    no_overlap_fraction: float = 0.2
    """Share of the pairs that have no overlap, in [0, 1]."""
    no_overlap_max: float = 0.02
    """A pair with an overlap below this counts as "no overlap"."""
    min_known_area: float = 4.0
    """Maps knowing less than this area (m²) are not used, m²."""

    def __post_init__(self) -> None:
        for name in ("n_pairs", "runs_per_world"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < (1 if name == "n_pairs" else 2):
                low = 1 if name == "n_pairs" else 2
                raise ValueError(
                    f"PairGenerationConfig.{name} must be an int >= {low}, got {value!r}"
                )
        if not self.worlds:
            raise ValueError("PairGenerationConfig.worlds must name at least one scenario")
        steps = self.checkpoints
        if not steps or any(s < 1 for s in steps) or list(steps) != sorted(set(steps)):
            raise ValueError(
                "PairGenerationConfig.checkpoints must be increasing positive step counts, "
                f"got {steps!r}"
            )
        edges = self.overlap_bins
        if len(edges) < 2 or list(edges) != sorted(set(edges)) or edges[0] <= 0 or edges[-1] > 1:
            raise ValueError(
                "PairGenerationConfig.overlap_bins must be >= 2 increasing edges in (0, 1], "
                f"got {edges!r}"
            )
        if not 0.0 <= self.no_overlap_fraction <= 1.0:
            raise ValueError(
                "PairGenerationConfig.no_overlap_fraction must be in [0, 1], "
                f"got {self.no_overlap_fraction!r}"
            )
        if not 0.0 < self.no_overlap_max < edges[0]:
            raise ValueError(
                "PairGenerationConfig.no_overlap_max must be in (0, overlap_bins[0]), "
                f"got {self.no_overlap_max!r}"
            )
        if not self.min_known_area >= 0:
            raise ValueError(
                f"PairGenerationConfig.min_known_area must be >= 0 m², got {self.min_known_area!r}"
            )

    def cache_key(self) -> str:
        """Folder name of this configuration's cached pairs (the onboard SLAM's defaults are
        part of it: maps made by another SLAM are other pairs)."""
        slam = asdict(SlamConfig())
        text = json.dumps(
            {"version": GENERATOR_VERSION, "slam": slam, **asdict(self)}, sort_keys=True
        )
        digest = hashlib.sha1(text.encode()).hexdigest()[:10]
        return f"v{GENERATOR_VERSION}-n{self.n_pairs}-seed{self.seed}-{digest}"


@dataclass(frozen=True, slots=True, kw_only=True)
class Tolerance:
    """When a returned transform counts as correct."""

    translation: float = 0.25
    """Largest translation error of a success, m."""
    rotation_deg: float = 2.0
    """Largest rotation error of a success, degrees."""

    def __post_init__(self) -> None:
        for name in ("translation", "rotation_deg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Tolerance.{name} must be > 0, got {value!r}")


@dataclass(frozen=True, slots=True, kw_only=True)
class RandomWalkBaselineConfig:
    """Birk & Carpin's adaptive random walk used alone (no MCL seed).

    A global search as in Birk & Carpin: from each of ``starts`` random initial transforms
    (uniform rotation; map 2's known centroid on a random known cell of map 1) the
    adaptive random walk runs with wide initial proposals; the lowest psi over
    all starts is then polished by a walk with the default, fine proposals.
    psi is the project's :func:`~mrslam_env.merge.dissimilarity.dissimilarity` (the
    overlap-restricted variant by default, which suits partial maps better than the paper's
    and so favours the baseline).

    Their acceptance indicator ``ai = agree / (agree + disagree)`` over cells known in both
    maps decides whether the merge is believed. Birk & Carpin call a merge good when ai is
    close to 1; the number used here, 0.95, is our choice, not theirs: on this benchmark's
    SLAM maps the true transform scores 0.96-0.99 (walls a cell apart after SLAM drift),
    a transform 0.5 m and 6° off scores 0.87-0.97 and aliased placements (the next shelf
    aisle, the other wing) 0.95-0.98, because free floor agrees with free floor under
    almost any placement. No threshold separates them; 0.95 keeps most correct merges.
    """

    starts: int = 8
    """Random initial transforms; the lowest psi over all their walks is kept."""
    search_iterations: int = 500
    """Proposals per start."""
    search_std_xy: float = 1.0
    """Initial proposal standard deviation of the search walks in x and y, m."""
    search_std_theta: float = 0.5
    """Initial proposal standard deviation of the search walks in theta, rad."""
    acceptance_threshold: float = 0.95
    """Smallest acceptance index at which the best transform is returned, in (0, 1]."""
    restrict_to_overlap: bool = True
    """psi over the overlap only (the project's variant, default) instead of the paper's
    psi over all cells. On partial maps the paper's psi is lowest where the two known areas
    pile up, not at the true transform, so the walk would never settle on it."""
    min_overlap_fraction: float = 0.1
    """With ``restrict_to_overlap``: psi is infinite, and a result is refused, below this
    share of the smaller map's known cells overlapping the other map; without it the walk
    slides to placements where a sliver of floor overlaps and nothing disagrees."""

    def __post_init__(self) -> None:
        for name in ("starts", "search_iterations"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(
                    f"RandomWalkBaselineConfig.{name} must be an int >= 1, got {value!r}"
                )
        if not 0.0 <= self.min_overlap_fraction < 1.0:
            raise ValueError(
                "RandomWalkBaselineConfig.min_overlap_fraction must be in [0, 1), "
                f"got {self.min_overlap_fraction!r}"
            )
        for name in ("search_std_xy", "search_std_theta"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"RandomWalkBaselineConfig.{name} must be > 0, got {value!r}")
        if not 0.0 < self.acceptance_threshold <= 1.0:
            raise ValueError(
                "RandomWalkBaselineConfig.acceptance_threshold must be in (0, 1], "
                f"got {self.acceptance_threshold!r}"
            )


# --------------------------------------------------------------------------------------
# Geometry of pairs: resampling and overlap


def resample_cells(
    source: GridMap,
    target_from_source: FloatArray,
    origin: tuple[float, float],
    shape: tuple[int, int],
    resolution: float,
) -> NDArray[np.int8]:
    """Resample a grid (nearest cell) onto a raster in another frame.

    Parameters
    ----------
    source : GridMap
        The grid, in its own frame.
    target_from_source : ndarray (3,)
        Pose of the source frame in the target frame.
    origin, shape, resolution
        The target raster: outer corner of its cell [0, 0] (m, target frame), (rows, cols),
        cell size (m).

    Returns
    -------
    ndarray of int8, shape ``shape``
        The source cell under each target cell centre; UNKNOWN outside the source grid.
    """
    rows, cols = shape
    xs = origin[0] + (np.arange(cols) + 0.5) * resolution
    ys = origin[1] + (np.arange(rows) + 0.5) * resolution
    source_from_target = inverse(target_from_source)
    c, s = math.cos(source_from_target[2]), math.sin(source_from_target[2])
    # Points in the source frame, separably: x_s = c x - s y + tx, y_s = s x + c y + ty.
    px = c * xs[None, :] - s * ys[:, None] + source_from_target[0]
    py = s * xs[None, :] + c * ys[:, None] + source_from_target[1]
    ix = np.floor((px - source.origin[0]) / source.resolution).astype(np.int64)
    iy = np.floor((py - source.origin[1]) / source.resolution).astype(np.int64)
    src_rows, src_cols = source.shape
    inside = (ix >= 0) & (ix < src_cols) & (iy >= 0) & (iy < src_rows)
    cells = np.full(shape, UNKNOWN, dtype=np.int8)
    cells[inside] = source.cells[iy[inside], ix[inside]]
    return cells


def grid_footprint(grid: GridMap, frame_from_grid: FloatArray) -> FloatArray:
    """Corners (4, 2) of a grid's extent in another frame."""
    xmin, ymin, xmax, ymax = grid.extent
    corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
    c, s = math.cos(frame_from_grid[2]), math.sin(frame_from_grid[2])
    return corners @ np.array([[c, s], [-s, c]]) + frame_from_grid[:2]


def true_overlap(m1: GridMap, m2: GridMap, map1_from_map2: FloatArray) -> float:
    """Overlap of two maps under the true transform: the area known (FREE or OCCUPIED) in
    both, over the smaller of the two known areas, in [0, 1].

    Both maps are resampled onto one raster in map 1's frame at the finer resolution.
    Returns 0 when either map knows nothing.
    """
    transform = np.asarray(map1_from_map2, dtype=np.float64)
    resolution = min(m1.resolution, m2.resolution)
    corners = np.vstack([grid_footprint(m1, np.zeros(3)), grid_footprint(m2, transform)])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    shape = (
        math.ceil((hi[1] - lo[1]) / resolution),
        math.ceil((hi[0] - lo[0]) / resolution),
    )
    origin = (float(lo[0]), float(lo[1]))
    known1 = resample_cells(m1, np.zeros(3), origin, shape, resolution) != UNKNOWN
    known2 = resample_cells(m2, transform, origin, shape, resolution) != UNKNOWN
    return _overlap_of_masks(known1, known2)


def _overlap_of_masks(known1: NDArray[np.bool_], known2: NDArray[np.bool_]) -> float:
    smaller = min(int(known1.sum()), int(known2.sum()))
    return 0.0 if smaller == 0 else int(np.count_nonzero(known1 & known2)) / smaller


def cell_agreement(m1: GridMap, m2: GridMap, map1_from_map2: FloatArray) -> float:
    """Share of the cells known in both maps (m2 resampled onto m1's lattice) that have the
    same state, in [0, 1]; NaN when no cell is known in both.

    A diagnostic for wrong answers: a wrong transform that agrees as well as the truth
    means the two maps alone cannot tell them apart (symmetric or repetitive places).
    """
    transform = np.asarray(map1_from_map2, dtype=np.float64)
    warped = resample_cells(m2, transform, m1.origin, m1.shape, m1.resolution)
    both = (warped != UNKNOWN) & (m1.cells != UNKNOWN)
    return float(np.mean(warped[both] == m1.cells[both])) if both.any() else math.nan


# --------------------------------------------------------------------------------------
# Pair generation


def reachable_starts(
    world: WorldSpec,
    count: int,
    rng: np.random.Generator,
    *,
    radius: float = 0.2,
    spread: int = 0,
    separation: float = 2.0,
) -> FloatArray:
    """Random start poses (count, 3) in the free space a robot can reach, any heading.

    Candidates are the cells (0.1 m) with at least ``radius + 0.3`` m clearance, connected
    for the robot to the world's first start, as the simulator's automatic starts
    (:func:`mrslam_env.sim.simulator.choose_starts`). The first ``spread`` starts are
    spread out by farthest-point sampling from a random first one; the rest are uniform,
    at least ``separation`` m from each other when possible.
    """
    resolution = 0.1
    grid = ground_truth_map(world, resolution, margin=resolution)
    distance = (ndimage.distance_transform_edt(grid.free) - 0.5) * resolution
    labels, _ = ndimage.label(distance >= radius)
    iy, ix = grid.world_to_cell(world.starts[0, :2])
    candidates = grid.cell_to_world(
        np.argwhere((labels == labels[iy, ix]) & (distance >= radius + 0.3))
    )
    if len(candidates) == 0:
        raise ValueError(f"world {world.name!r} has no room for a robot start")
    chosen = [candidates[rng.integers(len(candidates))]]
    nearest = np.hypot(*(candidates - chosen[0]).T)
    while len(chosen) < min(spread, count):
        pick = int(np.argmax(nearest))
        chosen.append(candidates[pick])
        nearest = np.minimum(nearest, np.hypot(*(candidates - candidates[pick]).T))
    for index in rng.permutation(len(candidates)):
        if len(chosen) == count:
            break
        point = candidates[index]
        if all(math.hypot(*(point - c)) >= separation for c in chosen):
            chosen.append(point)
    while len(chosen) < count:  # a small world: relax the separation
        chosen.append(candidates[rng.integers(len(candidates))])
    headings = rng.uniform(-math.pi, math.pi, count)
    return np.column_stack([np.array(chosen), headings])


def simulate_run(
    world: WorldSpec,
    start: FloatArray,
    checkpoints: Sequence[int],
    seed: Sequence[int] | int,
    *,
    slam_config: SlamConfig | None = None,
) -> tuple[FloatArray, dict[int, GridMap]]:
    """One robot wandering with onboard SLAM from ``start``; its map at each checkpoint.

    Parameters
    ----------
    world : WorldSpec
    start : ndarray (3,)
        Start pose in the world frame.
    checkpoints : sequence of int
        Env steps after which the SLAM map is taken (increasing).
    seed : int or sequence of int
        Seeds the env (sensor noise) and the wander policy.
    slam_config : SlamConfig, optional
        Onboard SLAM settings (``mode`` forced to ``slam``).

    Returns
    -------
    world_from_map : ndarray (3,)
        The true start pose: the map frame in the world.
    maps : dict of int to GridMap
        The map (in the map frame) after each checkpoint's number of steps.
    """
    steps = max(checkpoints)
    env_seed = int(np.random.SeedSequence(seed).generate_state(1)[0])
    pose = (float(start[0]), float(start[1]), float(start[2]))
    config = EnvConfig(max_cycles=steps, starts=(pose,))
    env = MultiRobotSlamEnv(scenario=world, n_robots=1, seed=env_seed, config=config)
    observations, infos = env.reset(seed=env_seed)
    lidar = env.config.lidar
    base = slam_config if slam_config is not None else SlamConfig()
    slam = RobotSlam(replace(base, mode="slam"), lidar.n_beams, lidar.max_range)
    policy = WanderPolicy(lidar.n_beams, np.random.default_rng(seed))
    agent = env.possible_agents[0]
    world_from_map = np.asarray(infos[agent]["true_pose"], dtype=np.float64).copy()
    slam.update(observations[agent]["odom"], observations[agent]["scan"])
    wanted = set(checkpoints)
    maps: dict[int, GridMap] = {}
    for k in range(1, steps + 1):
        observations, _, _, _, infos = env.step({agent: policy.act(observations[agent]["scan"])})
        slam.update(observations[agent]["odom"], observations[agent]["scan"])
        if k in wanted:
            maps[k] = slam.grid.to_gridmap()
    env.close()
    return world_from_map, maps


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class MergePair:
    """One benchmark pair.

    Attributes
    ----------
    pair_id : str
    scenario : str
    m1, m2 : GridMap
        The two maps, each in its own map frame.
    map1_from_map2 : ndarray (3,)
        The ground truth.
    overlap : float
        :func:`true_overlap` (computed on the world raster at generation).
    info : dict
        Provenance: the runs' world start poses, steps, known areas.
    """

    pair_id: str
    scenario: str
    m1: GridMap
    m2: GridMap
    map1_from_map2: FloatArray
    overlap: float
    info: dict[str, Any] = field(default_factory=dict)

    def overlapping(self, no_overlap_max: float = 0.02) -> bool:
        """Whether the pair counts as overlapping (overlap at or above ``no_overlap_max``)."""
        return self.overlap >= no_overlap_max


def merge_pair_from_runs(
    pair_id: str,
    scenario: str,
    run1: tuple[FloatArray, GridMap],
    run2: tuple[FloatArray, GridMap],
    info: dict[str, Any] | None = None,
) -> MergePair:
    """A pair from two runs ``(world_from_map, map)``: the truth is
    ``inverse(world_from_map1) ∘ world_from_map2``."""
    (start1, m1), (start2, m2) = run1, run2
    truth = compose(inverse(start1), start2)
    return MergePair(
        pair_id=pair_id,
        scenario=scenario,
        m1=m1,
        m2=m2,
        map1_from_map2=truth,
        overlap=true_overlap(m1, m2, truth),
        info=dict(info or {}),
    )


@dataclass(slots=True)
class _Snapshot:
    run: int
    steps: int
    start: FloatArray
    grid: GridMap
    known: NDArray[np.bool_]  # on the world raster
    area: float


def _world_snapshots(
    world: WorldSpec, world_index: int, config: PairGenerationConfig
) -> list[_Snapshot]:
    rng = np.random.default_rng([config.seed, world_index, 0])
    starts = reachable_starts(
        world, config.runs_per_world, rng, spread=(config.runs_per_world + 1) // 2
    )
    raster: GridMap | None = None
    snapshots: list[_Snapshot] = []
    for run, start in enumerate(starts):
        world_from_map, maps = simulate_run(
            world, start, config.checkpoints, [config.seed, world_index, run + 1]
        )
        for steps, grid in maps.items():
            if raster is None:
                raster = ground_truth_map(world, grid.resolution, margin=9.0)
            known = (
                resample_cells(grid, world_from_map, raster.origin, raster.shape, raster.resolution)
                != UNKNOWN
            )
            area = float(known.sum()) * raster.resolution**2
            if area >= config.min_known_area:
                snapshots.append(_Snapshot(run, steps, world_from_map, grid, known, area))
    return snapshots


def _candidates(
    snapshots: list[_Snapshot],
) -> list[tuple[int, int, float]]:
    """(index1, index2, overlap) for snapshots of different runs, index1 < index2."""
    found = []
    for i, a in enumerate(snapshots):
        for j in range(i + 1, len(snapshots)):
            b = snapshots[j]
            if a.run != b.run:
                found.append((i, j, _overlap_of_masks(a.known, b.known)))
    return found


def _bin_of(overlap: float, config: PairGenerationConfig) -> int | None:
    """-1 for no overlap, the bin index for overlapping pairs, None for neither."""
    if overlap < config.no_overlap_max:
        return -1
    edges = config.overlap_bins
    for k in range(len(edges) - 1):
        if edges[k] <= overlap < edges[k + 1]:
            return k
    return None


def _slot_plan(config: PairGenerationConfig) -> list[tuple[int, int]]:
    """(world index, bin) per pair: worlds in turn, no-overlap slots evenly spaced, each
    world cycling through the overlap bins."""
    n, n_worlds = config.n_pairs, len(config.worlds)
    n_none = round(n * config.no_overlap_fraction)
    none_slots = {math.floor(k * n / n_none) for k in range(n_none)} if n_none else set()
    per_world_bin = list(range(n_worlds))  # each world starts at a different bin
    n_bins = len(config.overlap_bins) - 1
    plan = []
    for slot in range(n):
        world = slot % n_worlds
        if slot in none_slots:
            plan.append((world, -1))
        else:
            plan.append((world, per_world_bin[world] % n_bins))
            per_world_bin[world] += 1
    return plan


def generate_pairs(
    config: PairGenerationConfig,
    out_dir: Path,
    *,
    progress: Callable[[str], None] | None = None,
) -> list[MergePair]:
    """Simulate the runs, choose the pairs, and save them (maps + ``manifest.json``).

    Slots that their world cannot fill (e.g. no pair of runs without overlap) are filled
    from the nearest bin of the same kind in that world, then from the same bin in the other
    worlds; a set that still falls short is saved short, with ``shortfall`` in the manifest.
    """
    started = time.perf_counter()
    snapshots: list[list[_Snapshot]] = []
    candidates: list[list[tuple[int, int, float]]] = []
    for w, name in enumerate(config.worlds):
        if progress is not None:
            progress(f"simulating {config.runs_per_world} runs in {name}")
        snapshots.append(_world_snapshots(build_world(name), w, config))
        candidates.append(_candidates(snapshots[-1]))
    rng = np.random.default_rng([config.seed, 7919])
    used: set[tuple[int, int, int]] = set()
    run_pair_uses: dict[tuple[int, int, int], int] = {}
    snapshot_uses: dict[tuple[int, int], int] = {}
    n_bins = len(config.overlap_bins) - 1

    def pick(world: int, wanted: int) -> tuple[int, int, float] | None:
        options = []
        for i, j, overlap in candidates[world]:
            if (world, i, j) in used or _bin_of(overlap, config) != wanted:
                continue
            a, b = snapshots[world][i], snapshots[world][j]
            runs = (world, min(a.run, b.run), max(a.run, b.run))
            cost = (
                10 * run_pair_uses.get(runs, 0)
                + snapshot_uses.get((world, i), 0)
                + snapshot_uses.get((world, j), 0)
                + float(rng.random())
            )
            options.append((cost, i, j, overlap))
        if not options:
            return None
        _, i, j, overlap = min(options)
        return i, j, overlap

    def fallbacks(world: int, wanted: int) -> list[tuple[int, int]]:
        kinds = [wanted] if wanted < 0 else sorted(range(n_bins), key=lambda k: abs(k - wanted))
        order = [world] + [w for w in range(len(config.worlds)) if w != world]
        same_world = [(world, k) for k in kinds]
        other_worlds = [(w, wanted) for w in order[1:]]
        rest = [(w, k) for w in order[1:] for k in kinds if k != wanted]
        return same_world + other_worlds + rest

    chosen: list[tuple[int, int, int, float]] = []
    shortfall = 0
    for world, wanted in _slot_plan(config):
        for w, k in fallbacks(world, wanted):
            found = pick(w, k)
            if found is not None:
                i, j, overlap = found
                used.add((w, i, j))
                a, b = snapshots[w][i], snapshots[w][j]
                runs = (w, min(a.run, b.run), max(a.run, b.run))
                run_pair_uses[runs] = run_pair_uses.get(runs, 0) + 1
                snapshot_uses[(w, i)] = snapshot_uses.get((w, i), 0) + 1
                snapshot_uses[(w, j)] = snapshot_uses.get((w, j), 0) + 1
                chosen.append((w, i, j, overlap))
                break
        else:
            shortfall += 1

    out_dir.mkdir(parents=True, exist_ok=True)
    pairs: list[MergePair] = []
    entries = []
    for number, (w, i, j, overlap) in enumerate(chosen):
        first, second = snapshots[w][i], snapshots[w][j]
        if rng.random() < 0.5:
            first, second = second, first
        scenario = config.worlds[w]
        pair_id = f"{number:03d}-{scenario}"
        info = {
            "start1_world": first.start.tolist(),
            "start2_world": second.start.tolist(),
            "run1": first.run,
            "run2": second.run,
            "steps1": first.steps,
            "steps2": second.steps,
            "known_area1_m2": first.area,
            "known_area2_m2": second.area,
        }
        truth = compose(inverse(first.start), second.start)
        pair = MergePair(
            pair_id=pair_id,
            scenario=scenario,
            m1=first.grid,
            m2=second.grid,
            map1_from_map2=truth,
            overlap=overlap,
            info=info,
        )
        pairs.append(pair)
        save_map(out_dir / f"{pair_id}-m1.yaml", pair.m1)
        save_map(out_dir / f"{pair_id}-m2.yaml", pair.m2)
        entries.append(
            {
                "pair_id": pair_id,
                "scenario": scenario,
                "map1": f"{pair_id}-m1.yaml",
                "map2": f"{pair_id}-m2.yaml",
                "map1_from_map2": truth.tolist(),
                "overlap": overlap,
                **info,
            }
        )
    manifest = {
        "generator_version": GENERATOR_VERSION,
        "config": asdict(config),
        "generation_seconds": time.perf_counter() - started,
        "shortfall": shortfall,
        "pairs": entries,
    }
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return pairs


def load_pairs(folder: Path) -> tuple[list[MergePair], dict[str, Any]]:
    """Pairs and manifest saved by :func:`generate_pairs`."""
    manifest = json.loads((folder / "manifest.json").read_text())
    pairs = []
    for entry in manifest["pairs"]:
        info = {
            key: value
            for key, value in entry.items()
            if key not in ("pair_id", "scenario", "map1", "map2", "map1_from_map2", "overlap")
        }
        pairs.append(
            MergePair(
                pair_id=entry["pair_id"],
                scenario=entry["scenario"],
                m1=load_map(folder / entry["map1"]),
                m2=load_map(folder / entry["map2"]),
                map1_from_map2=np.asarray(entry["map1_from_map2"], dtype=np.float64),
                overlap=float(entry["overlap"]),
                info=info,
            )
        )
    return pairs, manifest


def load_or_generate_pairs(
    config: PairGenerationConfig,
    cache: Path = DEFAULT_CACHE,
    *,
    regenerate: bool = False,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[MergePair], dict[str, Any]]:
    """The cached pairs of this configuration, generating them first when missing (or
    when ``regenerate``)."""
    folder = Path(cache) / config.cache_key()
    manifest_path = folder / "manifest.json"
    if regenerate or not manifest_path.exists():
        if progress is not None:
            progress(f"generating {config.n_pairs} pairs into {folder}")
        generate_pairs(config, folder, progress=progress)
    return load_pairs(folder)


# --------------------------------------------------------------------------------------
# Methods


def method_ours(m1: GridMap, m2: GridMap, rng: np.random.Generator) -> FloatArray | None:
    """The project's pipeline, :func:`mrslam_env.merge.pipeline.merge_maps`."""
    from mrslam_env.merge.pipeline import merge_maps

    result = merge_maps(m1, m2, rng=rng)
    return None if result.transform is None else np.asarray(result.transform, dtype=np.float64)


def _random_initial_transform(m1: GridMap, m2: GridMap, rng: np.random.Generator) -> FloatArray:
    """A uniformly random rotation, and a translation putting the centroid of m2's known
    cells on a random known cell of m1 (the space a blind search must cover)."""
    known1 = np.argwhere(m1.cells != UNKNOWN)
    known2 = np.argwhere(m2.cells != UNKNOWN)
    target = m1.cell_to_world(known1[rng.integers(len(known1))])
    centroid = m2.cell_to_world(known2).mean(axis=0)
    theta = float(rng.uniform(-math.pi, math.pi))
    c, s = math.cos(theta), math.sin(theta)
    rotated = np.array([c * centroid[0] - s * centroid[1], s * centroid[0] + c * centroid[1]])
    translation = target - rotated
    return np.array([translation[0], translation[1], theta])


def method_random_walk(
    m1: GridMap,
    m2: GridMap,
    rng: np.random.Generator,
    config: RandomWalkBaselineConfig | None = None,
) -> FloatArray | None:
    """Birk & Carpin's adaptive random walk alone from random initial transforms
    (:class:`RandomWalkBaselineConfig`)."""
    from mrslam_env.merge.dissimilarity import (
        DissimilarityConfig,
        acceptance_index,
        distance_maps,
    )
    from mrslam_env.merge.refine import RandomWalkConfig, refine_random_walk

    config = config if config is not None else RandomWalkBaselineConfig()
    if not (m1.cells != UNKNOWN).any() or not (m2.cells != UNKNOWN).any():
        return None
    distances1, distances2 = distance_maps(m1), distance_maps(m2)
    # psi counts at most max_free_cells free cells per map (plus every occupied one).
    free_limit = DissimilarityConfig().max_free_cells
    sampled = min(min(int(m.free.sum()), free_limit) + int(m.occupied.sum()) for m in (m1, m2))
    search = RandomWalkConfig(
        iterations=config.search_iterations,
        initial_std_xy=config.search_std_xy,
        initial_std_theta=config.search_std_theta,
        max_std_xy=max(2.0 * config.search_std_xy, 1.0),
        max_std_theta=max(2.0 * config.search_std_theta, math.radians(20.0)),
        dissimilarity=DissimilarityConfig(
            restrict_to_overlap=config.restrict_to_overlap,
            min_overlap_cells=max(20, round(config.min_overlap_fraction * sampled)),
        ),
    )
    best_transform = np.zeros(3)
    best_psi = math.inf
    for _ in range(config.starts):
        walk = refine_random_walk(
            m1,
            m2,
            _random_initial_transform(m1, m2, rng),
            config=search,
            rng=rng,
            distances1=distances1,
            distances2=distances2,
        )
        if walk.psi < best_psi:
            best_psi, best_transform = float(walk.psi), np.asarray(walk.transform, dtype=float)
    if not math.isfinite(best_psi):
        return None
    polished = refine_random_walk(
        m1,
        m2,
        best_transform,
        config=RandomWalkConfig(dissimilarity=search.dissimilarity),
        rng=rng,
        distances1=distances1,
        distances2=distances2,
    )
    transform = np.asarray(polished.transform, dtype=np.float64)
    agreement = acceptance_index(m1, m2, transform, distances1=distances1, distances2=distances2)
    enough_overlap = agreement.overlap_fraction >= config.min_overlap_fraction
    return transform if enough_overlap and agreement.index >= config.acceptance_threshold else None


def method_features(m1: GridMap, m2: GridMap, rng: np.random.Generator) -> FloatArray | None:
    """ROS ``multirobot_map_merge``
    (:func:`scenarios.merge_baselines.estimate_transform_features`)."""
    from scenarios.merge_baselines import estimate_transform_features

    return estimate_transform_features(m1, m2).transform


_METHODS: dict[str, tuple[MergeMethod, tuple[str, ...]]] = {
    "ours": (method_ours, ("mrslam_env.merge.pipeline",)),
    "random-walk": (
        method_random_walk,
        ("mrslam_env.merge.refine", "mrslam_env.merge.dissimilarity"),
    ),
    "features": (method_features, ("cv2",)),
}


def resolve_methods(
    names: Sequence[str],
) -> tuple[dict[str, MergeMethod], dict[str, str]]:
    """The runnable methods among ``names``, and why the others are skipped.

    Raises
    ------
    ValueError
        For a name that is no method.
    """
    import importlib

    runnable: dict[str, MergeMethod] = {}
    skipped: dict[str, str] = {}
    for name in names:
        if name not in _METHODS:
            raise ValueError(f"unknown method {name!r}; methods are {', '.join(_METHODS)}")
        method, modules = _METHODS[name]
        try:
            for module in modules:
                importlib.import_module(module)
        except ImportError as error:
            hint = " (install the 'baselines' extra)" if "cv2" in modules else ""
            skipped[name] = f"{error}{hint}"
            continue
        runnable[name] = method
    return runnable, skipped


# --------------------------------------------------------------------------------------
# Scoring


def pose_errors(estimate: FloatArray, truth: FloatArray) -> tuple[float, float]:
    """Translation error (m) and absolute rotation error (degrees, wrapped) of a transform."""
    e = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    translation = math.hypot(e[0] - t[0], e[1] - t[1])
    rotation = abs(wrap_scalar(float(e[2] - t[2])))
    return translation, math.degrees(rotation)


def classify_outcome(
    estimate: FloatArray | None,
    truth: FloatArray,
    overlapping: bool,
    tolerance: Tolerance | None = None,
) -> str:
    """``success`` / ``wrong`` / ``refused`` on an overlapping pair; ``correct_refusal`` /
    ``wrong`` on a pair without overlap (any transform returned there is wrong)."""
    tolerance = tolerance if tolerance is not None else Tolerance()
    if estimate is None:
        return "refused" if overlapping else "correct_refusal"
    if not overlapping:
        return "wrong"
    translation, rotation = pose_errors(estimate, truth)
    ok = translation <= tolerance.translation and rotation <= tolerance.rotation_deg
    return "success" if ok else "wrong"


def run_merge_benchmark(
    pairs: Sequence[MergePair],
    methods: Mapping[str, MergeMethod],
    *,
    seed: int = 0,
    tolerance: Tolerance | None = None,
    no_overlap_max: float = 0.02,
    warm_up: bool = True,
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Run every method on every pair; one row (dict) per (pair, method).

    Each call gets its own generator ``default_rng([seed, pair index, crc32(method)])``.
    With ``warm_up``, each method first runs once, untimed, on the first pair (numba
    compilation and caches are not timed).

    Row keys: ``pair_id, scenario, overlap, overlapping, method, outcome, returned, x, y,
    theta`` (the estimate or None), ``translation_error`` (m) and ``rotation_error_deg``
    (None when nothing was returned), ``seconds``, ``error`` (the one-line message when the
    method raised ``ValueError`` on the pair's maps, which counts as a refusal; else None),
    ``largest_side_cells`` (the longest side of the two grids), and the diagnostics
    ``agreement_truth`` / ``agreement_estimate`` (:func:`cell_agreement` under the truth and
    under the returned transform).
    """
    tolerance = tolerance if tolerance is not None else Tolerance()
    if warm_up and pairs:
        for name, method in methods.items():
            method(pairs[0].m1, pairs[0].m2, np.random.default_rng([seed, 999_983]))
            if progress is not None:
                progress(f"warmed up {name}")
    rows: list[dict[str, Any]] = []
    for index, pair in enumerate(pairs):
        overlapping = pair.overlapping(no_overlap_max)
        largest = max(*pair.m1.shape, *pair.m2.shape)
        truth_agreement = cell_agreement(pair.m1, pair.m2, pair.map1_from_map2)
        for name, method in methods.items():
            rng = np.random.default_rng([seed, index, zlib.crc32(name.encode())])
            started = time.perf_counter()
            error = None
            try:
                estimate = method(pair.m1, pair.m2, rng)
            except ValueError as failure:  # a method rejecting its input refuses to merge
                estimate, error = None, str(failure).splitlines()[0]
            seconds = time.perf_counter() - started
            errors = (
                (None, None) if estimate is None else pose_errors(estimate, pair.map1_from_map2)
            )
            rows.append(
                {
                    "pair_id": pair.pair_id,
                    "scenario": pair.scenario,
                    "overlap": pair.overlap,
                    "overlapping": overlapping,
                    "method": name,
                    "outcome": classify_outcome(
                        estimate, pair.map1_from_map2, overlapping, tolerance
                    ),
                    "returned": estimate is not None,
                    "x": None if estimate is None else float(estimate[0]),
                    "y": None if estimate is None else float(estimate[1]),
                    "theta": None if estimate is None else float(estimate[2]),
                    "translation_error": errors[0],
                    "rotation_error_deg": errors[1],
                    "seconds": seconds,
                    "error": error,
                    "largest_side_cells": largest,
                    "agreement_truth": truth_agreement,
                    "agreement_estimate": None
                    if estimate is None
                    else cell_agreement(pair.m1, pair.m2, estimate),
                }
            )
            if progress is not None:
                progress(f"{pair.pair_id} {name}: {rows[-1]['outcome']} ({seconds:.2f} s)")
    return rows


def _rate(numerator: int, denominator: int) -> float:
    return numerator / denominator if denominator else math.nan


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else math.nan


def _percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


def summarize(
    rows: Sequence[dict[str, Any]],
    methods: Sequence[str],
    *,
    high_overlap: float = 0.3,
    small_side: int = 400,
) -> dict[str, dict[str, Any]]:
    """Per method: the benchmark's figures.

    Keys: ``pairs``; ``success_rate_high`` (successes over pairs with overlap >=
    ``high_overlap``) with ``pairs_high``; ``success_rate_overlapping`` over all
    overlapping pairs with ``pairs_overlapping``; ``wrong`` (count) and ``wrong_rate`` (over
    all pairs); ``correct_refusals`` and ``refusal_rate`` over the ``pairs_no_overlap``;
    ``median_/p90_translation_error`` (m) and ``median_/p90_rotation_error_deg`` over the
    transforms returned on overlapping pairs; ``median_seconds`` per pair, and
    ``median_seconds_small`` over the ``pairs_small`` whose grids are at most
    ``small_side`` cells on a side; ``wrong_as_good_as_truth``: wrong answers on
    overlapping pairs whose :func:`cell_agreement` is at least the truth's (the maps alone
    cannot tell them apart). When the rows carry an ``aliasing`` label
    (:mod:`scenarios.aliasing`; the CLI adds it), also ``pairs_high_clear`` and
    ``success_rate_high_clear``: the pairs with overlap >= ``high_overlap`` whose maps single
    out the truth (label ``clear``), and the successes among them. When the rows carry
    ``undecidable`` (:mod:`scenarios.twins`; the CLI adds it): ``pairs_high_undecidable``
    and ``pairs_high_decidable`` (overlap >= ``high_overlap``), the
    ``success_rate_high_decidable``, and ``wrong_undecidable`` (wrong answers on undecidable
    pairs, any overlap).
    """
    summary: dict[str, dict[str, Any]] = {}
    for name in methods:
        mine = [row for row in rows if row["method"] == name]
        overlapping = [row for row in mine if row["overlapping"]]
        high = [row for row in overlapping if row["overlap"] >= high_overlap]
        clear = [row for row in high if row.get("aliasing") == "clear"]
        decidable = [row for row in high if row.get("undecidable") is False]
        none = [row for row in mine if not row["overlapping"]]
        returned = [row for row in overlapping if row["returned"]]
        translation = [row["translation_error"] for row in returned]
        rotation = [row["rotation_error_deg"] for row in returned]
        small = [row for row in mine if row.get("largest_side_cells", 0) <= small_side]
        wrong = sum(row["outcome"] == "wrong" for row in mine)
        refusals = sum(row["outcome"] == "correct_refusal" for row in none)
        summary[name] = {
            "pairs": len(mine),
            "pairs_high": len(high),
            "success_rate_high": _rate(sum(r["outcome"] == "success" for r in high), len(high)),
            "aliasing_labelled": any(row.get("aliasing") for row in mine),
            "pairs_high_clear": len(clear),
            "success_rate_high_clear": _rate(
                sum(r["outcome"] == "success" for r in clear), len(clear)
            ),
            "twins_labelled": any(row.get("undecidable") is not None for row in mine),
            "pairs_high_undecidable": sum(bool(row.get("undecidable")) for row in high),
            "pairs_high_decidable": len(decidable),
            "success_rate_high_decidable": _rate(
                sum(r["outcome"] == "success" for r in decidable), len(decidable)
            ),
            "wrong_undecidable": sum(
                r["outcome"] == "wrong" and bool(r.get("undecidable")) for r in mine
            ),
            "pairs_overlapping": len(overlapping),
            "success_rate_overlapping": _rate(
                sum(r["outcome"] == "success" for r in overlapping), len(overlapping)
            ),
            "wrong": wrong,
            "wrong_rate": _rate(wrong, len(mine)),
            "pairs_no_overlap": len(none),
            "correct_refusals": refusals,
            "refusal_rate": _rate(refusals, len(none)),
            "median_translation_error": _percentile(translation, 50),
            "p90_translation_error": _percentile(translation, 90),
            "median_rotation_error_deg": _percentile(rotation, 50),
            "p90_rotation_error_deg": _percentile(rotation, 90),
            "median_seconds": _median([r["seconds"] for r in mine]),
            "pairs_small": len(small),
            "median_seconds_small": _median([r["seconds"] for r in small]),
            "wrong_as_good_as_truth": sum(
                r["outcome"] == "wrong"
                and r["overlapping"]
                and r["agreement_estimate"] is not None
                and r["agreement_estimate"] >= r["agreement_truth"]
                for r in mine
            ),
        }
    return summary


def _percent(value: float) -> str:
    return "-" if math.isnan(value) else f"{100 * value:.0f}%"


def _number(value: float, digits: int) -> str:
    return "-" if math.isnan(value) else f"{value:.{digits}f}"


def format_merge_table(
    summary: Mapping[str, Mapping[str, Any]],
    skipped: Mapping[str, str] | None = None,
    *,
    high_overlap: float = 0.3,
) -> str:
    """A markdown table, methods side by side, one figure per row (skipped methods listed
    below it)."""
    names = list(summary)
    if not names:
        lines = ["(no method ran)"]
    else:
        first = summary[names[0]]
        rows: list[tuple[str, Callable[[Mapping[str, Any]], str]]] = [
            (
                f"success, overlap ≥ {100 * high_overlap:.0f}% (n={first['pairs_high']})",
                lambda s: _percent(s["success_rate_high"]),
            ),
            *(
                [
                    (
                        f"success, overlap ≥ {100 * high_overlap:.0f}%, maps single out the "
                        f"truth (n={first['pairs_high_clear']})",
                        lambda s: _percent(s["success_rate_high_clear"]),
                    )
                ]
                if first.get("aliasing_labelled")
                else []
            ),
            *(
                [
                    (
                        f"success, overlap ≥ {100 * high_overlap:.0f}%, decidable pairs "
                        f"(n={first['pairs_high_decidable']})",
                        lambda s: _percent(s["success_rate_high_decidable"]),
                    )
                ]
                if first.get("twins_labelled")
                else []
            ),
            (
                f"success, all overlapping (n={first['pairs_overlapping']})",
                lambda s: _percent(s["success_rate_overlapping"]),
            ),
            (
                f"wrong answers, all pairs (n={first['pairs']})",
                lambda s: f"{s['wrong']} ({_percent(s['wrong_rate'])})",
            ),
            (
                f"correct refusals, no overlap (n={first['pairs_no_overlap']})",
                lambda s: f"{s['correct_refusals']} ({_percent(s['refusal_rate'])})",
            ),
            (
                "translation error median / p90 (m)",
                lambda s: (
                    f"{_number(s['median_translation_error'], 3)} / "
                    f"{_number(s['p90_translation_error'], 3)}"
                ),
            ),
            (
                "rotation error median / p90 (°)",
                lambda s: (
                    f"{_number(s['median_rotation_error_deg'], 2)} / "
                    f"{_number(s['p90_rotation_error_deg'], 2)}"
                ),
            ),
            ("median time per pair (s)", lambda s: _number(s["median_seconds"], 2)),
            (
                f"median time, grids ≤ 400×400 (n={first['pairs_small']}) (s)",
                lambda s: _number(s["median_seconds_small"], 2),
            ),
            (
                "wrong answers agreeing as well as the truth",
                lambda s: str(s["wrong_as_good_as_truth"]),
            ),
        ]
        header = "| | " + " | ".join(names) + " |"
        lines = [header, "|---|" + "---:|" * len(names)]
        for label, cell in rows:
            lines.append(f"| {label} | " + " | ".join(cell(summary[n]) for n in names) + " |")
    for name, reason in (skipped or {}).items():
        lines.append(f"\nskipped {name}: {reason}")
    return "\n".join(lines)


def format_scenario_breakdown(rows: Sequence[dict[str, Any]], method: str = "ours") -> str:
    """Outcomes of one method per world (procedural layouts together), as a markdown
    table: where it succeeds, and where it refuses because the maps are ambiguous."""
    counts: dict[str, dict[str, int]] = {}
    for row in rows:
        if row["method"] != method:
            continue
        world = "procedural" if row["scenario"].startswith("procedural") else row["scenario"]
        tally = counts.setdefault(world, {})
        tally[row["outcome"]] = tally.get(row["outcome"], 0) + 1
    outcomes = ("success", "refused", "wrong", "correct_refusal")
    lines = [
        f"| {method}: world | " + " | ".join(o.replace("_", " ") for o in outcomes) + " |",
        "| --- |" + " ---: |" * len(outcomes),
    ]
    for world in sorted(counts):
        lines.append(
            f"| {world} | " + " | ".join(str(counts[world].get(o, 0)) for o in outcomes) + " |"
        )
    return "\n".join(lines)


def format_aliasing_breakdown(
    rows: Sequence[dict[str, Any]], method: str = "ours", *, high_overlap: float = 0.3
) -> str:
    """Outcomes of one method on the pairs with overlap >= ``high_overlap`` by their
    ``aliasing`` label (:mod:`scenarios.aliasing`), as a markdown table; empty when the
    rows carry no labels."""
    mine = [
        r
        for r in rows
        if r["method"] == method and r["overlapping"] and r["overlap"] >= high_overlap
    ]
    if not any(r.get("aliasing") for r in mine):
        return ""
    outcomes = ("success", "refused", "wrong")
    lines = [
        f"| {method}: the maps, overlap ≥ {100 * high_overlap:.0f}% | pairs | "
        + " | ".join(outcomes)
        + " |",
        "| --- | ---: |" + " ---: |" * len(outcomes),
    ]
    for label, meaning in (
        ("clear", "single out the truth"),
        ("close", "fit a wrong placement nearly as well"),
        ("misleading", "fit a wrong placement as well or better"),
    ):
        group = [r for r in mine if r.get("aliasing") == label]
        counts = " | ".join(str(sum(r["outcome"] == o for r in group)) for o in outcomes)
        lines.append(f"| {label}: {meaning} | {len(group)} | {counts} |")
    dominated = [r for r in mine if r.get("aliasing_dominated")]
    if dominated:
        counts = " | ".join(str(sum(r["outcome"] == o for r in dominated)) for o in outcomes)
        lines.append(
            f"| of all these, a wrong placement overlaps as much or more, no more conflicts "
            f"| {len(dominated)} | {counts} |"
        )
    return "\n".join(lines)


def format_twin_breakdown(
    rows: Sequence[dict[str, Any]], method: str = "ours", *, high_overlap: float = 0.3
) -> str:
    """Outcomes of one method on the pairs whose maps arise from a second start too
    (``undecidable``, :mod:`scenarios.twins`) and on the rest, as a markdown table with the
    success ceiling they set; empty when the rows carry no such label."""
    mine = [r for r in rows if r["method"] == method and r.get("undecidable") is not None]
    if not mine:
        return ""
    outcomes = ("success", "refused", "wrong", "correct_refusal")
    lines = [
        f"| {method}: can the maps decide? | pairs | "
        + " | ".join(o.replace("_", " ") for o in outcomes)
        + " |",
        "| --- | ---: |" + " ---: |" * len(outcomes),
    ]
    high = [r for r in mine if r["overlapping"] and r["overlap"] >= high_overlap]
    groups = (
        (f"overlap ≥ {100 * high_overlap:.0f}%, decidable", high, False),
        (f"overlap ≥ {100 * high_overlap:.0f}%, undecidable", high, True),
        (
            f"overlap < {100 * high_overlap:.0f}%, undecidable",
            [r for r in mine if r["overlapping"] and r["overlap"] < high_overlap],
            True,
        ),
        ("no overlap, undecidable", [r for r in mine if not r["overlapping"]], True),
    )
    for label, group, undecidable in groups:
        members = [r for r in group if bool(r["undecidable"]) == undecidable]
        counts = " | ".join(str(sum(r["outcome"] == o for r in members)) for o in outcomes)
        lines.append(f"| {label} | {len(members)} | {counts} |")
    if high:
        share = sum(not r["undecidable"] for r in high) / len(high)
        lines.append(
            f"\nUndecidable: the same two maps arise from a second pair of starts with another "
            f"ground truth. Refusing those, no method passes {_percent(share)} at overlap "
            f"≥ {100 * high_overlap:.0f}%; merging one is a wrong answer on its twin."
        )
    return "\n".join(lines)


def write_rows(path: Path, rows: Sequence[dict[str, Any]], extra: dict[str, Any]) -> Path:
    """Per-pair rows to ``path``: CSV when it ends in ``.csv``, else JSON (with ``extra``,
    e.g. the summary and the manifest's generation figures)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".csv":
        with path.open("w", newline="") as handle:
            fields = list(rows[0]) if rows else ["pair_id"]
            writer = csv.DictWriter(handle, fieldnames=fields)
            writer.writeheader()
            writer.writerows(rows)
    else:
        path.write_text(json.dumps({**extra, "rows": list(rows)}, indent=2, default=float))
    return path
