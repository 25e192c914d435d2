"""``merge_maps``: the whole virtual-robot-motion merge, from two grids to a verdict.

docs/design.md §5, offline (no rendezvous): the maps are brought to one working resolution; the
hypothesis side (:func:`~mrslam_env.merge.hypotheses.generate_hypotheses`: skeletons,
virtual runs along m1's skeleton, partial-map MCL in m2, clusters pooled and voted across
runs) proposes ranked ``map1_from_map2`` hypotheses, and a wall correlation over the
rotations the walls allow (:func:`~mrslam_env.merge.hypotheses.correlation_hypotheses`)
adds a few placements the virtual robot may have missed on a small overlap; the best few
are refined by the Birk & Carpin random walk
(:func:`~mrslam_env.merge.refine.refine_random_walk`) and judged cell by cell
(:func:`~mrslam_env.merge.dissimilarity.acceptance_index`). A hypothesis is
*confident* when the maps agree where they overlap (acceptance index), no wall of one map
crosses open floor of the other (conflicts), they overlap enough to say so (and a small
overlap fits tightly), and no *different* transform explains the maps about as well
(ambiguity: symmetric buildings, repeated rooms). Otherwise the answer is "no confident
merge" with the reason, never a guess. The winner is refined again at the finer input
resolution and the maps are fused.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mrslam_env.geometry import compose, inverse, transform_points, wrap_scalar
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.dissimilarity import (
    Agreement,
    DissimilarityConfig,
    DistanceMaps,
    acceptance_index,
    dissimilarity,
    distance_maps,
    largest_conflict,
)
from mrslam_env.merge.fuse import fuse_maps, resample_map
from mrslam_env.merge.hypotheses import (
    CorrelationConfig,
    HypothesisConfig,
    HypothesisSet,
    correlation_hypotheses,
    generate_hypotheses,
)
from mrslam_env.merge.mcl import MclConfig
from mrslam_env.merge.refine import RandomWalkConfig, RandomWalkResult, refine_random_walk
from mrslam_env.merge.virtual import VirtualRobotConfig

__all__ = [
    "MergeConfig",
    "MergeInputError",
    "MergeResult",
    "MergeTrace",
    "ScoredHypothesis",
    "ambiguous_rival",
    "merge_maps",
    "refine_transform",
    "relative_transform_error",
]

FloatArray = NDArray[np.float64]


class MergeInputError(ValueError):
    """The maps cannot be merged as given (empty, no free space, resolutions too far
    apart); the message is one line naming the problem."""


@dataclass(frozen=True, slots=True, kw_only=True)
class MergeConfig:
    """Everything :func:`merge_maps` decides with."""

    working_resolution: float = 0.1
    """Resolution (m) at which hypotheses are generated, refined and judged; maps finer
    than this are coarsened (never refined). The winner is refined again at the finer
    input resolution."""
    max_working_cells: int = 160_000
    """Coarse-to-fine for large maps: the working resolution is coarsened further (by
    whole factors) until each map has at most this many cells."""
    max_resolution_ratio: float = 4.0
    """Refuse (bad input) two maps whose resolutions differ by more than this factor."""
    min_known_area: float = 1.0
    """Each map needs at least this much known area (m²) with some free space in it."""
    virtual: VirtualRobotConfig = field(default_factory=VirtualRobotConfig)
    mcl: MclConfig = field(default_factory=MclConfig)
    pooling: HypothesisConfig = field(default_factory=HypothesisConfig)
    random_walk: RandomWalkConfig = field(default_factory=RandomWalkConfig)
    final_random_walk: RandomWalkConfig = field(
        default_factory=lambda: RandomWalkConfig(
            iterations=600,
            initial_std_xy=0.03,
            initial_std_theta=math.radians(0.5),
            dissimilarity=DissimilarityConfig(wall_sides=True),
        )
    )
    """The last refinement, at the input resolution. Its psi matches walls by the side
    they were seen from (``DissimilarityConfig.wall_sides``): two robots often see a thin
    wall from its two sides, and plain psi then lays the faces over each other. On 45
    verification-time map pairs of live runs (3 seeds each) the final error was median
    0.024 m, p90 0.048 m, max 0.105 m with plain psi; median 0.024, p90 0.040, max
    0.082 m with wall sides (600 iterations; 200 left some walks short, max 0.11 m)."""
    candidates: int = 4
    """How many of each direction's ranked hypotheses are refined and judged."""
    correlation: CorrelationConfig = field(default_factory=CorrelationConfig)
    """The second proposal source (:func:`~mrslam_env.merge.hypotheses.correlation_hypotheses`)."""
    correlation_candidates: int = 4
    """How many of the wall-correlation placements are refined and judged besides the
    virtual robot's (0 disables the source). The virtual robot misses the true placement
    when no short run both crosses a small overlap and converges there (6 of 64
    overlapping benchmark pairs of seed 1); the correlation ranked it in its first four on
    all of them, at about 30 ms a pair."""
    min_correlation_overlap: float = 0.2
    """A best candidate that only the wall correlation proposed (no confident virtual-robot
    candidate is the same answer) is accepted only when it overlaps at least this
    fraction of the smaller map's known cells (:attr:`Agreement.overlap_fraction`);
    otherwise the answer is "no confident merge". The correlation tries every translation
    at every wall-aligned rotation, so a chance fit of a small piece of a repetitive
    building (a maze corridor, the next shelf aisle) is far likelier among its proposals
    than among the virtual robot's: on the benchmark's no-overlap pairs such fits covered
    10-14 % of the smaller map, true small overlaps it found 23-44 %. Such candidates still
    count as rivals in the ambiguity test."""
    min_acceptance_index: float = 0.9
    """A confident merge agrees on at least this fraction of the cells known in both."""
    max_conflict_fraction: float = 0.01
    """... and has at most this fraction of conflicts (a wall of one map on open floor of
    the other, beyond a two-cell tolerance)."""
    min_overlap_area: float = 3.0
    """... and overlaps on at least this many m²."""
    small_overlap_area: float = 8.0
    """A best candidate that overlaps less than this (m²) ..."""
    small_overlap_max_psi: float = 0.6
    """... is accepted only when it fits tightly: psi at most this (cells of the working
    grid). A room fitted onto a similar room, or a dead end onto another, agrees almost
    everywhere on a few m² but leaves walls a cell or two apart; a true small overlap has
    little drift to blur it. On the merge benchmark's 240 pairs this turned two of the
    seven wrong answers (no-overlap pairs fitted over 6.3 and 7.3 m² at psi 0.93 and 0.92)
    into refusals and cost no success; true merges under 8 m² had psi up to 0.53, while
    larger true overlaps reach psi 1.0-1.3 (more drift), hence the area limit."""
    conflict_weight: float = 10.0
    """Score of a candidate: ``(agree - conflict_weight * conflicts) * cell area`` (m²)."""
    ambiguity_ratio: float = 0.25
    """Refuse when a confident candidate that is a *different* transform scores at least
    this fraction of the best one. Low on purpose: in repetitive buildings (shelf aisles,
    mirrored wings) the wrong placement often overlaps *more* than the right one and
    scores higher, so only "a second consistent answer exists at all" is a safe signal;
    the live system settles such cases by rendezvous instead."""
    contradicted_rival_factor: float = 3.0
    """A rival with at least this many times the best candidate's conflicts plus one ..."""
    contradicted_rival_length: float = 0.3
    """... whose largest unbroken group of conflicts is at least this long (m) ..."""
    contradicted_rival_ratio: float = 0.6
    """... makes the answer ambiguous only from this fraction of the best score, instead of
    ``ambiguity_ratio``. A part of one map fitted elsewhere (often a wing turned by 180°)
    leaves a few wall cells on open floor; the true placement of a clean pair leaves none
    or one or two. On the merge benchmark such rivals (4-19 conflicts, stretches of
    0.4-1.0 m, 50-70 % of the best score) made ours refuse pairs whose maps single out the
    truth."""
    distinct_translation: float = 0.5
    """Two transforms are the same answer when they move m2's known centre less than this
    (m) apart ..."""
    distinct_rotation: float = math.radians(8.0)
    """... and differ in rotation by less than this (rad)."""
    refuting_conflict_length: float = 2.0
    """A confident candidate is *refuted* (no longer confident, so no longer a rival
    answer) when its conflicts include an unbroken group of at least this many metres
    (cells x resolution: a wall of one map lying across open floor of the other) while
    a different confident candidate is clean (see ``clean_conflict_length``) and fits at
    least as well (psi). Under the true transform the largest group seen on the
    benchmark pairs was 1.0 m (drift, a wall seen through a doorway); a shelf row or
    outer wall placed across an aisle gives 2.3-4.7 m."""
    clean_conflict_length: float = 0.5
    """A candidate whose largest conflict group is at most this long (m) is clean."""
    symmetry_proposals: int = 3
    """Aliasing check: with a confident best candidate ``b`` and each of the next
    best-scoring different candidates ``c`` (at most this many; 0 disables it), the
    building may repeat under ``S = b ∘ c⁻¹`` (a shelf aisle further on, the mirrored
    wing); ``S ∘ b`` — the next repetition — is refined and judged too, so that a
    placement one aisle off is found to be ambiguous instead of merged."""

    def __post_init__(self) -> None:
        name = type(self).__name__

        def number(attr: str) -> float:
            value = getattr(self, attr)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{name}.{attr} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"{name}.{attr} must be finite, got {value!r}")
            return float(value)

        for attr in (
            "working_resolution",
            "min_known_area",
            "min_overlap_area",
            "small_overlap_max_psi",
            "distinct_translation",
            "distinct_rotation",
        ):
            if number(attr) <= 0:
                raise ValueError(f"{name}.{attr} must be > 0, got {getattr(self, attr)!r}")
        if number("max_resolution_ratio") < 1.0:
            raise ValueError(
                f"{name}.max_resolution_ratio must be >= 1, got {self.max_resolution_ratio!r}"
            )
        for attr in ("contradicted_rival_factor", "contradicted_rival_length"):
            if number(attr) < 0:
                raise ValueError(f"{name}.{attr} must be >= 0, got {getattr(self, attr)!r}")
        if number("small_overlap_area") < 0:
            raise ValueError(
                f"{name}.small_overlap_area must be >= 0, got {self.small_overlap_area!r}"
            )
        if number("conflict_weight") < 0:
            raise ValueError(f"{name}.conflict_weight must be >= 0, got {self.conflict_weight!r}")
        for attr in (
            "min_acceptance_index",
            "max_conflict_fraction",
            "ambiguity_ratio",
            "contradicted_rival_ratio",
            "min_correlation_overlap",
        ):
            if not 0.0 <= number(attr) <= 1.0:
                raise ValueError(f"{name}.{attr} must be in [0, 1], got {getattr(self, attr)!r}")
        value = self.correlation_candidates
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= 0):
            raise ValueError(f"{name}.correlation_candidates must be an int >= 0, got {value!r}")
        for attr in ("max_working_cells", "candidates"):
            value = getattr(self, attr)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                raise ValueError(f"{name}.{attr} must be an int >= 1, got {value!r}")
        value = self.symmetry_proposals
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= 0):
            raise ValueError(f"{name}.symmetry_proposals must be an int >= 0, got {value!r}")
        if number("clean_conflict_length") < 0:
            raise ValueError(
                f"{name}.clean_conflict_length must be >= 0, got {self.clean_conflict_length!r}"
            )
        if number("refuting_conflict_length") <= self.clean_conflict_length:
            raise ValueError(
                f"{name}.refuting_conflict_length must be > clean_conflict_length "
                f"({self.clean_conflict_length}), got {self.refuting_conflict_length!r}"
            )
        for attr, kind in (
            ("virtual", VirtualRobotConfig),
            ("mcl", MclConfig),
            ("pooling", HypothesisConfig),
            ("correlation", CorrelationConfig),
            ("random_walk", RandomWalkConfig),
            ("final_random_walk", RandomWalkConfig),
        ):
            value = getattr(self, attr)
            if not isinstance(value, kind):
                raise ValueError(f"{name}.{attr} must be a {kind.__name__}, got {value!r}")


