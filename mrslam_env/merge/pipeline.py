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
*confident* when no wall of one map crosses open floor of the other (conflicts), they
overlap enough to say so (and a small overlap fits tightly), and no *different*
transform explains the maps about as well (ambiguity: symmetric buildings, repeated
rooms). Otherwise the answer is "no confident merge" with the reason, never a guess. The
winner is refined again at the finer input resolution and the maps are fused.

:func:`merge_maps` runs the stages in order: prepare, propose, score, decide (the rules,
each a named pure function in :mod:`mrslam_env.merge.decide`), refine, fuse.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from mrslam_env.geometry import compose, inverse, wrap_scalar
from mrslam_env.gridmap import GridMap, crop_to_known
from mrslam_env.merge.decide import (
    Candidates,
    Decision,
    ambiguous_rival,
    ambiguous_rivals,
    decide,
    judge,
    refute,
    same_answer,
    same_part,
    switching_rival,
    unsettled_rival,
)
from mrslam_env.merge.dissimilarity import (
    Agreement,
    DissimilarityConfig,
    DistanceMaps,
    WallMatch,
    acceptance_index,
    dissimilarity,
    distance_maps,
    largest_conflict,
    wall_match,
)
from mrslam_env.merge.fuse import at_resolution, fuse_maps
from mrslam_env.merge.hypotheses import (
    CorrelationConfig,
    Hypothesis,
    HypothesisConfig,
    HypothesisSet,
    correlation_hypotheses,
    generate_hypotheses,
    neighbour_placements,
)
from mrslam_env.merge.mcl import MclConfig
from mrslam_env.merge.refine import RandomWalkConfig, RandomWalkResult, refine_random_walk
from mrslam_env.merge.spectrum import hough_rotations
from mrslam_env.merge.virtual import VirtualRobotConfig
from mrslam_env.validation import check_fields, require

__all__ = [
    "ALL_PLACEMENTS",
    "MergeConfig",
    "MergeInputError",
    "MergeResult",
    "MergeTrace",
    "ScoredHypothesis",
    "ambiguous_rival",
    "distinct_placements",
    "merge_maps",
    "refine_transform",
    "same_answer",
]

FloatArray = NDArray[np.float64]


class MergeInputError(ValueError):
    """The maps cannot be merged as given (empty, no free space, resolutions too far
    apart); the message is one line naming the problem."""


