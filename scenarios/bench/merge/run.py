"""Running the merge methods over the pairs and scoring each answer against the truth.

Variants
--------
Besides the plain pair, ``ours`` and ``ours-nocrop`` can run on transformed copies of it, the
situations users meet with real map files (rows of method ``ours+<variant>``,
``ours-nocrop+<variant>``, scored against the variant's own truth):

``pad4000``  map 2 placed in a 4000 x 4000 all-UNKNOWN grid (same world position), as
             ``map_server`` maps padded to a fixed size are
``yaw``      map 2 saved with origin yaw :data:`VARIANT_YAW` and read back by
             :func:`~mrslam_env.mapio.load_map` (which turns the grid into the file's
             frame); the truth is the file's frame, in which the grid is rotated by the
             yaw about the origin corner (the ROS meaning)
``res``      map 2 at another resolution (:func:`~mrslam_env.merge.fuse.resample_map`):
             0.1 m for a map finer than 0.1 m, else 0.05 m

Proposal recall
---------------
For a method with an ``answer`` (the pipeline's :class:`~scenarios.bench.merge.methods.
PipelineMethod`), each row on an overlapping pair records ``proposal_hit``: whether any
judged candidate (refined or as proposed, confident or not) lies within
:data:`RECALL_TRANSLATION` / :data:`RECALL_ROTATION_DEG` of the truth at map 2's known
centroid.
"""

from __future__ import annotations

import math
import tempfile
import time
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mrslam_env.evaluation import cell_agreement, relative_transform_error
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import UNKNOWN, GridMap
from mrslam_env.validation import check_fields
from scenarios.bench.merge.methods import MergeMethod
from scenarios.bench.merge.pairs import MergePair, world_family

FloatArray = NDArray[np.float64]


OUTCOMES = ("success", "wrong", "refused", "correct_refusal")


@dataclass(frozen=True, slots=True, kw_only=True)
class Tolerance:
    """When a returned transform counts as correct."""

    translation: float = 0.25
    """Largest translation error of a success, m."""
    rotation_deg: float = 2.0
    """Largest rotation error of a success, degrees."""

    def __post_init__(self) -> None:
        check_fields(self, positive=("translation", "rotation_deg"))


VARIANT_YAW = 0.3
"""Origin yaw (rad) of the ``yaw`` variant's map 2 file."""
PAD_CELLS = 4000
"""Side (cells) of the ``pad4000`` variant's grid."""
RECALL_TRANSLATION = 0.5
"""A candidate this close to the truth (m, at map 2's known centroid) counts as proposed."""
RECALL_ROTATION_DEG = 3.0
"""... and this close in rotation (degrees)."""


def pad_grid(grid: GridMap, side: int = PAD_CELLS) -> GridMap:
    """``grid`` centred in a ``side`` x ``side`` all-UNKNOWN grid, every cell at the same
    world position (a grid larger than ``side`` is returned unchanged)."""
    rows, cols = grid.shape
    if rows >= side and cols >= side:
        return grid
    total_rows, total_cols = max(side, rows), max(side, cols)
    top, left = (total_rows - rows) // 2, (total_cols - cols) // 2
    cells = np.full((total_rows, total_cols), UNKNOWN, dtype=np.int8)
    cells[top : top + rows, left : left + cols] = grid.cells
    origin = (grid.origin[0] - left * grid.resolution, grid.origin[1] - top * grid.resolution)
    return GridMap(cells=cells, resolution=grid.resolution, origin=origin)


def yaw_variant(pair: MergePair, yaw: float = VARIANT_YAW) -> MergePair:
    """Map 2 written with origin yaw ``yaw`` and read back by :func:`load_map` (which turns
    the grid into the file's frame); the truth is the file's frame."""
    from mrslam_env.mapio import load_map, map_frame_from_lattice, save_map

    with tempfile.TemporaryDirectory() as folder:
        grid = load_map(save_map(Path(folder) / "m2.yaml", pair.m2, yaw=yaw))
    truth = compose(pair.map1_from_map2, inverse(map_frame_from_lattice(pair.m2, yaw)))
    return replace(pair, m2=grid, map1_from_map2=truth)