@dataclass(frozen=True, slots=True, kw_only=True)
class ScoredHypothesis:
    """One hypothesis after refinement and judgement.

    Attributes
    ----------
    map1_from_map2 : ndarray, shape (3,)
        The refined transform (m, m, rad).
    initial : ndarray, shape (3,)
        The transform as proposed by the virtual robot (before refinement).
    support : float
        The proposal's scan support (fraction of virtual beams landing on m2's walls;
        0.0 for a symmetry or correlation proposal).
    votes : int
        Virtual runs that voted for it (0 for a symmetry or correlation proposal).
    psi : float
        Dissimilarity after refinement (cells; lower is better).
    agreement : Agreement
        Cell-by-cell agreement after refinement.
    score : float
        ``(agree - conflict_weight * conflicts) * cell area``, m².
    confident : bool
        Passes the acceptance index, conflict and overlap tests (and is not refuted).
    conflict_length : float
        Length (m) of the largest unbroken group of conflicts
        (:func:`~mrslam_env.merge.dissimilarity.largest_conflict` x resolution); 0.0
        when not measured (candidates that are not confident).
    refuted : bool
        Was confident, but a long conflict group refutes it against a clean rival
        (:attr:`MergeConfig.refuting_conflict_length`).
    proposed_by : str
        ``"virtual robot"`` (the hypothesis side), ``"correlation"`` (the wall
        correlation, :func:`~mrslam_env.merge.hypotheses.correlation_hypotheses`) or
        ``"symmetry"`` (:func:`symmetry_proposals`, the aliasing check).
    """

    map1_from_map2: FloatArray
    initial: FloatArray
    support: float
    votes: int
    psi: float
    agreement: Agreement
    score: float
    confident: bool
    conflict_length: float = 0.0
    refuted: bool = False
    proposed_by: str = "virtual robot"

    @property
    def acceptance_index(self) -> float:
        return self.agreement.index

    @property
    def overlap(self) -> float:
        """Fraction of the smaller map's known cells that the other map also knows."""
        return self.agreement.overlap_fraction

    def as_dict(self) -> dict[str, object]:
        x, y, theta = (float(v) for v in self.map1_from_map2)
        return {
            "transform": {"x": x, "y": y, "theta": theta},
            "support": round(self.support, 4),
            "votes": self.votes,
            "psi": round(self.psi, 4) if math.isfinite(self.psi) else None,
            "acceptance_index": round(self.agreement.index, 4),
            "overlap": round(self.agreement.overlap_fraction, 4),
            "conflicts": self.agreement.conflicts,
            "score": round(self.score, 3),
            "confident": self.confident,
            "conflict_length": round(self.conflict_length, 3),
            "refuted": self.refuted,
            "proposed_by": self.proposed_by,
        }


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class MergeTrace:
    """What happened inside, for the recorder (all at the working resolution).

    Attributes
    ----------
    working1, working2 : GridMap
        The maps the hypotheses were made on.
    hypotheses : HypothesisSet
        Skeletons, virtual runs and MCL results (particle histories) of the hypothesis
        side.
    refinements : list of RandomWalkResult
        One per judged candidate, in the order of :attr:`MergeResult.hypotheses`, with
        their random-walk traces.
    """

    working1: GridMap
    working2: GridMap
    hypotheses: HypothesisSet
    refinements: list[RandomWalkResult]


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class MergeResult:
    """The outcome of :func:`merge_maps`.

    Attributes
    ----------
    transform : ndarray, shape (3,), or None
        ``map1_from_map2`` (m, m, rad, in the maps' own frames), or None when there is no
        confident merge.
    reason : str
        One line: why the transform was accepted, or why there is none.
    hypotheses : list of ScoredHypothesis
        The judged candidates, best first.
    chosen : ScoredHypothesis or None
        The accepted candidate (its final refinement is :attr:`transform`).
    fused : GridMap or None
        m1 and m2 fused in m1's frame, at m1's resolution, when merged.
    agreement : Agreement or None
        The final agreement at the input resolution, when merged.
    psi : float
        The final dissimilarity (cells), NaN when not merged.
    seconds : dict of str to float
        Wall time per stage and ``"total"``.
    trace : MergeTrace or None
        With ``trace=True``.
    """

    transform: FloatArray | None
    reason: str
    hypotheses: list[ScoredHypothesis]
    chosen: ScoredHypothesis | None
    fused: GridMap | None
    agreement: Agreement | None
    psi: float
    seconds: dict[str, float]
    trace: MergeTrace | None = None

    @property
    def merged(self) -> bool:
        return self.transform is not None

    def as_dict(self) -> dict[str, object]:
        """The ``mrslam merge --json`` report (docs/design.md §8)."""
        transform = None
        if self.transform is not None:
            x, y, theta = (float(v) for v in self.transform)
            transform = {"x": x, "y": y, "theta": theta}
        return {
            "transform": transform,
            "score": None if self.chosen is None else round(self.chosen.score, 3),
            "acceptance_index": None if self.agreement is None else round(self.agreement.index, 4),
            "psi": round(self.psi, 4) if math.isfinite(self.psi) else None,
            "reason": self.reason,
            "hypotheses": [h.as_dict() for h in self.hypotheses],
            "seconds": round(self.seconds.get("total", math.nan), 4),
            "stage_seconds": {k: round(v, 4) for k, v in self.seconds.items()},
        }


