"""Running the merge methods over the pairs and scoring each answer against the truth."""

from __future__ import annotations

import math
import time
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mrslam_env.evaluation import cell_agreement, relative_transform_error
from mrslam_env.validation import check_fields
from scenarios.bench.merge.methods import MergeMethod
from scenarios.bench.merge.pairs import MergePair

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
            errors: tuple[float | None, float | None] = (None, None)
            if estimate is not None:
                translation, rotation = relative_transform_error(estimate, pair.map1_from_map2)
                errors = (translation, math.degrees(rotation))
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
