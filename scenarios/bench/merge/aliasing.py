"""How well two maps alone single out their true alignment: an exhaustive placement search.

A merge benchmark pair can be *aliased*: in a repetitive or symmetric building (the next
shelf aisle, the mirrored wing of ``twin_wings``) a wrong placement of map 2 can fit map 1
as well as the true one, or better. No method that sees only the two maps can then be
expected to merge them; refusing is the right answer. This module measures that for a
pair, independently of any merging method, with the ground truth used only to tell the
true placement from the rest.

Every placement of map 2 over map 1 is scored: all rotations in steps of
:attr:`AliasingConfig.rotation_step_deg`, and every translation at once by FFT
cross-correlation on a grid of :attr:`AliasingConfig.resolution` (both maps pooled to it,
occupied winning a cell). The score of a placement counts cells (of that grid)::

    score = overlap - conflict_weight * conflicts

``overlap`` is the number of cells known (free or occupied) in both maps, ``conflicts`` the
number of occupied cells of either map on free cells of the other that lie farther than
:attr:`AliasingConfig.wall_tolerance` from any of the other map's walls (a wall across open
floor). A placement is the *true* one when it moves map 2's known centre less than
:attr:`AliasingConfig.same_translation` from where the truth puts it and turns less than
:attr:`AliasingConfig.same_rotation_deg`; the best score among those is the truth's score
(the maps' own small errors may put the best cell a little off the exact truth). The best
score among all other placements is the rival's. Their ratio labels the pair:

``clear``       rival < ``close_ratio`` x truth: the maps single the truth out;
``close``       within that margin: a second placement fits nearly as well;
``misleading``  rival >= truth: a wrong placement fits as well as the truth, or better.

Separately, a pair is *dominated* when some other placement overlaps at least as much as
the truth's best one with no more conflicts: then no weighting of the two can rank the
truth first.

The default conflict weight (30 cells) makes one wall cell across open floor outweigh
thirty agreeing cells; with weight 10 many more true placements lose to a larger but
contradicted alias. The search takes a few seconds a pair (360 rotations of five FFTs of
a few hundred cells square), so :func:`load_or_compute_aliasing` caches the results
beside the pairs.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray
from scipy import fft as scipy_fft
from scipy import ndimage

from mrslam_env.atomic import write_text_atomic
from mrslam_env.geometry import transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap, grid_footprint, resample_cells
from mrslam_env.merge.fuse import resample_map
from mrslam_env.validation import check_fields, require
from scenarios.bench.merge.pairs import MergePair

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

FloatArray = NDArray[np.float64]

__all__ = [
    "LABELS",
    "Aliasing",
    "AliasingConfig",
    "aliasing",
    "cached_per_pair",
    "config_key",
    "load_or_compute_aliasing",
    "placement_counts",
    "placement_score",
]

LABELS = ("clear", "close", "misleading")

_MAX_CONFLICTS = 2000
"""Conflict counts tracked for the dominance test (a truth with more is never dominated)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class AliasingConfig:
    """The exhaustive placement search of :func:`aliasing`."""

    resolution: float = 0.1
    """Cell size of the search grid, m (both maps are pooled to it, occupied winning)."""
    rotation_step_deg: float = 1.0
    """Rotations tried: the truth's plus every multiple of this, degrees."""
    wall_tolerance: float = 0.2
    """A wall of one map conflicts only with free cells of the other farther than this
    from the other's walls, m (the maps' own errors stay within it)."""
    conflict_weight: float = 30.0
    """Agreeing cells one conflicting cell outweighs."""
    same_translation: float = 1.0
    """A placement moving map 2's known centre less than this from the truth's (m) ..."""
    same_rotation_deg: float = 10.0
    """... and turning less than this (degrees) is the true placement."""
    close_ratio: float = 0.8
    """Rival score over truth score from which a pair is ``close``."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=(
                "resolution",
                "rotation_step_deg",
                "wall_tolerance",
                "same_translation",
                "same_rotation_deg",
            ),
            non_negative=("conflict_weight",),
        )
        require(
            "AliasingConfig", "close_ratio", self.close_ratio, 0.0 < self.close_ratio <= 1.0,
            "in (0, 1]",
        )  # fmt: skip
        require(
            "AliasingConfig", "rotation_step_deg", self.rotation_step_deg,
            self.rotation_step_deg <= 90.0, "<= 90",
        )  # fmt: skip


@dataclass(frozen=True, slots=True, kw_only=True)
class Aliasing:
    """The result of :func:`aliasing` for one pair.

    Attributes
    ----------
    truth_score, rival_score : float
        Best score (cells of the search grid) of a true placement and of any other one
        (0 when no other placement overlaps at all).
    rival : ndarray (3,) or None
        ``map1_from_map2`` of the best other placement.
    ratio : float
        ``rival_score / truth_score`` (inf when the truth scores 0 or less).
    label : str
        ``clear``, ``close`` or ``misleading`` (module docstring).
    truth_overlap, truth_conflicts : float
        Overlap and conflicts (cells) of the truth's best placement.
    dominated : bool
        Some other placement overlaps at least as much with no more conflicts: whatever
        weight a method gives conflicts, the maps cannot rank the truth first.
    """

    truth_score: float
    rival_score: float
    rival: FloatArray | None
    ratio: float
    label: str
    truth_overlap: float
    truth_conflicts: float
    dominated: bool

    def to_json(self) -> dict[str, object]:
        return {
            "truth_score": self.truth_score,
            "rival_score": self.rival_score,
            "rival": None if self.rival is None else [float(v) for v in self.rival],
            "ratio": self.ratio if math.isfinite(self.ratio) else None,
            "label": self.label,
            "truth_overlap": self.truth_overlap,
            "truth_conflicts": self.truth_conflicts,
            "dominated": self.dominated,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Aliasing:
        rival, ratio = data["rival"], data["ratio"]
        return cls(
            truth_score=float(data["truth_score"]),
            rival_score=float(data["rival_score"]),
            rival=None if rival is None else np.asarray(rival, dtype=np.float64),
            ratio=math.inf if ratio is None else float(ratio),
            label=str(data["label"]),
            truth_overlap=float(data["truth_overlap"]),
            truth_conflicts=float(data["truth_conflicts"]),
            dominated=bool(data["dominated"]),
        )


def _masks(
    cells: NDArray[np.int8], resolution: float, tolerance: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Known, occupied, and free-far-from-walls masks of a pooled grid, as floats."""
    occupied = cells == OCCUPIED
    if occupied.any():
        far = (cells == FREE) & (ndimage.distance_transform_edt(~occupied) * resolution > tolerance)
    else:
        far = cells == FREE
    return (
        (cells != UNKNOWN).astype(np.float64),
        occupied.astype(np.float64),
        far.astype(np.float64),
    )