# --- input checks and resolutions -------------------------------------------------------------


def _check_input(grid: GridMap, name: str, config: MergeConfig) -> None:
    if not isinstance(grid, GridMap):
        raise MergeInputError(f"{name} must be a GridMap, got {type(grid).__name__}")
    if grid.cells.size == 0:
        raise MergeInputError(f"{name} is empty (0 cells)")
    known = np.count_nonzero(~grid.unknown)
    if known == 0:
        raise MergeInputError(f"{name} is all unknown: nothing to merge")
    if not grid.free.any():
        raise MergeInputError(f"{name} has no free space: nothing to localise in")
    area = known * grid.resolution**2
    if area < config.min_known_area:
        raise MergeInputError(
            f"{name} knows only {area:.2f} m² (need at least {config.min_known_area} m²)"
        )


def _working_resolution(m1: GridMap, m2: GridMap, config: MergeConfig) -> float:
    """The coarsest of the inputs and ``working_resolution``, coarsened by whole factors
    until both maps fit in ``max_working_cells``."""
    base = max(m1.resolution, m2.resolution, config.working_resolution)
    factor = 1
    while True:
        resolution = base * factor
        cells = max(
            (m.cells.shape[0] * m.resolution / resolution)
            * (m.cells.shape[1] * m.resolution)
            / resolution
            for m in (m1, m2)
        )
        if cells <= config.max_working_cells:
            return resolution
        factor += 1


