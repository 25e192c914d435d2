"""Benchmark pairs that no merging method can decide: the same maps from a second start.

A pair's ground truth comes from the two robots' start poses. If map 2 fits the *world* as
well with the robot started somewhere else (the other wing of a point-symmetric building,
the next identical room), a robot started there would have built the same map 2. The pair
``(m1, m2)`` then has two possible ground truths, and a method that sees only the maps
gives one answer for both: it can be right on one at most. Such a pair is *undecidable*.

:func:`world_twin` finds the second start by the exhaustive placement search of
:func:`scenarios.bench.merge.aliasing.aliasing`, run with the world itself as map 1: the world is
rasterised (:func:`world_grid`: floor the robots can reach is free, walls and everything
out of reach are occupied) and every placement of map 2 over it is scored at 1° and 0.1 m
steps. The true placement is the robot's real start. Map 2 has a *twin* start when the
best other placement (over 1 m or 10° away), counted again cell by cell, covers as many
world cells with no more conflicts (a wall of map 2 on open floor, or open floor of map 2
inside a wall, beyond 0.2 m) than the best placement at the true start. The test is
strict, so the twins found are certain and some are missed (a rival a fraction of a cell
off the search grid may score a conflict more); the count is a lower bound.

What the twin means for the benchmark:

* an overlapping pair with a twin: merging at the truth is a wrong answer on the twin
  pair (the twin truth is a different transform, or none when the twin start leaves the
  maps without overlap); refusing fails the success count;
* a no-overlap pair whose twin overlaps map 1: merging at the twin's transform is a
  success on the twin pair and a wrong answer here.

Over a population of pairs where a start and its twin are equally likely (starts are
drawn uniformly over the reachable floor), a method that merges undecidable pairs is wrong
on them as often as it is right. A success rate above ``1 - undecidable share`` can thus
only be bought with wrong answers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from mrslam_env.evaluation import true_overlap
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.registry import build_world
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from scenarios.bench.merge.aliasing import (
    AliasingConfig,
    aliasing,
    cached_per_pair,
    config_key,
    placement_counts,
)
from scenarios.bench.merge.pairs import MergePair

FloatArray = NDArray[np.float64]

__all__ = [
    "WorldTwin",
    "load_or_compute_world_twins",
    "world_grid",
    "world_starts",
    "world_twin",
]

WORLD_RESOLUTION = 0.05
"""Cell size (m) at which a world is rasterised before the search pools it."""
WORLD_MARGIN = 3.0
"""Border (m) around a world's bounds, occupied, so a placement of map 2 partly outside
the building is scored (its free cells there are conflicts) rather than cut off."""
_CACHE_VERSION = 1
"""Bump when the test or its result changes, so cached results are recomputed."""


@dataclass(frozen=True, slots=True, kw_only=True)
class WorldTwin:
    """The result of :func:`world_twin` for one pair.

    Attributes
    ----------
    undecidable : bool
        The maps arise from a second ground truth that a method cannot tell from the
        pair's (module docstring).
    twin : ndarray (3,) or None
        ``map1_from_map2`` that the twin start implies; None when map 2 fits the world
        nowhere else as well.
    twin_overlap : float
        Overlap of the maps under ``twin`` (:func:`~mrslam_env.evaluation.true_overlap`),
        0.0 without a twin.
    truth_conflicts : float
        Conflicts (search cells) of map 2 with the world at its true start: the map's own
        errors, which the twin may not exceed.
    """

    undecidable: bool
    twin: FloatArray | None
    twin_overlap: float
    truth_conflicts: float

    def to_json(self) -> dict[str, object]:
        return {
            "undecidable": self.undecidable,
            "twin": None if self.twin is None else [float(v) for v in self.twin],
            "twin_overlap": self.twin_overlap,
            "truth_conflicts": self.truth_conflicts,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> WorldTwin:
        twin = data["twin"]
        return cls(
            undecidable=bool(data["undecidable"]),
            twin=None if twin is None else np.asarray(twin, dtype=np.float64),
            twin_overlap=float(data["twin_overlap"]),
            truth_conflicts=float(data["truth_conflicts"]),
        )


def world_grid(
    world: WorldSpec,
    starts: Sequence[ArrayLike],
    resolution: float = WORLD_RESOLUTION,
    margin: float = WORLD_MARGIN,
) -> GridMap:
    """The world as a fully known map: FREE where a robot started at one of ``starts``
    can reach, OCCUPIED elsewhere (walls, the outside, enclosed voids).

    Raises
    ------
    ValueError
        A start outside the raster or inside a wall.
    """
    raster = ground_truth_map(world, resolution, margin=margin)
    wall = raster.cells == OCCUPIED
    regions, _ = ndimage.label(~wall)
    rows, cols = raster.shape
    reachable = np.zeros_like(wall)
    for start in starts:
        x, y = np.asarray(start, dtype=np.float64)[:2]
        col = math.floor((x - raster.origin[0]) / resolution)
        row = math.floor((y - raster.origin[1]) / resolution)
        if not (0 <= row < rows and 0 <= col < cols) or wall[row, col]:
            raise ValueError(f"start ({x:.2f}, {y:.2f}) is not on the floor of {world.name}")
        reachable |= regions == regions[row, col]
    cells = np.where(reachable, FREE, OCCUPIED).astype(np.int8)
    return GridMap(cells=cells, resolution=resolution, origin=raster.origin)


def world_starts(pair: MergePair) -> tuple[FloatArray, FloatArray]:
    """The two robots' start poses in the world (``pair.info``), or a one-line ValueError."""
    try:
        first, second = pair.info["start1_world"], pair.info["start2_world"]
    except KeyError as missing:
        raise ValueError(f"pair {pair.pair_id} has no world start pose {missing}") from None
    return np.asarray(first, dtype=np.float64), np.asarray(second, dtype=np.float64)