def _rendered(
    m2: GridMap, placement: FloatArray, origin1: FloatArray, resolution: float
) -> tuple[NDArray[np.int8], NDArray[np.int64]]:
    """Map 2 under ``placement``, pooled onto map 1's search lattice (cells whose corners
    are ``origin1`` plus whole multiples of ``resolution``), and the (col, row) offset of
    the raster's cell [0, 0] in that lattice."""
    corners = grid_footprint(m2, placement)
    low, high = corners.min(axis=0), corners.max(axis=0)
    offset = np.floor((low - origin1) / resolution).astype(np.int64)
    corner = origin1 + offset * resolution
    factor = max(1, round(resolution / m2.resolution))
    fine = resolution / factor
    cols = math.ceil((high[0] - corner[0]) / resolution)
    rows = math.ceil((high[1] - corner[1]) / resolution)
    origin = (float(corner[0]), float(corner[1]))
    cells = resample_cells(m2, placement, origin, (rows * factor, cols * factor), fine)
    pooled = resample_map(GridMap(cells=cells, resolution=fine, origin=origin), resolution)
    return pooled.cells[:rows, :cols], offset


def placement_score(
    m1: GridMap, m2: GridMap, map1_from_map2: FloatArray, config: AliasingConfig | None = None
) -> float:
    """The score (module docstring) of one placement, counted directly (no FFT), with map
    2 resampled onto map 1's search grid as :func:`aliasing` does."""
    config = config or AliasingConfig()
    overlap, conflicts = placement_counts(m1, m2, map1_from_map2, config)
    return overlap - config.conflict_weight * conflicts