def _at_resolution(grid: GridMap, resolution: float) -> GridMap:
    if math.isclose(grid.resolution, resolution, rel_tol=1e-9):
        return grid
    return resample_map(grid, resolution)


def same_answer(a: FloatArray, b: FloatArray, pivot: FloatArray, config: MergeConfig) -> bool:
    """Whether two transforms are one answer: they put ``pivot`` (a point of m2, its
    frame) within ``distinct_translation`` and turn within ``distinct_rotation``."""
    point = np.asarray(pivot, dtype=np.float64)[None, :]
    moved = float(np.hypot(*(transform_points(a, point)[0] - transform_points(b, point)[0])))
    turned = abs(wrap_scalar(float(a[2] - b[2])))
    return moved < config.distinct_translation and turned < config.distinct_rotation


# --- judging -------------------------------------------------------------------------------


def judge(agreement: Agreement, resolution: float, config: MergeConfig) -> tuple[float, bool, str]:
    """Score (m²), whether it is confident, and if not, why (one phrase)."""
    cell_area = resolution**2
    score = (agreement.agree - config.conflict_weight * agreement.conflicts) * cell_area
    overlap_area = agreement.overlap * cell_area
    if overlap_area < config.min_overlap_area:
        return score, False, f"overlap {overlap_area:.1f} m² < {config.min_overlap_area} m²"
    if agreement.index < config.min_acceptance_index:
        return (
            score,
            False,
            f"acceptance index {agreement.index:.3f} < {config.min_acceptance_index}",
        )
    if agreement.conflict_fraction > config.max_conflict_fraction:
        return (
            score,
            False,
            f"conflicts {agreement.conflict_fraction:.3f} > {config.max_conflict_fraction}",
        )
    return score, True, ""