def resolution_variant(pair: MergePair) -> MergePair:
    """Map 2 at 0.1 m when finer than that, else at 0.05 m (same origin, same truth)."""
    from mrslam_env.merge.fuse import resample_map

    target = 0.1 if pair.m2.resolution < 0.1 - 1e-9 else 0.05
    return replace(pair, m2=resample_map(pair.m2, target))


VARIANTS = ("pad4000", "yaw", "res")
"""The variants :func:`run_merge_benchmark` knows (module docstring)."""


def make_variant(pair: MergePair, name: str) -> tuple[MergePair, dict[str, Any]]:
    """The pair transformed by variant ``name`` and what to note in its row."""
    if name == "pad4000":
        return replace(pair, m2=pad_grid(pair.m2)), {}
    if name == "yaw":
        return yaw_variant(pair), {"variant_yaw": VARIANT_YAW}
    if name == "res":
        changed = resolution_variant(pair)
        return changed, {"variant_resolution": changed.m2.resolution}
    raise ValueError(f"unknown variant {name!r}; variants are {', '.join(VARIANTS)}")


def known_centroid(grid: GridMap) -> FloatArray:
    """Mean position of a grid's known cells (its frame; the frame origin when none)."""
    known = np.argwhere(grid.cells != UNKNOWN)
    return grid.cell_to_world(known).mean(axis=0) if len(known) else np.zeros(2)


def proposal_hit(candidates: Sequence[FloatArray], truth: FloatArray, pivot: FloatArray) -> bool:
    """Whether a candidate is within the recall tolerance of the truth at ``pivot``."""
    for candidate in candidates:
        translation, rotation = relative_transform_error(candidate, truth, pivot)
        if translation <= RECALL_TRANSLATION and math.degrees(rotation) <= RECALL_ROTATION_DEG:
            return True
    return False


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
    translation, rotation = relative_transform_error(estimate, truth)
    ok = translation <= tolerance.translation and math.degrees(rotation) <= tolerance.rotation_deg
    return "success" if ok else "wrong"