def placement_counts(
    m1: GridMap, m2: GridMap, map1_from_map2: FloatArray, config: AliasingConfig | None = None
) -> tuple[float, float]:
    """Overlap and conflicts (cells of the search grid) of one placement, counted as
    :func:`placement_score` counts them."""
    config = config or AliasingConfig()
    res = config.resolution
    g1 = resample_map(m1, res)
    origin1 = np.asarray(g1.origin, dtype=np.float64)
    placement = np.asarray(map1_from_map2, dtype=np.float64)
    cells2, offset = _rendered(m2, placement, origin1, res)
    known1, occupied1, far1 = _masks(g1.cells, res, config.wall_tolerance)
    known2, occupied2, far2 = _masks(cells2, res, config.wall_tolerance)
    rows1, cols1 = g1.shape
    # The part of map 2's raster that lies on map 1's grid, and the matching part of map 1.
    dc, dr = int(offset[0]), int(offset[1])
    r0, c0 = max(0, -dr), max(0, -dc)
    r1, c1 = min(cells2.shape[0], rows1 - dr), min(cells2.shape[1], cols1 - dc)
    if r1 <= r0 or c1 <= c0:
        return 0.0, 0.0
    on1 = np.s_[r0 + dr : r1 + dr, c0 + dc : c1 + dc]
    on2 = np.s_[r0:r1, c0:c1]
    overlap = float(np.sum(known2[on2] * known1[on1]))
    conflicts = float(np.sum(occupied2[on2] * far1[on1] + far2[on2] * occupied1[on1]))
    return overlap, conflicts


def aliasing(
    m1: GridMap, m2: GridMap, map1_from_map2: FloatArray, config: AliasingConfig | None = None
) -> Aliasing:
    """Search every placement of ``m2`` over ``m1``; compare the best true placement with
    the best other one (module docstring).

    Parameters
    ----------
    m1, m2 : GridMap
        The pair's maps, each in its own frame, any resolutions finer than the search grid.
    map1_from_map2 : ndarray (3,)
        The ground truth.
    config : AliasingConfig, optional

    Returns
    -------
    Aliasing

    Raises
    ------
    ValueError
        A map with no known cell.
    """
    config = config or AliasingConfig()
    for name, grid in (("map 1", m1), ("map 2", m2)):
        if not (grid.free.any() or grid.occupied.any()):
            raise ValueError(f"{name} has no known (free or occupied) cell")
    res = config.resolution
    truth = np.asarray(map1_from_map2, dtype=np.float64)
    g1 = resample_map(m1, res)
    origin1 = np.asarray(g1.origin, dtype=np.float64)
    known1, occupied1, far1 = _masks(g1.cells, res, config.wall_tolerance)
    reach = math.ceil(math.hypot(*m2.shape) * m2.resolution / res) + 2
    shape = (
        int(scipy_fft.next_fast_len(g1.shape[0] + reach)),
        int(scipy_fft.next_fast_len(g1.shape[1] + reach)),
    )
    spectra1 = [scipy_fft.rfft2(mask, shape) for mask in (known1, occupied1, far1)]
    # Shifts (cells) of every FFT index: the correlation wraps negative shifts round.
    shift_rows = np.arange(shape[0])
    shift_rows[shift_rows >= shape[0] - reach] -= shape[0]
    shift_cols = np.arange(shape[1])
    shift_cols[shift_cols >= shape[1] - reach] -= shape[1]
    centre2 = m2.cell_to_world(np.argwhere(m2.cells != UNKNOWN)).mean(axis=0)
    truth_centre = transform_points(truth, centre2[None, :])[0]

    truth_score, rival_score = -math.inf, 0.0
    truth_cells = (0.0, 0.0)  # overlap and conflicts of the truth's best placement
    rival: FloatArray | None = None
    # rival_overlap[c]: the largest overlap of a rival placement with at most c conflicts.
    rival_overlap = np.full(_MAX_CONFLICTS + 1, -1.0)
    steps = round(360.0 / config.rotation_step_deg)
    for k in range(steps):
        turn = math.remainder(math.radians(k * config.rotation_step_deg), 2.0 * math.pi)
        base = np.array([truth[0], truth[1], truth[2] + turn])
        cells2, offset = _rendered(m2, base, origin1, res)
        known2, occupied2, far2 = _masks(cells2, res, config.wall_tolerance)
        overlap = np.rint(
            scipy_fft.irfft2(np.conj(scipy_fft.rfft2(known2, shape)) * spectra1[0], shape)
        )
        conflicts = np.rint(
            scipy_fft.irfft2(
                np.conj(scipy_fft.rfft2(occupied2, shape)) * spectra1[2]
                + np.conj(scipy_fft.rfft2(far2, shape)) * spectra1[1],
                shape,
            )
        )
        score = overlap - config.conflict_weight * conflicts
        # Index (i, j) lays raster cell [0, 0] on lattice cell (j, i); ``base`` laid it
        # on ``offset``, so the placement is ``base`` translated by the difference.
        dx = (shift_cols - offset[0]) * res
        dy = (shift_rows - offset[1]) * res
        moved = transform_points(base, centre2[None, :])[0] - truth_centre
        distance = np.hypot(dy[:, None] + moved[1], dx[None, :] + moved[0])
        same = (distance < config.same_translation) & (
            abs(math.degrees(turn)) < config.same_rotation_deg
        )
        if same.any():
            best = np.unravel_index(int(np.argmax(np.where(same, score, -np.inf))), score.shape)
            if score[best] > truth_score:
                truth_score = float(score[best])
                truth_cells = (float(overlap[best]) + 0.0, float(conflicts[best]) + 0.0)
        few = ~same & (conflicts <= _MAX_CONFLICTS)
        np.maximum.at(rival_overlap, conflicts[few].astype(np.int64), overlap[few])
        others = np.where(same, -np.inf, score)
        index = np.unravel_index(int(np.argmax(others)), others.shape)
        if others[index] > rival_score:
            rival_score = float(others[index])
            rival = base + np.array([dx[index[1]], dy[index[0]], 0.0])
    ratio = rival_score / truth_score if truth_score > 0 else math.inf
    rival_overlap = np.maximum.accumulate(rival_overlap)
    dominated = bool(
        truth_cells[1] <= _MAX_CONFLICTS
        and rival_overlap[int(truth_cells[1])] >= max(truth_cells[0], 1.0)
    )
    if ratio >= 1.0:
        label = "misleading"
    elif ratio >= config.close_ratio:
        label = "close"
    else:
        label = "clear"
    if rival is not None:
        rival[2] = math.remainder(float(rival[2]), 2.0 * math.pi)
    return Aliasing(
        truth_score=max(truth_score, 0.0) if math.isfinite(truth_score) else 0.0,
        rival_score=rival_score,
        rival=rival,
        ratio=ratio,
        label=label,
        truth_overlap=truth_cells[0],
        truth_conflicts=truth_cells[1],
        dominated=dominated,
    )