def _score_candidate(
    w1: GridMap,
    w2: GridMap,
    d1: DistanceMaps,
    d2: DistanceMaps,
    hypothesis_transform: FloatArray,
    support: float,
    votes: int,
    config: MergeConfig,
    rng: np.random.Generator,
    trace: bool,
) -> tuple[ScoredHypothesis, RandomWalkResult, str]:
    walk = refine_random_walk(
        w1,
        w2,
        hypothesis_transform,
        config=config.random_walk,
        rng=rng,
        distances1=d1,
        distances2=d2,
        trace=trace,
    )
    agreement = acceptance_index(w1, w2, walk.transform, distances1=d1, distances2=d2)
    score, confident, why = judge(agreement, w1.resolution, config)
    conflict_length = (
        largest_conflict(w1, w2, walk.transform, distances1=d1, distances2=d2) * w1.resolution
        if confident
        else 0.0
    )
    scored = ScoredHypothesis(
        map1_from_map2=np.asarray(walk.transform, dtype=np.float64),
        initial=np.asarray(hypothesis_transform, dtype=np.float64),
        support=support,
        votes=votes,
        psi=float(walk.psi),
        agreement=agreement,
        score=score,
        confident=confident,
        conflict_length=conflict_length,
    )
    return scored, walk, why


def refute(
    scored: list[ScoredHypothesis], pivot: FloatArray, config: MergeConfig
) -> list[tuple[int, str]]:
    """Which confident candidates the evidence refutes, with why (indices into ``scored``).

    A confident candidate is refuted when one unbroken group of its conflicts is at least
    ``refuting_conflict_length`` long (a wall across open floor, which drift does not
    produce) and a *different* confident candidate is clean (largest group at most
    ``clean_conflict_length``) and fits at least as well (psi no larger). Only a
    candidate that has a clean rival is refuted, so evidence can settle an ambiguity
    but never leaves a refuted candidate as the answer.
    """
    clean = [h for h in scored if h.confident and h.conflict_length <= config.clean_conflict_length]
    refuted = []
    for index, h in enumerate(scored):
        if not h.confident or h.conflict_length < config.refuting_conflict_length:
            continue
        if any(
            c.psi <= h.psi and not same_answer(c.map1_from_map2, h.map1_from_map2, pivot, config)
            for c in clean
        ):
            refuted.append(
                (index, f"refuted: a {h.conflict_length:.1f} m wall of one map on open floor")
            )
    return refuted