def run_merge_benchmark(
    pairs: Sequence[MergePair],
    methods: Mapping[str, MergeMethod],
    *,
    seed: int = 0,
    tolerance: Tolerance | None = None,
    no_overlap_max: float = 0.02,
    warm_up: bool = True,
    variants: Sequence[str] = (),
    variant_methods: Sequence[str] = ("ours", "ours-nocrop"),
    progress: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Run every method on every pair; one row (dict) per (pair, method).

    Each call gets its own generator ``default_rng([seed, pair index, crc32(method)])``.
    With ``warm_up``, each method first runs once, untimed, on the first pair (numba
    compilation and caches are not timed).

    Row keys: ``pair_id, scenario, overlap, overlapping, method, outcome, returned, x, y,
    theta`` (the estimate or None), ``translation_error`` (m) and ``rotation_error_deg``
    (None when nothing was returned), ``seconds`` (wall) and ``cpu_seconds`` (the
    process's CPU time, :func:`time.process_time`: the figure to compare when other jobs
    share the cores), ``error`` (the one-line message when the
    method raised ``ValueError`` on the pair's maps, which counts as a refusal; else None),
    ``largest_side_cells`` (the longest side of the two grids), and the diagnostics
    ``agreement_truth`` / ``agreement_estimate`` (:func:`cell_agreement` under the truth and
    under the returned transform), ``family`` (:func:`~scenarios.bench.merge.pairs.world_family`),
    ``variant`` (None for the plain pair), ``proposal_hit`` (module docstring; None when
    the method gives no candidates or the pair has no overlap) and ``candidates``.

    With ``variants`` (names of :data:`VARIANTS`), each of ``variant_methods`` that is
    among ``methods`` also runs on each variant of every pair, as method
    ``<method>+<variant>``.
    """
    for variant in variants:
        if variant not in VARIANTS:
            raise ValueError(f"unknown variant {variant!r}; variants are {', '.join(VARIANTS)}")
    tolerance = tolerance if tolerance is not None else Tolerance()
    if warm_up and pairs:
        for name, method in methods.items():
            method(pairs[0].m1, pairs[0].m2, np.random.default_rng([seed, 999_983]))
            if progress is not None:
                progress(f"warmed up {name}")
    rows: list[dict[str, Any]] = []
    for index, pair in enumerate(pairs):
        for name, method in methods.items():
            rows.append(_run_one(pair, index, name, method, seed, tolerance, no_overlap_max, {}))
            if progress is not None:
                row = rows[-1]
                progress(f"{pair.pair_id} {name}: {row['outcome']} ({row['seconds']:.2f} s)")
        for variant in variants:
            changed, notes = make_variant(pair, variant)
            for base in (m for m in variant_methods if m in methods):
                name = f"{base}+{variant}"
                method = methods[base]
                rows.append(
                    _run_one(changed, index, name, method, seed, tolerance, no_overlap_max, notes)
                )
                if progress is not None:
                    row = rows[-1]
                    progress(f"{pair.pair_id} {name}: {row['outcome']} ({row['seconds']:.2f} s)")
    return rows


def _run_one(
    pair: MergePair,
    index: int,
    name: str,
    method: MergeMethod,
    seed: int,
    tolerance: Tolerance,
    no_overlap_max: float,
    notes: dict[str, Any],
) -> dict[str, Any]:
    """One (pair, method) row (:func:`run_merge_benchmark`)."""
    overlapping = pair.overlapping(no_overlap_max)
    rng = np.random.default_rng([seed, index, zlib.crc32(name.encode())])
    answer = getattr(method, "answer", None)
    candidates: list[FloatArray] | None = None
    started, cpu_started = time.perf_counter(), time.process_time()
    error = None
    try:
        if answer is not None:
            estimate, candidates = answer(pair.m1, pair.m2, rng)
        else:
            estimate = method(pair.m1, pair.m2, rng)
    except ValueError as failure:  # a method rejecting its input refuses to merge
        estimate, error = None, str(failure).splitlines()[0]
    seconds = time.perf_counter() - started
    cpu_seconds = time.process_time() - cpu_started
    errors: tuple[float | None, float | None] = (None, None)
    if estimate is not None:
        translation, rotation = relative_transform_error(estimate, pair.map1_from_map2)
        errors = (translation, math.degrees(rotation))
    hit = None
    if candidates is not None and overlapping:
        hit = proposal_hit(candidates, pair.map1_from_map2, known_centroid(pair.m2))
    return {
        "pair_id": pair.pair_id,
        "scenario": pair.scenario,
        "overlap": pair.overlap,
        "overlapping": overlapping,
        "method": name,
        "outcome": classify_outcome(estimate, pair.map1_from_map2, overlapping, tolerance),
        "returned": estimate is not None,
        "x": None if estimate is None else float(estimate[0]),
        "y": None if estimate is None else float(estimate[1]),
        "theta": None if estimate is None else float(estimate[2]),
        "translation_error": errors[0],
        "rotation_error_deg": errors[1],
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
        "error": error,
        "largest_side_cells": max(*pair.m1.shape, *pair.m2.shape),
        "agreement_truth": cell_agreement(pair.m1, pair.m2, pair.map1_from_map2),
        "agreement_estimate": None
        if estimate is None
        else cell_agreement(pair.m1, pair.m2, estimate),
        "family": world_family(pair.scenario),
        "variant": name.partition("+")[2] or None,
        "proposal_hit": hit,
        "candidates": None if candidates is None else len(candidates),
        **notes,
    }