def world_twin(
    pair: MergePair,
    world: GridMap,
    config: AliasingConfig | None = None,
    *,
    no_overlap_max: float = 0.02,
) -> WorldTwin:
    """Whether map 2 of ``pair`` fits ``world`` (:func:`world_grid`) as well at a second
    start, and what that makes of the pair (module docstring).

    ``pair.info`` must hold the world start poses ``start1_world`` and ``start2_world``
    (the pairs of :func:`~scenarios.bench.merge.generate_pairs` do).
    """
    start1, start2 = world_starts(pair)
    config = config or AliasingConfig()
    found = aliasing(world, pair.m2, start2, config)
    if found.rival is None:
        return _no_twin(found.truth_conflicts)
    # The best other placement is the twin when, counted directly, it covers as many world
    # cells as the truth with no more conflicts.
    overlap, conflicts = placement_counts(world, pair.m2, found.rival, config)
    if overlap < found.truth_overlap or conflicts > found.truth_conflicts:
        return _no_twin(found.truth_conflicts)
    twin = compose(inverse(start1), found.rival)
    twin[2] = math.remainder(float(twin[2]), 2.0 * math.pi)
    overlap = true_overlap(pair.m1, pair.m2, twin)
    return WorldTwin(
        # A no-overlap pair is only in doubt when its twin does overlap: refusing is right
        # for both otherwise.
        undecidable=pair.overlapping(no_overlap_max) or overlap >= no_overlap_max,
        twin=twin,
        twin_overlap=overlap,
        truth_conflicts=found.truth_conflicts,
    )


def _no_twin(truth_conflicts: float) -> WorldTwin:
    return WorldTwin(
        undecidable=False, twin=None, twin_overlap=0.0, truth_conflicts=truth_conflicts
    )


def load_or_compute_world_twins(
    pairs: Sequence[MergePair],
    folder: Path | None,
    config: AliasingConfig | None = None,
    *,
    worlds: Callable[[str], WorldSpec] = build_world,
    progress: Callable[[str], None] | None = None,
) -> dict[str, WorldTwin]:
    """:func:`world_twin` of every pair that has world start poses (the pairs of
    :func:`~scenarios.bench.merge.generate_pairs` do), by pair id, each in the world its
    scenario names (``worlds``); read from and written to
    ``folder / "twins-<config digest>.json"`` when ``folder`` is given."""
    config = config or AliasingConfig()
    specs: dict[str, WorldSpec] = {}

    def compute(pair: MergePair) -> WorldTwin:
        spec = specs.setdefault(pair.scenario, worlds(pair.scenario))
        found = world_twin(pair, world_grid(spec, world_starts(pair)), config)
        if progress is not None:
            verdict = "undecidable" if found.undecidable else "decidable"
            progress(f"world twin {pair.pair_id}: {verdict}")
        return found

    path = None
    if folder is not None:
        path = Path(folder) / f"twins-{config_key(config, _CACHE_VERSION)}.json"
    placed = [p for p in pairs if "start1_world" in p.info and "start2_world" in p.info]
    return cached_per_pair(placed, path, compute, WorldTwin.from_json)