def ambiguous_rival(
    scored: list[ScoredHypothesis], pivot: FloatArray, config: MergeConfig
) -> ScoredHypothesis | None:
    """The first confident candidate that is a *different* answer from the best one
    (``scored[0]``, sorted best first) and scores enough to make the answer ambiguous, or
    None.

    Enough is ``ambiguity_ratio`` of the best score; for a *contradicted* rival (at least
    ``contradicted_rival_factor`` x (best's conflicts + 1) conflicts, with an unbroken
    group of at least ``contradicted_rival_length``) it is ``contradicted_rival_ratio``.
    """
    best = scored[0]
    for other in scored[1:]:
        if not other.confident or same_answer(
            best.map1_from_map2, other.map1_from_map2, pivot, config
        ):
            continue
        contradicted = (
            other.agreement.conflicts
            >= config.contradicted_rival_factor * (best.agreement.conflicts + 1)
            and other.conflict_length >= config.contradicted_rival_length
        )
        ratio = config.contradicted_rival_ratio if contradicted else config.ambiguity_ratio
        if other.score >= ratio * best.score:
            return other
    return None


def symmetry_proposals(
    scored: list[ScoredHypothesis], pivot: FloatArray, config: MergeConfig
) -> list[FloatArray]:
    """Placements a repeating building would also allow (aliasing check).

    ``scored`` is sorted best first and its first entry is confident. For each of the
    next ``symmetry_proposals`` different candidates ``c`` with a positive score, the
    building may repeat under ``S = b ∘ c⁻¹`` (it carries ``c`` onto the best ``b``);
    then ``S ∘ b`` is a placement the maps may fit as well. Duplicates of candidates
    already judged are dropped.
    """
    best = scored[0].map1_from_map2
    known = [h.map1_from_map2 for h in scored]
    proposals: list[FloatArray] = []
    for other in scored[1:]:
        if len(proposals) >= config.symmetry_proposals:
            break
        if other.score <= 0 or same_answer(best, other.map1_from_map2, pivot, config):
            continue
        repeat = compose(compose(best, inverse(other.map1_from_map2)), best)
        repeat[2] = wrap_scalar(float(repeat[2]))
        if not any(same_answer(repeat, k, pivot, config) for k in known + proposals):
            proposals.append(repeat)
    return proposals


# --- the pipeline ----------------------------------------------------------------------------


def _propose(
    w1: GridMap,
    w2: GridMap,
    pivot: FloatArray,
    config: MergeConfig,
    rng: np.random.Generator,
    trace: bool,
    seconds: dict[str, float],
) -> tuple[HypothesisSet, list[tuple[FloatArray, float, int, str]]]:
    """Hypotheses from both directions: the virtual robot drives in m1 and localises in
    m2, and the other way round (inverted). A run only localises where the two maps
    overlap; when one map is much larger, few of its runs fall in the shared part, while
    the smaller map's runs mostly do. The two ranked lists are interleaved and
    duplicates (:func:`same_answer`) dropped; at most ``candidates`` from each. Then the
    best ``correlation_candidates`` wall-correlation placements that are not duplicates.
    Each entry: transform, support, votes, source (:attr:`ScoredHypothesis.proposed_by`)."""
    forward = generate_hypotheses(
        w1, w2, virtual=config.virtual, mcl=config.mcl, pooling=config.pooling, rng=rng,
        trace=trace,
    )  # fmt: skip
    backward = generate_hypotheses(
        w2, w1, virtual=config.virtual, mcl=config.mcl, pooling=config.pooling, rng=rng
    )
    for name, found in (("forward", forward), ("backward", backward)):
        for stage, value in found.timings.items():
            seconds[f"hypotheses.{name}.{stage}"] = value
    ahead = [(h.map1_from_map2, h.support, h.votes) for h in forward.hypotheses]
    behind = [(inverse(h.map1_from_map2), h.support, h.votes) for h in backward.hypotheses]
    initials: list[tuple[FloatArray, float, int, str]] = []
    for k in range(config.candidates):
        for ranked in (ahead, behind):
            if k < len(ranked) and not any(
                same_answer(ranked[k][0], kept[0], pivot, config) for kept in initials
            ):
                initials.append((*ranked[k], "virtual robot"))
    if config.correlation_candidates > 0:
        tick = time.perf_counter()
        placements = correlation_hypotheses(w1, w2, config.correlation)
        for placement in placements[: config.correlation_candidates]:
            transform = placement.map1_from_map2
            if not any(same_answer(transform, kept[0], pivot, config) for kept in initials):
                initials.append((transform, 0.0, 0, "correlation"))
        seconds["hypotheses.correlation"] = time.perf_counter() - tick
    return forward, initials