_CACHE_VERSION = 1
"""Bump when the search or its result changes, so cached results are recomputed."""


def config_key(config: DataclassInstance, version: int = _CACHE_VERSION) -> str:
    """A short digest of a config dataclass and a cache version, for cache file names."""
    text = json.dumps({"version": version, **asdict(config)}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:10]


def load_or_compute_aliasing(
    pairs: Sequence[MergePair],
    folder: Path | None,
    config: AliasingConfig | None = None,
    *,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Aliasing]:
    """:func:`aliasing` of every overlapping pair, by pair id; read from and written to
    ``folder / "aliasing-<config digest>.json"`` when ``folder`` is given."""
    config = config or AliasingConfig()

    def compute(pair: MergePair) -> Aliasing:
        found = aliasing(pair.m1, pair.m2, pair.map1_from_map2, config)
        if progress is not None:
            progress(f"aliasing {pair.pair_id}: {found.label} (ratio {found.ratio:.2f})")
        return found

    return cached_per_pair(
        [pair for pair in pairs if pair.overlapping()],
        None if folder is None else Path(folder) / f"aliasing-{config_key(config)}.json",
        compute,
        Aliasing.from_json,
    )


class _Cacheable(Protocol):
    def to_json(self) -> dict[str, object]: ...


Result = TypeVar("Result", bound=_Cacheable)


def cached_per_pair(
    pairs: Sequence[MergePair],
    path: Path | None,
    compute: Callable[[MergePair], Result],
    from_json: Callable[[dict[str, Any]], Result],
) -> dict[str, Result]:
    """``compute(pair)`` for every pair, by pair id, read from the JSON file ``path`` when
    it holds the pair and written back to it after each new result (so an interrupted run
    keeps what it computed)."""
    cached: dict[str, Result] = {}
    if path is not None and path.exists():
        cached = {key: from_json(value) for key, value in json.loads(path.read_text()).items()}
    result: dict[str, Result] = {}
    for pair in pairs:
        if pair.pair_id not in cached:
            cached[pair.pair_id] = compute(pair)
            if path is not None:
                path.parent.mkdir(parents=True, exist_ok=True)
                write_text_atomic(
                    path, json.dumps({k: v.to_json() for k, v in cached.items()}, indent=1)
                )
        result[pair.pair_id] = cached[pair.pair_id]
    return result