def _fine_walk(iterations: int) -> RandomWalkConfig:
    """A random walk at the input resolution: small first steps, walls matched by the
    side they were seen from."""
    return RandomWalkConfig(
        iterations=iterations,
        initial_std_xy=0.03,
        initial_std_theta=math.radians(0.5),
        dissimilarity=DissimilarityConfig(wall_sides=True),
    )


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
    crop_to_known: bool = True
    """Cut each map to its known area (plus :data:`KNOWN_MARGIN` cells) before anything
    else, so that unknown padding (gmapping's 4000 x 4000 default) changes neither the
    answer nor the cost, and the working resolution is chosen from the known extent
    (docs/decisions.md)."""
    cascade: bool = False
    """Cheap proposals first: the wall-correlation placements (``correlation_candidates``,
    with those at the Hough rotations) are refined and judged alone, by the same scoring
    and decision step (aliasing check included); when that accepts one, the virtual robot
    (skeletons, virtual runs, MCL) does not run. Otherwise the whole pipeline runs as it
    does without the cascade, to the same answer bit for bit (the cheap pass draws from a
    copy of the generator). The cheap pass answers only when no other placement it judged,
    confident or not, is an uncontradicted rival
    (:func:`~mrslam_env.merge.decide.unsettled_rival`), and it also judges the wall
    correlation's best distinct answers (``cascade_rivals``), so that a mirrored wing's
    true placement is seen as a rival. Off by default: on a held-out set it merged a
    chance fit of two maps without overlap that the whole pipeline refused, both on the
    edge of ``max_conflict_fraction`` (docs/decisions.md, "The cascade's rival search");
    it halves the time of the pairs it answers. No effect when ``correlation_candidates``
    is 0."""
    cascade_rivals: int = 6
    """The cascade's rival search: its cheap pass refines and judges this many *distinct*
    wall-correlation placements (:func:`distinct_placements`: every local maximum over
    the wall orientations' rotations, best first, one per answer), not only the
    ``correlation_candidates`` best ones, before it may settle a merge. In a building
    that repeats (a mirrored wing) the wall correlation often ranks the true placement
    and its twin among its first few *answers* while its first few placements are the
    twin's, a few cells apart; the rival then shows up in the cheap pass as it would in
    the whole pipeline, and the decision step refuses, or the whole pipeline runs
    (docs/decisions.md, "The cascade")."""
    virtual: VirtualRobotConfig = field(default_factory=VirtualRobotConfig)
    mcl: MclConfig = field(default_factory=MclConfig)
    pooling: HypothesisConfig = field(default_factory=HypothesisConfig)
    random_walk: RandomWalkConfig = field(default_factory=RandomWalkConfig)
    final_random_walk: RandomWalkConfig = field(default_factory=lambda: _fine_walk(600))
    """The last refinement, at the input resolution. Its psi matches walls by the side
    they were seen from (``DissimilarityConfig.wall_sides``): two robots often see a thin
    wall from its two sides, and plain psi then lays the faces over each other, a wall's
    thickness off. 600 iterations: shorter walks leave some short of the optimum."""
    candidates: int = 4
    """How many of each direction's ranked hypotheses are refined and judged."""
    correlation: CorrelationConfig = field(default_factory=CorrelationConfig)
    """The second proposal source (:func:`~mrslam_env.merge.hypotheses.correlation_hypotheses`)."""
    correlation_candidates: int = 4
    """How many of the wall-correlation placements are refined and judged besides the
    virtual robot's (0 disables the source, its placements at the Hough rotations
    included). The virtual robot misses the true placement when no short run both
    crosses a small overlap and converges there; the correlation ranks it among its first
    few, for a few tens of ms a pair."""
    hough_candidates: int = 2
    """How many more wall-correlation placements, at the rotations the Hough spectra allow
    (:func:`~mrslam_env.merge.spectrum.hough_rotations`, ``hough_peaks`` peaks) instead of
    the wall orientations', are refined and judged besides the others, when they are not
    already proposed (0 disables them; so does ``correlation_candidates = 0``, which turns
    the whole correlation source off, as the live team does). The spectrum
    weighs long straight walls by the square of their length, so it finds the rotation of
    a cluttered real map whose wall-orientation histogram is flat."""
    hough_peaks: int = 2
    """Peaks of the Hough-spectrum cross-correlation used; each gives two rotations."""
    hough_sweep: float = math.radians(3.0)
    """Coarse to fine: around each Hough rotation, the rotations within this (rad) ...
    (0: the Hough rotation alone)."""
    hough_sweep_step: float = math.radians(1.0)
    """... at this step (rad) are scored by the wall correlation, and the best placements of
    the neighbourhood kept. The spectrum's rotation was within 0.5° of the truth on every
    overlapping pair of the seed-0 set but up to 2.7° off on the real-building set, where
    a placement 2.7° off lies 0.6 m from the truth at map 2's centre and the random walk
    does not bring it back (docs/decisions.md)."""
    min_overlap_fraction: float = 0.2
    """A best candidate is accepted only when it overlaps at least this fraction of the
    smaller map's known cells (:attr:`Agreement.overlap_fraction`), whichever source
    proposed it (:func:`~mrslam_env.merge.decide.rule_covers_enough`): a chance fit of a
    small piece of a repetitive building (a maze corridor, the next shelf aisle) agrees
    almost everywhere on the little it covers. For the same reason a candidate covering
    less is no rival that makes the best ambiguous
    (:func:`~mrslam_env.merge.decide.ambiguous_rivals`)."""
    max_conflict_fraction: float = 0.01
    """A confident candidate has at most this fraction of conflicts (a wall of one map on
    open floor of the other, beyond a two-cell tolerance, so that thick or doubled walls
    are not counted) ..."""
    min_overlap_area: float = 3.0
    """... and overlaps on at least this many m²."""
    min_merge_area: float = 6.0
    """A best candidate that overlaps less than this (m²) is refused however well it fits
    (:func:`~mrslam_env.merge.decide.rule_small_overlap_fits_tightly`): a window of a few
    m² of a symmetric or repeating building fits another part of it as tightly as its own
    (docs/decisions.md, "A floor under the overlap of a merge")."""
    small_overlap_area: float = 8.0
    """A best candidate that overlaps less than this (m²) ..."""
    small_overlap_max_psi: float = 0.6
    """... is accepted only when it fits tightly: psi at most this (cells of the working
    grid; :func:`~mrslam_env.merge.decide.rule_small_overlap_fits_tightly`). A room fitted
    onto a similar room, or a dead end onto another, agrees almost everywhere on a few m²
    but leaves walls a cell or two apart; a true small overlap has little drift to blur
    it, while larger true overlaps drift more, hence the area limit."""
    conflict_weight: float = 10.0
    """Score of a candidate: ``(agree - conflict_weight * conflicts) * cell area`` (m²)."""
    ambiguity_ratio: float = 0.25
    """Refuse when a confident candidate that is a *different* transform scores at least
    this fraction of the best one (:func:`~mrslam_env.merge.decide.rule_unambiguous`).
    Low on purpose: in repetitive buildings (shelf aisles, mirrored wings) the wrong
    placement often overlaps *more* than the right one and scores higher, so only "a
    second consistent answer exists at all" is a safe signal; the live system settles
    such cases by rendezvous instead."""
    contradicted_rival_factor: float = 3.0
    """A rival with at least this many times the best candidate's conflicts plus one ..."""
    contradicted_rival_length: float = 0.3
    """... whose largest unbroken group of conflicts is at least this long (m) ..."""
    contradicted_rival_ratio: float = 0.6
    """... makes the answer ambiguous only from this fraction of the best score, instead of
    ``ambiguity_ratio`` (:func:`~mrslam_env.merge.decide.contradicted`). A part of one map
    fitted elsewhere (often a wing turned by 180°) leaves a few wall cells on open floor;
    the true placement of a clean pair leaves none or one or two."""
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
    least as well (psi; :func:`~mrslam_env.merge.decide.refute`). Drift under the true
    transform (a wall seen through a doorway) leaves shorter groups than a shelf row or
    outer wall placed across an aisle."""
    clean_conflict_length: float = 0.5
    """A candidate whose largest conflict group is at most this long (m) is clean."""
    settle: bool = True
    """Settle an ambiguity at the input resolution
    (:func:`~mrslam_env.merge.decide.settled`): when a different confident candidate
    scores enough to make the answer ambiguous, the best and each such rival are refined
    once more at the finer input resolution (``settle_walk``) and judged by their walls
    (:func:`~mrslam_env.merge.dissimilarity.wall_match`); a rival that places the same
    part of the maps (``settle_distance``) and misses at least ``settle_ratio`` times the
    best's share of walls no longer makes the answer ambiguous. No effect when the input
    resolution is not finer than the working one, nor on the cascade's cheap pass. It
    merges the `tb3_sandbox` pairs (a near-symmetric arena) that the ambiguity ratio
    refuses (docs/decisions.md, "Ambiguity settled at the input resolution")."""
    settle_ratio: float = 5.0
    """One ratio, both ways: of two placements of the same part of the maps re-judged at
    the input resolution, the one missing the smaller share of walls
    (:attr:`~mrslam_env.merge.dissimilarity.WallMatch.missed`) wins only when the other
    misses at least this many times its share. A rival that does is settled; a rival that
    the *best* misses this many times more than takes the best's place
    (:func:`~mrslam_env.merge.decide.switching_rival`) and is then judged by every rule
    like any best. Otherwise the answer stays ambiguous (docs/decisions.md, "Ambiguity
    settled at the input resolution" and "Rival switching")."""
    settle_distance: float = 2.0
    """Only a rival that places the same part of the maps can be settled: it puts m2's
    known centre within this distance (m) of where the best puts it (turned by any
    angle). Walls at the input resolution compare two placements of the same overlap;
    a placement of another part (the mirrored wing, the next aisle) explains its own
    overlap and may fit as well as the truth (docs/decisions.md)."""
    twin_rival: bool = True
    """With a confident best candidate, its mirrored twin (m2 turned by 180° about its known
    centre, which lands where the best puts it; :func:`twin_proposal`) is refined and
    judged too, so that a near-symmetric building's twin is always among the rivals
    (docs/decisions.md, "Rival switching")."""
    neighbour_rivals: int = 2
    """With a confident best candidate, up to this many placements near it and near each of
    its rivals (same rotation, m2's known centre moved by ``distinct_translation`` to
    ``settle_distance``; :func:`~mrslam_env.merge.hypotheses.neighbour_placements`) are
    refined and judged too, so that the truth one period off a repeating structure is
    among the rivals (0: off; off too with the correlation off, ``correlation_candidates =
    0``, the live team's setting; docs/decisions.md, "Neighbour rivals")."""
    settle_walk: RandomWalkConfig = field(default_factory=lambda: _fine_walk(200))
    """The short refinement of each candidate re-judged at the input resolution: the final
    refinement's (``final_random_walk``) with a third of its iterations."""
    symmetry_proposals: int = 3
    """Aliasing check: with a confident best candidate ``b`` and each of the next
    best-scoring different candidates ``c`` (at most this many; 0 disables it), the
    building may repeat under ``S = b ∘ c⁻¹`` (a shelf aisle further on, the mirrored
    wing); ``S ∘ b`` — the next repetition — is refined and judged too, so that a
    placement one aisle off is found to be ambiguous instead of merged."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        fractions = (
            "max_conflict_fraction",
            "ambiguity_ratio",
            "contradicted_rival_ratio",
            "min_overlap_fraction",
        )
        check_fields(
            self,
            positive=(
                "working_resolution",
                "max_resolution_ratio",
                "min_known_area",
                "min_overlap_area",
                "small_overlap_max_psi",
                "distinct_translation",
                "distinct_rotation",
                "refuting_conflict_length",
                "hough_sweep_step",
                "settle_ratio",
                "settle_distance",
            ),
            non_negative=(
                "hough_sweep",
                "min_merge_area",
                "small_overlap_area",
                "conflict_weight",
                "contradicted_rival_factor",
                "contradicted_rival_length",
                "clean_conflict_length",
                *fractions,
            ),
            counts=("max_working_cells", "candidates", "hough_peaks"),
            whole=(
                "correlation_candidates",
                "hough_candidates",
                "symmetry_proposals",
                "cascade_rivals",
                "neighbour_rivals",
            ),
        )
        for attr in fractions:
            value = getattr(self, attr)
            require(name, attr, value, value <= 1.0, "in [0, 1]")
        ratio = self.max_resolution_ratio
        require(name, "max_resolution_ratio", ratio, ratio >= 1.0, ">= 1")
        require(name, "cascade", self.cascade, isinstance(self.cascade, bool), "a bool")
        require(name, "settle", self.settle, isinstance(self.settle, bool), "a bool")
        # both ways (settle and switch): a ratio of 1 or less would let two placements
        # take each other's place for ever
        require(name, "settle_ratio", self.settle_ratio, self.settle_ratio > 1.0, "> 1")
        twin = self.twin_rival
        require(name, "twin_rival", twin, isinstance(twin, bool), "a bool")
        clean = self.clean_conflict_length
        require(
            name,
            "refuting_conflict_length",
            self.refuting_conflict_length,
            self.refuting_conflict_length > clean,
            f"> clean_conflict_length ({clean})",
        )
        for attr, kind in (
            ("virtual", VirtualRobotConfig),
            ("mcl", MclConfig),
            ("pooling", HypothesisConfig),
            ("correlation", CorrelationConfig),
            ("random_walk", RandomWalkConfig),
            ("settle_walk", RandomWalkConfig),
            ("final_random_walk", RandomWalkConfig),
        ):
            value = getattr(self, attr)
            require(name, attr, value, isinstance(value, kind), f"a {kind.__name__}")


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
        Passes the overlap-area and conflict-fraction tests (and is not refuted).
    conflict_length : float
        Length (m) of the largest unbroken group of conflicts
        (:func:`~mrslam_env.merge.dissimilarity.largest_conflict` x resolution); 0.0
        when not measured (candidates that are not confident).
    refuted : bool
        Was confident, but a long conflict group refutes it against a clean rival
        (:attr:`MergeConfig.refuting_conflict_length`).
    proposed_by : str
        ``"virtual robot"`` (the hypothesis side), ``"correlation"`` (the wall
        correlation, :func:`~mrslam_env.merge.hypotheses.correlation_hypotheses`),
        ``"hough"`` (the same correlation at the Hough spectra's rotations,
        :attr:`MergeConfig.hough_candidates`), ``"symmetry"``
        (:func:`symmetry_proposals`, the aliasing check), ``"twin"`` (the best turned
        by 180° about m2's known centre, :func:`twin_proposal`) or ``"neighbour"`` (near
        the best or a rival, :attr:`MergeConfig.neighbour_rivals`).
    fine_walls : WallMatch or None
        When the candidate was re-judged at the input resolution to settle an ambiguity
        (:attr:`MergeConfig.settle`): its walls against the other map's there, after a
        short refinement (:func:`~mrslam_env.merge.dissimilarity.wall_match`); None
        otherwise.
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
    fine_walls: WallMatch | None = None

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
            "walls_missed": None if self.fine_walls is None else round(self.fine_walls.missed, 4),
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
        m1 and m2 fused in m1's frame, on m1's lattice at m1's resolution, when merged;
        with :attr:`MergeConfig.crop_to_known` (the default) the grid spans the two maps'
        known areas (plus a margin), not m1's whole grid.
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


# --- aliasing check -------------------------------------------------------------------------


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


def twin_proposal(
    scored: list[ScoredHypothesis], pivot: FloatArray, config: MergeConfig
) -> FloatArray | None:
    """The mirrored twin of the best candidate (``scored[0]``): m2 turned by 180° about
    ``pivot`` (its known centre, m2's frame), which lands where the best puts it; None
    when a candidate already gives that answer (:func:`same_answer`).

    In a near-symmetric building (the hexagonal ``tb3_sandbox`` arena) the turned
    placement may score best while the truth is never proposed; with the twin always
    judged, the truth is then a rival that the settling can compare
    (:attr:`MergeConfig.twin_rival`)."""
    best = scored[0].map1_from_map2
    flip = np.array([2.0 * pivot[0], 2.0 * pivot[1], math.pi])  # p -> 2 pivot - p
    twin = compose(best, flip)
    twin[2] = wrap_scalar(float(twin[2]))
    if any(same_answer(twin, h.map1_from_map2, pivot, config) for h in scored):
        return None
    return twin


# --- the stages --------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class _Working:
    """Both maps at the working resolution, with what every later stage reads of them."""

    w1: GridMap
    w2: GridMap
    d1: DistanceMaps
    d2: DistanceMaps
    pivot: FloatArray
    """The centre of m2's known cells, m2's frame (m): where transforms are compared."""
    resolution: float


class _Judged(NamedTuple):
    """One refined and judged candidate, its random walk, and why it is not confident."""

    hypothesis: ScoredHypothesis
    walk: RandomWalkResult
    why: str


KNOWN_MARGIN = 2
"""Unknown cells kept around each map's known area when it is cropped, cells."""


def _known_parts(m1: GridMap, m2: GridMap, config: MergeConfig) -> tuple[GridMap, GridMap]:
    """Both maps, with ``config.crop_to_known`` cut to their known area (plus
    :data:`KNOWN_MARGIN`), then checked: all that follows, the working resolution, the
    fused map and the memory used included, then depends on what the maps know, never on
    how much unknown padding their files carry."""
    for grid, name in ((m1, "map 1"), (m2, "map 2")):
        if not isinstance(grid, GridMap):
            raise MergeInputError(f"{name} must be a GridMap, got {type(grid).__name__}")
    if config.crop_to_known:
        m1, m2 = crop_to_known(m1, KNOWN_MARGIN), crop_to_known(m2, KNOWN_MARGIN)
    _check_input(m1, "map 1", config)
    _check_input(m2, "map 2", config)
    return m1, m2


def _prepare(m1: GridMap, m2: GridMap, config: MergeConfig) -> _Working:
    """Bring both maps (checked by :func:`_known_parts`) to the working resolution, with
    their distance maps; resolutions too far apart are a :class:`MergeInputError`."""
    ratio = max(m1.resolution, m2.resolution) / min(m1.resolution, m2.resolution)
    if ratio > config.max_resolution_ratio:
        raise MergeInputError(
            f"resolutions {m1.resolution} m and {m2.resolution} m differ by {ratio:.1f}x "
            f"(at most {config.max_resolution_ratio}x)"
        )
    resolution = _working_resolution(m1, m2, config)
    w1, w2 = at_resolution(m1, resolution), at_resolution(m2, resolution)
    for name, working in (("map 1", w1), ("map 2", w2)):
        if not working.free.any():
            raise MergeInputError(
                f"{name} has no free space left at the working resolution {resolution:g} m "
                "(only scattered free cells)"
            )
    sides = config.random_walk.dissimilarity.wall_sides
    pivot = w2.cell_to_world(np.argwhere(~w2.unknown).mean(axis=0)[None, :])[0]
    return _Working(
        w1=w1,
        w2=w2,
        d1=distance_maps(w1, sides=sides),
        d2=distance_maps(w2, sides=sides),
        pivot=pivot,
        resolution=resolution,
    )


def _propose(
    work: _Working,
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
    best ``correlation_candidates`` wall-correlation placements that are not duplicates,
    then ``hough_candidates`` placements at the Hough spectra's rotations that are not
    (:func:`_hough_proposals`). Each entry: transform, support, votes, source
    (:attr:`ScoredHypothesis.proposed_by`)."""
    w1, w2, pivot = work.w1, work.w2, work.pivot
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
    return forward, _correlation_proposals(work, config, initials, seconds, "hypotheses")


def _correlation_proposals(
    work: _Working,
    config: MergeConfig,
    initials: list[tuple[FloatArray, float, int, str]],
    seconds: dict[str, float],
    stage: str,
    placements: list[Hypothesis] | None = None,
) -> list[tuple[FloatArray, float, int, str]]:
    """``initials`` followed by the best ``correlation_candidates`` wall-correlation
    placements that are not duplicates of earlier entries, then ``hough_candidates``
    placements at the Hough spectra's rotations that are not (:func:`_hough_proposals`);
    timed as ``<stage>.correlation`` and ``<stage>.hough``. ``placements``: the wall
    correlation's placements when already computed (best first; its first
    ``correlation_candidates`` are those of the default ``max_hypotheses``)."""
    initials = list(initials)
    if config.correlation_candidates > 0:
        with _timed(seconds, f"{stage}.correlation"):
            if placements is None:
                placements = correlation_hypotheses(work.w1, work.w2, config.correlation)
            for placement in placements[: config.correlation_candidates]:
                transform = placement.map1_from_map2
                if not any(
                    same_answer(transform, kept[0], work.pivot, config) for kept in initials
                ):
                    initials.append((transform, 0.0, 0, "correlation"))
    if config.correlation_candidates > 0 and config.hough_candidates > 0:
        with _timed(seconds, f"{stage}.hough"):
            initials += _hough_proposals(work, config, initials)
    return initials


def distinct_placements(
    placements: list[Hypothesis], pivot: FloatArray, config: MergeConfig, count: int
) -> list[FloatArray]:
    """The cascade's rival search (:attr:`MergeConfig.cascade_rivals`): the first ``count``
    of ``placements`` (best first) that are different answers from every one kept before
    (:func:`same_answer` at ``pivot``). Fed every local maximum of the wall correlation
    (:func:`~mrslam_env.merge.hypotheses.correlation_hypotheses` with ``max_hypotheses``
    :data:`ALL_PLACEMENTS`), it gives the correlation's best *answers*, where its best
    placements are often one answer a few cells apart."""
    kept: list[FloatArray] = []
    for placement in placements:
        if len(kept) >= count:
            break
        transform = placement.map1_from_map2
        if not any(same_answer(transform, k, pivot, config) for k in kept):
            kept.append(transform)
    return kept


ALL_PLACEMENTS = 1_000_000
"""``max_hypotheses`` that keeps every local maximum of the wall correlation."""


def _hough_proposals(
    work: _Working, config: MergeConfig, kept: list[tuple[FloatArray, float, int, str]]
) -> list[tuple[FloatArray, float, int, str]]:
    """Up to ``hough_candidates`` placements at the Hough spectra's rotations, none the
    same answer as one in ``kept``: the wall correlation's best placement near each
    rotation (within ``hough_sweep``, every ``hough_sweep_step``), strongest spectrum peak
    first, then the second best near each, and so on. One near each rotation rather than
    the best over all: in a building that looks alike turned by 180° the turned placements
    outscore the true one, which the random walk then never sees."""
    w1, w2, pivot = work.w1, work.w2, work.pivot
    rotations = hough_rotations(w1, w2, peaks=config.hough_peaks, resolution=w1.resolution)
    steps = int(config.hough_sweep / config.hough_sweep_step + 1e-9)
    offsets = [k * config.hough_sweep_step for k in range(-steps, steps + 1)]
    per_rotation = [
        correlation_hypotheses(
            w1,
            w2,
            replace(config.correlation, max_hypotheses=config.hough_candidates),
            rotations=[theta + offset for offset in offsets],
        )
        for theta in rotations
    ]
    proposals: list[tuple[FloatArray, float, int, str]] = []
    for rank in range(config.hough_candidates):
        for placements in per_rotation:
            if len(proposals) >= config.hough_candidates or rank >= len(placements):
                continue
            transform = placements[rank].map1_from_map2
            if not any(same_answer(transform, k[0], pivot, config) for k in kept + proposals):
                proposals.append((transform, 0.0, 0, "hough"))
    return proposals


def _score_candidate(
    work: _Working,
    hypothesis_transform: FloatArray,
    support: float,
    votes: int,
    source: str,
    config: MergeConfig,
    rng: np.random.Generator,
    trace: bool,
) -> _Judged:
    """One proposal refined by the random walk and judged (:func:`judge`); the length of
    its largest conflict group is measured when it is confident."""
    w1, w2, d1, d2 = work.w1, work.w2, work.d1, work.d2
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
        proposed_by=source,
    )
    return _Judged(scored, walk, why)


def _rank(judged: list[_Judged], pivot: FloatArray, config: MergeConfig) -> list[_Judged]:
    """Withdraw confidence from the candidates :func:`refute` refutes, then sort:
    confident first, each group by decreasing score (stable)."""
    judged = list(judged)
    for index, why in refute([j.hypothesis for j in judged], pivot, config):
        refuted = replace(judged[index].hypothesis, confident=False, refuted=True)
        judged[index] = _Judged(refuted, judged[index].walk, why)
    return sorted(judged, key=lambda j: (not j.hypothesis.confident, -j.hypothesis.score))


def _score(
    work: _Working,
    initials: list[tuple[FloatArray, float, int, str]],
    config: MergeConfig,
    rng: np.random.Generator,
    trace: bool,
) -> tuple[Candidates, list[RandomWalkResult]]:
    """Refine and judge every proposal, refute and rank (:func:`_rank`); when the best is
    then confident, also judge the placements a repeating building would allow
    (:func:`symmetry_proposals`, the aliasing check; :func:`twin_proposal`; the
    neighbours of the best and of its rivals, ``neighbour_rivals``) and rank again.
    Returns the ranked candidates and their random walks, in the same order."""
    judged = [
        _score_candidate(work, transform, support, votes, source, config, rng, trace)
        for transform, support, votes, source in initials
    ]
    judged = _rank(judged, work.pivot, config)
    if judged and judged[0].hypothesis.confident:
        scored = [j.hypothesis for j in judged]
        extra = [(t, "symmetry") for t in symmetry_proposals(scored, work.pivot, config)]
        twin = twin_proposal(scored, work.pivot, config) if config.twin_rival else None
        extra += [] if twin is None else [(twin, "twin")]
        neighbours = config.neighbour_rivals if config.correlation_candidates > 0 else 0
        for h in [scored[0], *ambiguous_rivals(scored, work.pivot, config)]:
            near = neighbour_placements(
                work.w1, work.w2, h.map1_from_map2, work.pivot, config.correlation,
                radius=config.settle_distance, separation=config.distinct_translation,
                count=neighbours,
            )  # fmt: skip
            extra += [(t, "neighbour") for t in near]
        seen = [h.map1_from_map2 for h in scored]
        for transform, source in extra:
            if any(same_answer(transform, k, work.pivot, config) for k in seen):
                continue
            seen.append(transform)
            judged.append(_score_candidate(work, transform, 0.0, 0, source, config, rng, trace))
        judged = _rank(judged, work.pivot, config)
    candidates = Candidates(
        hypotheses=[j.hypothesis for j in judged],
        reasons=[j.why for j in judged],
        pivot=work.pivot,
        resolution=work.resolution,
    )
    return candidates, [j.walk for j in judged]


def _refine_final(
    m1: GridMap,
    m2: GridMap,
    work: _Working,
    chosen: ScoredHypothesis,
    config: MergeConfig,
    rng: np.random.Generator,
) -> tuple[FloatArray, float, Agreement]:
    """The accepted transform refined once more at the finer input resolution, when it is
    finer than the working one; otherwise as judged. Transform, psi, agreement."""
    if _input_is_finer(m1, m2, work):
        return _refine_at_input_resolution(m1, m2, chosen.map1_from_map2, config, rng)
    psi = dissimilarity(
        work.w1, work.w2, chosen.map1_from_map2, distances1=work.d1, distances2=work.d2
    )
    return chosen.map1_from_map2, float(psi), chosen.agreement


def _settle(
    m1: GridMap,
    m2: GridMap,
    work: _Working,
    candidates: Candidates,
    config: MergeConfig,
    rng: np.random.Generator,
) -> Candidates:
    """Re-judge an ambiguity at the input resolution (:attr:`MergeConfig.settle`): when
    confident rivals (:func:`~mrslam_env.merge.decide.ambiguous_rivals`) make the best
    candidate ambiguous and the input is finer than the working grid, the best and each of
    them are refined there by ``settle_walk`` and their walls matched
    (:func:`~mrslam_env.merge.dissimilarity.wall_match`); the candidates come back with
    :attr:`ScoredHypothesis.fine_walls` set on those, for
    :func:`~mrslam_env.merge.decide.settled`. When a rival then takes the best's place
    (:func:`~mrslam_env.merge.decide.switching_rival`, ``settle_ratio``), it is moved to
    the front and its own rivals are settled the same way (a rival misses strictly fewer
    walls than the best it replaces, so this ends). Otherwise (no rival, or a rival
    placing another part of the maps, ``settle_distance`` or more away, which is never
    settled) they come back unchanged."""
    hypotheses, reasons = list(candidates.hypotheses), list(candidates.reasons)
    if (
        not config.settle
        or not hypotheses
        or not hypotheses[0].confident
        or not _input_is_finer(m1, m2, work)
    ):
        return candidates
    pivot = candidates.pivot
    grids: tuple[GridMap, GridMap, DistanceMaps, DistanceMaps] | None = None
    while True:
        rivals = ambiguous_rivals(hypotheses, pivot, config)
        if not rivals or not all(same_part(hypotheses[0], r, pivot, config) for r in rivals):
            break  # no rival, or one the input resolution cannot settle
        if grids is None:
            grids = _input_grids(m1, m2, config.settle_walk.dissimilarity.wall_sides)
        f1, f2, d1, d2 = grids
        chosen = {id(h) for h in [hypotheses[0], *rivals] if h.fine_walls is None}
        for index, h in enumerate(hypotheses):
            if id(h) in chosen:
                walk = refine_random_walk(
                    f1,
                    f2,
                    h.map1_from_map2,
                    config=config.settle_walk,
                    rng=rng,
                    distances1=d1,
                    distances2=d2,
                )
                transform = np.asarray(walk.transform, dtype=np.float64)
                walls = wall_match(f1, f2, transform, distances1=d1, distances2=d2)
                hypotheses[index] = replace(h, fine_walls=walls)
        switched = switching_rival(hypotheses, pivot, config)
        if switched is None:
            break
        index = next(k for k, h in enumerate(hypotheses) if h is switched)
        hypotheses.insert(0, hypotheses.pop(index))
        reasons.insert(0, reasons.pop(index))
    return replace(candidates, hypotheses=hypotheses, reasons=reasons)


def _cheap_pass(
    work: _Working,
    config: MergeConfig,
    rng: np.random.Generator,
    trace: bool,
    seconds: dict[str, float],
) -> tuple[Candidates, list[RandomWalkResult], Decision] | None:
    """The cascade's first pass (:attr:`MergeConfig.cascade`): the wall-correlation and
    Hough placements alone, refined, judged and decided on as in the whole pipeline
    (:func:`_score`, :func:`~mrslam_env.merge.decide.decide`). The ranked candidates,
    their walks and the decision when it accepts one; None otherwise (or when nothing was
    proposed)."""
    with _timed(seconds, "cascade.placements"):
        # every local maximum (for the rivals): its first max_hypotheses are the default
        # call's, so the cheap pass proposes what the whole pipeline would
        many = ALL_PLACEMENTS if config.cascade_rivals > 0 else config.correlation.max_hypotheses
        placements = correlation_hypotheses(
            work.w1, work.w2, replace(config.correlation, max_hypotheses=many)
        )
    default = placements[: config.correlation.max_hypotheses]
    initials = _correlation_proposals(work, config, [], seconds, "cascade", default)
    if config.cascade_rivals > 0:
        with _timed(seconds, "cascade.rivals"):
            rivals = distinct_placements(placements, work.pivot, config, config.cascade_rivals)
            for rival in rivals:
                if not any(same_answer(rival, k[0], work.pivot, config) for k in initials):
                    initials.append((rival, 0.0, 0, "correlation"))
    if not initials:
        return None
    with _timed(seconds, "cascade.judge"):
        candidates, walks = _score(work, initials, config, rng, trace)
    decision = decide(candidates, config)
    if decision.chosen is None:
        return None
    floor = config.ambiguity_ratio * decision.chosen.score
    measured = [
        h
        if h.confident or h.refuted or h.score < floor
        else replace(
            h,
            conflict_length=largest_conflict(
                work.w1, work.w2, h.map1_from_map2, distances1=work.d1, distances2=work.d2
            )
            * work.resolution,
        )
        for h in candidates.hypotheses
    ]
    if unsettled_rival(measured, work.pivot, config) is not None:
        return None
    return candidates, walks, decision


@contextmanager
def _timed(seconds: dict[str, float], stage: str) -> Iterator[None]:
    """Record the wall time of the ``with`` block as ``seconds[stage]``."""
    tick = time.perf_counter()
    yield
    seconds[stage] = time.perf_counter() - tick


# --- the pipeline ----------------------------------------------------------------------------


def merge_maps(
    m1: GridMap,
    m2: GridMap,
    config: MergeConfig | None = None,
    *,
    rng: np.random.Generator | int | None = None,
    trace: bool = False,
) -> MergeResult:
    """Merge two partial occupancy maps by virtual robot motion (docs/design.md §5).

    The stages: :func:`_prepare` (input checks, working resolution), :func:`_propose`
    (virtual robot both ways, wall correlation), :func:`_score` (random walk, judge,
    refute, rank, aliasing check), :func:`~mrslam_env.merge.decide.decide` (the decision
    rules), :func:`_refine_final` (at the input resolution) and
    :func:`~mrslam_env.merge.fuse.fuse_maps`.

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
    with _timed(seconds, "prepare"):
        known1, known2 = _known_parts(m1, m2, config)
        work = _prepare(known1, known2, config)
    early = None
    if config.cascade and config.correlation_candidates > 0:
        with _timed(seconds, "cascade"):
            early = _cheap_pass(work, config, copy.deepcopy(rng), trace, seconds)
    if early is not None:
        candidates, walks, decision = early
        proposals = None
        if trace:  # the recorder draws the virtual robot; the answer does not depend on it
            proposals = generate_hypotheses(
                work.w1, work.w2, virtual=config.virtual, mcl=config.mcl,
                pooling=config.pooling, rng=copy.deepcopy(rng), trace=True,
            )  # fmt: skip
    else:
        with _timed(seconds, "hypotheses"):
            proposals, initials = _propose(work, config, rng, trace, seconds)
        with _timed(seconds, "judge"):
            candidates, walks = _score(work, initials, config, rng, trace)
        with _timed(seconds, "settle"):
            candidates = _settle(known1, known2, work, candidates, config, rng)
        decision = decide(candidates, config)
    merge_trace = (
        MergeTrace(working1=work.w1, working2=work.w2, hypotheses=proposals, refinements=walks)
        if trace and proposals is not None
        else None
    )
    if decision.chosen is None:
        seconds["total"] = time.perf_counter() - started
        return MergeResult(
            transform=None,
            reason=decision.reason,
            hypotheses=candidates.hypotheses,
            chosen=None,
            fused=None,
            agreement=None,
            psi=math.nan,
            seconds=seconds,
            trace=merge_trace,
        )
    with _timed(seconds, "final_refine"):
        transform, psi, agreement = _refine_final(
            known1, known2, work, decision.chosen, config, rng
        )
    with _timed(seconds, "fuse"):
        fused = fuse_maps(known1, at_resolution(known2, known1.resolution), transform)
    seconds["total"] = time.perf_counter() - started
    fine = min(m1.resolution, m2.resolution)
    return MergeResult(
        transform=transform,
        reason=(
            f"merged: acceptance index {agreement.index:.3f}, overlap "
            f"{agreement.overlap * fine**2:.1f} m², {decision.reason}"
        ),
        hypotheses=candidates.hypotheses,
        chosen=replace(decision.chosen, map1_from_map2=transform),
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
    m1, m2 = _known_parts(m1, m2, config)
    resolution = _working_resolution(m1, m2, config)
    w1, w2 = at_resolution(m1, resolution), at_resolution(m2, resolution)
    walk = refine_random_walk(w1, w2, map1_from_map2, config=config.random_walk, rng=rng)
    return _refine_at_input_resolution(m1, m2, walk.transform, config, rng)


def _input_is_finer(m1: GridMap, m2: GridMap, work: _Working) -> bool:
    """Whether the finer input map is finer than the working grid."""
    return min(m1.resolution, m2.resolution) < work.resolution * (1.0 - 1e-9)


def _input_grids(
    m1: GridMap, m2: GridMap, sides: bool
) -> tuple[GridMap, GridMap, DistanceMaps, DistanceMaps]:
    """Both maps at the finer input resolution, and their distance maps."""
    fine = min(m1.resolution, m2.resolution)
    f1, f2 = at_resolution(m1, fine), at_resolution(m2, fine)
    return f1, f2, distance_maps(f1, sides=sides), distance_maps(f2, sides=sides)


def _refine_at_input_resolution(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: FloatArray,
    config: MergeConfig,
    rng: np.random.Generator,
) -> tuple[FloatArray, float, Agreement]:
    """The last random walk, at the finer input resolution: transform, psi, agreement."""
    f1, f2, d1, d2 = _input_grids(m1, m2, config.final_random_walk.dissimilarity.wall_sides)
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