def merge_maps(
    m1: GridMap,
    m2: GridMap,
    config: MergeConfig | None = None,
    *,
    rng: np.random.Generator | int | None = None,
    trace: bool = False,
) -> MergeResult:
    """Merge two partial occupancy maps by virtual robot motion (docs/design.md §5).

    Parameters
    ----------
    m1, m2 : GridMap
        The maps, each in its own frame (resolutions may differ by up to
        ``config.max_resolution_ratio``).
    config : MergeConfig, optional
    rng : numpy.random.Generator or int, optional
        All randomness (an int seeds a new generator; None: seed 0, so that a merge is
        reproducible by default).
    trace : bool
        Keep what the recorder draws (:class:`MergeTrace`).

    Returns
    -------
    MergeResult
        ``transform`` is ``map1_from_map2`` or None ("no confident merge", with
        ``reason``).

    Raises
    ------
    MergeInputError
        Empty or all-unknown maps, maps without free space, resolutions too far apart.
    """
    config = config if config is not None else MergeConfig()
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(0 if rng is None else rng)
    started = time.perf_counter()
    seconds: dict[str, float] = {}
    _check_input(m1, "map 1", config)
    _check_input(m2, "map 2", config)
    ratio = max(m1.resolution, m2.resolution) / min(m1.resolution, m2.resolution)
    if ratio > config.max_resolution_ratio:
        raise MergeInputError(
            f"resolutions {m1.resolution} m and {m2.resolution} m differ by {ratio:.1f}x "
            f"(at most {config.max_resolution_ratio}x)"
        )

    tick = time.perf_counter()
    resolution = _working_resolution(m1, m2, config)
    w1, w2 = _at_resolution(m1, resolution), _at_resolution(m2, resolution)
    for name, working in (("map 1", w1), ("map 2", w2)):
        if not working.free.any():
            raise MergeInputError(
                f"{name} has no free space left at the working resolution {resolution:g} m "
                "(only scattered free cells)"
            )
    sides = config.random_walk.dissimilarity.wall_sides
    d1, d2 = distance_maps(w1, sides=sides), distance_maps(w2, sides=sides)
    seconds["prepare"] = time.perf_counter() - tick

    tick = time.perf_counter()
    pivot = w2.cell_to_world(np.argwhere(~w2.unknown).mean(axis=0)[None, :])[0]
    proposals, initials = _propose(w1, w2, pivot, config, rng, trace, seconds)
    seconds["hypotheses"] = time.perf_counter() - tick

    tick = time.perf_counter()
    scored: list[ScoredHypothesis] = []
    walks: list[RandomWalkResult] = []
    reasons: list[str] = []
    for transform, support, votes, source in initials:
        candidate, walk, why = _score_candidate(
            w1, w2, d1, d2, transform, support, votes, config, rng, trace
        )
        scored.append(replace(candidate, proposed_by=source))
        walks.append(walk)
        reasons.append(why)

    def rank() -> None:
        nonlocal scored, walks, reasons
        for index, why in refute(scored, pivot, config):
            scored[index] = replace(scored[index], confident=False, refuted=True)
            reasons[index] = why
        order = sorted(
            range(len(scored)), key=lambda i: (not scored[i].confident, -scored[i].score)
        )
        scored = [scored[i] for i in order]
        walks = [walks[i] for i in order]
        reasons = [reasons[i] for i in order]

    rank()
    if scored and scored[0].confident:
        for transform in symmetry_proposals(scored, pivot, config):
            candidate, walk, why = _score_candidate(
                w1, w2, d1, d2, transform, 0.0, 0, config, rng, trace
            )
            scored.append(replace(candidate, proposed_by="symmetry"))
            walks.append(walk)
            reasons.append(why)
        rank()
    seconds["judge"] = time.perf_counter() - tick

    merge_trace = (
        MergeTrace(working1=w1, working2=w2, hypotheses=proposals, refinements=walks)
        if trace
        else None
    )

    def refuse(reason: str) -> MergeResult:
        seconds["total"] = time.perf_counter() - started
        return MergeResult(
            transform=None,
            reason=f"no confident merge: {reason}",
            hypotheses=scored,
            chosen=None,
            fused=None,
            agreement=None,
            psi=math.nan,
            seconds=seconds,
            trace=merge_trace,
        )

    if not scored:
        return refuse("the virtual robot found no hypothesis (too little structure)")
    best = scored[0]
    if not best.confident:
        return refuse(f"best hypothesis fails: {reasons[0]}")
    rival = ambiguous_rival(scored, pivot, config)
    if rival is not None:
        return refuse(
            "ambiguous: two different transforms fit "
            f"(scores {best.score:.1f} and {rival.score:.1f} m²)"
        )
    if (
        best.proposed_by == "correlation"
        and best.agreement.overlap_fraction < config.min_correlation_overlap
        and not any(
            o.confident
            and o.proposed_by != "correlation"
            and same_answer(best.map1_from_map2, o.map1_from_map2, pivot, config)
            for o in scored[1:]
        )
    ):
        return refuse(
            "only the wall correlation proposes the best transform and it overlaps "
            f"{best.agreement.overlap_fraction:.0%} of the smaller map "
            f"(< {config.min_correlation_overlap:.0%})"
        )

    overlap_area = best.agreement.overlap * resolution**2
    if overlap_area < config.small_overlap_area and best.psi > config.small_overlap_max_psi:
        return refuse(
            f"the best transform overlaps only {overlap_area:.1f} m² and fits loosely "
            f"(psi {best.psi:.2f} > {config.small_overlap_max_psi} cells)"
        )

    tick = time.perf_counter()
    transform = best.map1_from_map2
    agreement = best.agreement
    fine = min(m1.resolution, m2.resolution)
    if fine < resolution * (1.0 - 1e-9):
        transform, psi, agreement = _refine_at_input_resolution(m1, m2, transform, config, rng)
    else:
        psi = float(dissimilarity(w1, w2, transform, distances1=d1, distances2=d2))
    seconds["final_refine"] = time.perf_counter() - tick

    tick = time.perf_counter()
    fused = fuse_maps(m1, _at_resolution(m2, m1.resolution), transform)
    seconds["fuse"] = time.perf_counter() - tick
    seconds["total"] = time.perf_counter() - started
    runner_up = next(
        (
            o
            for o in scored[1:]
            if o.confident and not same_answer(best.map1_from_map2, o.map1_from_map2, pivot, config)
        ),
        None,
    )
    margin = "" if runner_up is None else f", next confident candidate {runner_up.score:.1f} m²"
    return MergeResult(
        transform=transform,
        reason=(
            f"merged: acceptance index {agreement.index:.3f}, overlap "
            f"{agreement.overlap * fine**2:.1f} m², score {best.score:.1f} m²{margin}"
        ),
        hypotheses=scored,
        chosen=replace(best, map1_from_map2=transform),
        fused=fused,
        agreement=agreement,
        psi=psi,
        seconds=seconds,
        trace=merge_trace,
    )


def refine_transform(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: FloatArray,
    config: MergeConfig | None = None,
    *,
    rng: np.random.Generator,
) -> tuple[FloatArray, float, Agreement]:
    """Refine a known-good ``map1_from_map2`` on the current maps (docs/design.md §5 step 6):
    the random walk at the working resolution, then at the finer input resolution.

    For a transform verified some other way (a rendezvous); no acceptance decision is
    made. Returns the transform, its psi (cells) and the agreement at the fine
    resolution.
    """
    config = config if config is not None else MergeConfig()
    resolution = _working_resolution(m1, m2, config)
    w1, w2 = _at_resolution(m1, resolution), _at_resolution(m2, resolution)
    walk = refine_random_walk(w1, w2, map1_from_map2, config=config.random_walk, rng=rng)
    return _refine_at_input_resolution(m1, m2, walk.transform, config, rng)


def _refine_at_input_resolution(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: FloatArray,
    config: MergeConfig,
    rng: np.random.Generator,
) -> tuple[FloatArray, float, Agreement]:
    """The last random walk, at the finer input resolution: transform, psi, agreement."""
    fine = min(m1.resolution, m2.resolution)
    f1, f2 = _at_resolution(m1, fine), _at_resolution(m2, fine)
    sides = config.final_random_walk.dissimilarity.wall_sides
    d1, d2 = distance_maps(f1, sides=sides), distance_maps(f2, sides=sides)
    final = refine_random_walk(
        f1,
        f2,
        map1_from_map2,
        config=config.final_random_walk,
        rng=rng,
        distances1=d1,
        distances2=d2,
    )
    transform = np.asarray(final.transform, dtype=np.float64)
    agreement = acceptance_index(f1, f2, transform, distances1=d1, distances2=d2)
    return transform, float(final.psi), agreement


def relative_transform_error(
    estimate: FloatArray, truth: FloatArray, pivot: FloatArray | None = None
) -> tuple[float, float]:
    """Translation error (m) and absolute rotation error (rad) of ``estimate`` against
    ``truth`` (both ``map1_from_map2``): the translation of ``inverse(truth) ∘ estimate``
    measured at ``pivot`` (a point of m2; default its frame's origin)."""
    error = compose(inverse(truth), estimate)
    point = np.zeros(2) if pivot is None else np.asarray(pivot, dtype=np.float64)
    moved = transform_points(error, point[None, :])[0] - point
    return float(np.hypot(*moved)), abs(wrap_scalar(float(error[2])))
