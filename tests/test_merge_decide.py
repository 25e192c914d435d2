"""The decision step of the merge (:mod:`mrslam_env.merge.decide`) on hand-made candidates.

- Each candidate check of :func:`judge` and each decision rule of :data:`RULES`, on
  candidates that pass it and candidates that fail it, with the exact reason the CLI
  prints and the rule's name in the :class:`Decision`.
- The order in which the rules apply: a candidate set that several rules would refuse is
  refused by the first of them.
- :func:`decide` on no candidates, and an accepted decision's reason.
- Ambiguity settled at the input resolution (:func:`settled`, ``MergeConfig.settle``):
  hand-made wall matches around ``settle_ratio``, and the real :func:`wall_match` of a
  room against its thick-walled copy, the truth against the room turned by 180 degrees.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest
from merge_fixtures import room_map
from scipy import ndimage

from mrslam_env.geometry import transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.merge.decide import (
    CANDIDATE_CHECKS,
    RULES,
    Candidates,
    ambiguous_rival,
    check_conflict_fraction,
    check_overlap_area,
    contradicted,
    decide,
    judge,
    rule_confident_fit,
    rule_covers_enough,
    rule_has_candidates,
    rule_small_overlap_fits_tightly,
    rule_unambiguous,
    settled,
    switching_rival,
    unsettled_rival,
)
from mrslam_env.merge.dissimilarity import Agreement, WallMatch, acceptance_index, wall_match
from mrslam_env.merge.pipeline import (
    MergeConfig,
    ScoredHypothesis,
    _prepare,
    _settle,
    twin_proposal,
)

RESOLUTION = 0.1  # m: one cell is 0.01 m²
PIVOT = np.array([0.0, 0.0])
CONFIG = MergeConfig()


def _agreement(
    *,
    agree: int = 2000,
    disagree: int = 20,
    conflicts: int = 0,
    overlap_fraction: float = 0.5,
) -> Agreement:
    overlap = agree + disagree
    return Agreement(
        agree=agree,
        disagree=disagree,
        conflicts=conflicts,
        overlap=overlap,
        known1=4000,
        known2=4000,
        index=agree / overlap,
        overlap_fraction=overlap_fraction,
        conflict_fraction=conflicts / overlap,
    )


def _candidate(
    x: float,
    theta: float = 0.0,
    *,
    score: float = 100.0,
    confident: bool = True,
    psi: float = 0.3,
    conflicts: int = 0,
    length: float = 0.0,
    agreement: Agreement | None = None,
    proposed_by: str = "virtual robot",
) -> ScoredHypothesis:
    transform = np.array([x, 0.0, theta])
    return ScoredHypothesis(
        map1_from_map2=transform,
        initial=transform,
        support=0.3,
        votes=2,
        psi=psi,
        agreement=agreement if agreement is not None else _agreement(conflicts=conflicts),
        score=score,
        confident=confident,
        conflict_length=length,
        proposed_by=proposed_by,
    )


def _candidates(
    *hypotheses: ScoredHypothesis,
    reasons: list[str] | None = None,
    resolution: float = RESOLUTION,
) -> Candidates:
    return Candidates(
        hypotheses=list(hypotheses),
        reasons=reasons if reasons is not None else ["" for _ in hypotheses],
        pivot=PIVOT,
        resolution=resolution,
    )


def _refused_by(candidates: Candidates, config: MergeConfig = CONFIG) -> tuple[str | None, str]:
    decision = decide(candidates, config)
    assert (decision.chosen is None) == (decision.rule is not None)
    return decision.rule, decision.reason


# -- the candidate checks (judge) ---------------------------------------------------------------


def test_judge_scores_agreement_minus_weighted_conflicts_in_square_metres() -> None:
    agreement = _agreement(agree=2000, conflicts=3)
    score, _, _ = judge(agreement, RESOLUTION, CONFIG)
    assert score == pytest.approx((2000 - 10.0 * 3) * 0.01)


def test_judge_accepts_a_candidate_that_passes_every_check() -> None:
    score, confident, why = judge(_agreement(), RESOLUTION, CONFIG)
    assert confident and why == ""
    assert score == pytest.approx(20.0)


@pytest.mark.parametrize(
    ("agreement", "check", "why"),
    [
        # 299 cells of 0.01 m² overlap: under 3 m².
        (_agreement(agree=299, disagree=0), check_overlap_area, "overlap 3.0 m² < 3.0 m²"),
        (_agreement(conflicts=21), check_conflict_fraction, "conflicts 0.010 > 0.01"),
    ],
    ids=["overlap-area", "conflict-fraction"],
)
def test_each_candidate_check_fails_with_its_reason(
    agreement: Agreement, check: Callable[[Agreement, float, MergeConfig], str | None], why: str
) -> None:
    assert check in CANDIDATE_CHECKS
    assert check(agreement, RESOLUTION, CONFIG) == why
    _, confident, reason = judge(agreement, RESOLUTION, CONFIG)
    assert not confident and reason == why


@pytest.mark.parametrize(
    "agreement",
    [
        _agreement(agree=300, disagree=0),  # exactly 3 m² (0.01 m² per cell)
        _agreement(conflicts=20),  # conflicts 20 / 2020 < 0.01
    ],
    ids=["overlap-area", "conflict-fraction"],
)
def test_candidate_checks_pass_at_their_thresholds(agreement: Agreement) -> None:
    assert [check(agreement, RESOLUTION, CONFIG) for check in CANDIDATE_CHECKS] == [None] * 2


def test_the_overlap_check_reads_the_resolution() -> None:
    small = _agreement(agree=200, disagree=0)  # 2 m² at 0.1 m, 8 m² at 0.2 m
    assert check_overlap_area(small, RESOLUTION, CONFIG) is not None
    assert check_overlap_area(small, 0.2, CONFIG) is None


def test_judge_reports_the_first_failing_check() -> None:
    # Too small and too contradicted: the overlap check comes first.
    everything_wrong = _agreement(agree=150, disagree=50, conflicts=10)
    assert judge(everything_wrong, RESOLUTION, CONFIG)[2].startswith("overlap ")
    # Enough overlap: the conflicts decide.
    disagreeing = _agreement(agree=1500, disagree=500, conflicts=100)
    assert judge(disagreeing, RESOLUTION, CONFIG)[2].startswith("conflicts ")


def test_thick_walls_do_not_sink_a_true_placement() -> None:
    # The same room, its walls drawn 5 cells thick in map 2 (a real SLAM map's ragged,
    # doubled walls, exaggerated): at the truth a cell-exact agreement is 0.87, but no
    # wall lies on open floor beyond the tolerance, so the candidate is confident; half a
    # metre off, the thick walls cross open floor and it is not.
    m1 = room_map(resolution=RESOLUTION)
    thick = ndimage.binary_dilation(m1.cells == OCCUPIED, iterations=2)
    m2 = GridMap(cells=np.where(thick, OCCUPIED, FREE).astype(np.int8), resolution=RESOLUTION)
    truth = acceptance_index(m1, m2, np.zeros(3))
    assert truth.index < 0.9
    assert truth.conflicts == 0
    score, confident, why = judge(truth, RESOLUTION, CONFIG)
    assert confident and why == ""
    assert score == pytest.approx(truth.agree * RESOLUTION**2)
    off = acceptance_index(m1, m2, np.array([0.5, 0.0, 0.0]))
    assert judge(off, RESOLUTION, CONFIG)[2].startswith("conflicts ")


# -- decide on nothing, and an accepted decision -----------------------------------------------


def test_decide_on_no_candidates_refuses_for_lack_of_structure() -> None:
    decision = decide(_candidates(), CONFIG)
    assert decision.chosen is None
    assert decision.rule == "rule_has_candidates"
    assert decision.reason == (
        "no confident merge: the virtual robot found no hypothesis (too little structure)"
    )


def test_rule_has_candidates_lets_any_candidate_through() -> None:
    unsure = _candidate(0.0, confident=False)
    assert rule_has_candidates(_candidates(unsure, reasons=["x"]), CONFIG) is None


def test_a_lone_confident_candidate_is_accepted_with_its_score() -> None:
    best = _candidate(0.0, score=44.83)
    decision = decide(_candidates(best), CONFIG)
    assert decision.chosen is best
    assert decision.rule is None
    assert decision.reason == "score 44.8 m²"


def test_an_accepted_decision_names_the_next_different_confident_candidate() -> None:
    best = _candidate(0.0, score=100.0)
    duplicate = _candidate(0.2, score=90.0)  # 0.2 m at the pivot: the same answer
    unsure = _candidate(5.0, score=80.0, confident=False)
    weak = _candidate(5.0, score=20.0)  # different, confident, under a quarter of the best
    decision = decide(_candidates(best, duplicate, weak, unsure, reasons=["", "", "", "x"]), CONFIG)
    assert decision.chosen is best
    assert decision.reason == "score 100.0 m², next confident candidate 20.0 m²"
    # An unconfident different candidate is no runner-up.
    alone = decide(_candidates(best, duplicate, unsure, reasons=["", "", "x"]), CONFIG)
    assert alone.chosen is best and alone.reason == "score 100.0 m²"


def test_decide_leaves_its_input_alone() -> None:
    best, rival = _candidate(0.0), _candidate(5.0, score=60.0)
    candidates = _candidates(best, rival)
    first, second = decide(candidates, CONFIG), decide(candidates, CONFIG)
    assert (first.rule, first.reason) == (second.rule, second.reason)
    assert candidates.hypotheses == [best, rival] and candidates.reasons == ["", ""]


def test_candidates_need_one_reason_per_hypothesis() -> None:
    with pytest.raises(ValueError, match="1 reasons for 2 hypotheses"):
        _candidates(_candidate(0.0), _candidate(5.0), reasons=[""])


# -- rule_confident_fit ------------------------------------------------------------------------


def test_rule_confident_fit_passes_a_confident_best() -> None:
    assert rule_confident_fit(_candidates(_candidate(0.0)), CONFIG) is None


@pytest.mark.parametrize(
    "why",
    ["conflicts 0.012 > 0.01", "refuted: a 2.3 m wall of one map on open floor"],
)
def test_rule_confident_fit_refuses_with_the_best_candidates_own_reason(why: str) -> None:
    best = _candidate(0.0, confident=False)
    other = _candidate(5.0, confident=False)
    candidates = _candidates(best, other, reasons=[why, "conflicts 0.039 > 0.01"])
    assert rule_confident_fit(candidates, CONFIG) == f"best hypothesis fails: {why}"
    assert _refused_by(candidates) == (
        "rule_confident_fit",
        f"no confident merge: best hypothesis fails: {why}",
    )


# -- rule_unambiguous and contradicted ---------------------------------------------------------


@pytest.mark.parametrize(
    ("score", "refused"), [(25.0, True), (24.9, False)], ids=["at-ratio", "below-ratio"]
)
def test_rule_unambiguous_refuses_a_clean_rival_from_a_quarter_of_the_best(
    score: float, refused: bool
) -> None:
    candidates = _candidates(_candidate(0.0, score=100.0), _candidate(6.0, score=score))
    why = rule_unambiguous(candidates, CONFIG)
    if refused:
        assert why == f"ambiguous: two different transforms fit (scores 100.0 and {score:.1f} m²)"
        assert _refused_by(candidates) == ("rule_unambiguous", f"no confident merge: {why}")
    else:
        assert why is None


@pytest.mark.parametrize(("covered", "refused"), [(0.2, True), (0.19, False), (0.08, False)])
def test_a_rival_covering_too_little_to_be_an_answer_is_no_rival(
    covered: float, refused: bool
) -> None:
    # A corridor end fitted elsewhere: confident, scoring 30 % of the best, but covering
    # less of the smaller map than rule_covers_enough asks of an answer. It would be
    # refused as the best, so it does not make the best ambiguous either (it did before:
    # any confident rival from a quarter of the best score counted).
    assert CONFIG.min_overlap_fraction == 0.2
    small = _agreement(agree=300, disagree=5, overlap_fraction=covered)
    rival = _candidate(6.0, score=30.0, agreement=small)
    candidates = _candidates(_candidate(0.0, score=100.0), rival)
    assert (ambiguous_rival(candidates.hypotheses, PIVOT, CONFIG) is rival) is refused
    decision = decide(candidates, CONFIG)
    assert (decision.rule == "rule_unambiguous") is refused
    assert (decision.chosen is candidates.hypotheses[0]) is not refused


def test_a_rotated_rival_in_the_same_place_is_a_different_answer() -> None:
    turned = _candidate(0.0, math.radians(10.0), score=50.0)  # > 8 degrees off
    assert rule_unambiguous(_candidates(_candidate(0.0), turned), CONFIG) is not None
    close = _candidate(0.0, math.radians(6.0), score=50.0)  # < 8 degrees: the same answer
    assert rule_unambiguous(_candidates(_candidate(0.0), close), CONFIG) is None


def test_rule_unambiguous_ignores_duplicates_and_unconfident_rivals() -> None:
    best = _candidate(0.0, score=100.0)
    duplicate = _candidate(0.3, score=99.0)  # 0.3 m at the pivot: the same answer
    unsure = _candidate(6.0, score=90.0, confident=False)
    candidates = _candidates(best, duplicate, unsure, reasons=["", "", "x"])
    assert rule_unambiguous(candidates, CONFIG) is None


@pytest.mark.parametrize(
    ("conflicts", "length", "expected"),
    [
        (9, 0.3, True),  # 9 >= 3 x (2 + 1), a 0.3 m group: both at their thresholds
        (8, 1.0, False),  # one conflict short
        (9, 0.29, False),  # the group is too short
    ],
    ids=["at-thresholds", "few-conflicts", "short-group"],
)
def test_contradicted_needs_many_conflicts_in_a_long_group(
    conflicts: int, length: float, expected: bool
) -> None:
    best = _candidate(0.0, conflicts=2)
    rival = _candidate(6.0, conflicts=conflicts, length=length)
    assert contradicted(best, rival, CONFIG) is expected


@pytest.mark.parametrize(
    ("score", "refused"), [(60.0, True), (59.0, False)], ids=["at-ratio", "below-ratio"]
)
def test_a_contradicted_rival_is_ambiguous_only_from_its_higher_ratio(
    score: float, refused: bool
) -> None:
    best = _candidate(0.0, score=100.0, conflicts=2)
    rival = _candidate(6.0, math.pi, score=score, conflicts=9, length=0.5)
    why = rule_unambiguous(_candidates(best, rival), CONFIG)
    assert (why is not None) is refused


def test_the_cheap_pass_leaves_an_uncontradicted_rival_to_the_whole_pipeline() -> None:
    """:func:`unsettled_rival` (the cascade): a different candidate from a quarter of the
    best score, confident or not, unsettles the cheap pass unless it is contradicted."""
    best = _candidate(0.0, score=100.0, conflicts=2)
    narrow = _candidate(6.0, score=25.0, confident=False, conflicts=8, length=1.0)
    assert unsettled_rival([best, narrow], PIVOT, CONFIG) is narrow
    low = replace(narrow, score=24.0)  # below the ambiguity ratio
    assert unsettled_rival([best, low], PIVOT, CONFIG) is None
    duplicate = replace(narrow, map1_from_map2=np.array([0.3, 0.0, 0.0]))  # the same answer
    assert unsettled_rival([best, duplicate], PIVOT, CONFIG) is None
    wall_on_floor = replace(narrow, agreement=_agreement(conflicts=9))  # 9 >= 3 x (2 + 1)
    assert unsettled_rival([best, wall_on_floor], PIVOT, CONFIG) is None
    scattered = replace(wall_on_floor, conflict_length=0.29)  # no long group: not contradicted
    assert unsettled_rival([best, scattered], PIVOT, CONFIG) is scattered


# -- rule_covers_enough ------------------------------------------------------------------------


def _covering(overlap_fraction: float, proposed_by: str = "correlation") -> ScoredHypothesis:
    agreement = _agreement(overlap_fraction=overlap_fraction)
    return _candidate(0.0, agreement=agreement, proposed_by=proposed_by)


@pytest.mark.parametrize("source", ["correlation", "virtual robot", "symmetry"])
def test_a_best_covering_too_little_is_refused_whoever_proposed_it(source: str) -> None:
    candidates = _candidates(_covering(0.15, source))
    why = rule_covers_enough(candidates, CONFIG)
    assert why == "the best transform overlaps 15% of the smaller map (< 20%)"
    assert _refused_by(candidates) == ("rule_covers_enough", f"no confident merge: {why}")


def test_the_floor_alone_stands_between_a_confident_fit_covering_little_and_a_merge() -> None:
    # Far from every other threshold: 20 m² of overlap (min_merge_area 6, small_overlap_area
    # 8), psi 0.3 cells (small_overlap_max_psi 0.6), no conflict and no rival. Only the
    # coverage floor (8 % < 20 %) refuses it; without the floor it is the answer. The
    # end-to-end pair of test_merge_proposals.py is too close to other thresholds to say
    # this (issue 36).
    best = _covering(0.08)
    assert _refused_by(_candidates(best))[0] == "rule_covers_enough"
    loose = decide(_candidates(best), replace(CONFIG, min_overlap_fraction=0.0))
    assert loose.chosen is best


def test_a_best_covering_enough_passes() -> None:
    assert rule_covers_enough(_candidates(_covering(0.2)), CONFIG) is None
    # A confident rival that is the same answer changes nothing: the best is judged.
    agreeing = _candidate(0.1, score=90.0)
    assert rule_covers_enough(_candidates(_covering(0.15), agreeing), CONFIG) is not None


# -- rule_small_overlap_fits_tightly ------------------------------------------------------------


def _small(psi: float, overlap_cells: int = 700, overlap_fraction: float = 0.5) -> ScoredHypothesis:
    agreement = _agreement(agree=overlap_cells, disagree=0, overlap_fraction=overlap_fraction)
    return _candidate(0.0, psi=psi, agreement=agreement)


def test_a_small_loose_overlap_is_refused() -> None:
    candidates = _candidates(_small(psi=0.7))  # 7 m² at psi 0.7 cells
    why = rule_small_overlap_fits_tightly(candidates, CONFIG)
    assert why == "the best transform overlaps only 7.0 m² and fits loosely (psi 0.70 > 0.6 cells)"
    assert _refused_by(candidates) == (
        "rule_small_overlap_fits_tightly",
        f"no confident merge: {why}",
    )


@pytest.mark.parametrize(
    ("psi", "overlap_cells", "resolution"),
    [
        (0.6, 700, RESOLUTION),  # tight enough: psi at the threshold
        (1.2, 900, RESOLUTION),  # 9 m²: not small, may fit loosely
        (1.2, 700, 0.2),  # 700 cells of 0.04 m²: 28 m²
    ],
    ids=["tight", "not-small", "coarser-cells"],
)
def test_a_tight_or_large_overlap_passes(psi: float, overlap_cells: int, resolution: float) -> None:
    candidates = _candidates(_small(psi, overlap_cells), resolution=resolution)
    assert rule_small_overlap_fits_tightly(candidates, CONFIG) is None


def test_a_tiny_overlap_is_refused_however_tightly_it_fits() -> None:
    # 5 m² at psi 0.1 cells: two windows of a symmetric arena lie on each other as tightly
    candidates = _candidates(_small(psi=0.1, overlap_cells=500))
    why = rule_small_overlap_fits_tightly(candidates, CONFIG)
    assert why == "the best transform overlaps only 5.0 m² (< 6.0 m²)"
    assert _refused_by(candidates) == (
        "rule_small_overlap_fits_tightly",
        f"no confident merge: {why}",
    )
    assert rule_small_overlap_fits_tightly(candidates, MergeConfig(min_merge_area=4.0)) is None


def test_the_small_overlap_rule_reads_its_two_thresholds() -> None:
    candidates = _candidates(_small(psi=0.7))
    assert rule_small_overlap_fits_tightly(candidates, MergeConfig(small_overlap_area=6.0)) is None
    assert (
        rule_small_overlap_fits_tightly(candidates, MergeConfig(small_overlap_max_psi=0.8)) is None
    )


# -- the order of the rules -------------------------------------------------------------------


def test_the_rules_apply_in_their_documented_order() -> None:
    assert [rule.__name__ for rule in RULES] == [
        "rule_has_candidates",
        "rule_confident_fit",
        "rule_unambiguous",
        "rule_covers_enough",
        "rule_small_overlap_fits_tightly",
    ]


def test_an_unconfident_best_is_refused_before_ambiguity_is_looked_at() -> None:
    # Ranked wrongly on purpose: an unconfident best with a confident rival.
    best = _candidate(0.0, confident=False)
    rival = _candidate(6.0, score=90.0)
    rule, _ = _refused_by(_candidates(best, rival, reasons=["overlap 2.0 m² < 3.0 m²", ""]))
    assert rule == "rule_confident_fit"


def test_ambiguity_is_refused_before_the_coverage_and_small_overlap_rules() -> None:
    # 10 % of the smaller map, 7 m² and loose: three rules would refuse; ambiguity first,
    # then coverage, whoever proposed it.
    best = replace(_small(psi=0.9, overlap_fraction=0.1), proposed_by="correlation")
    rival = _candidate(6.0, score=90.0)
    assert _refused_by(_candidates(best, rival))[0] == "rule_unambiguous"
    assert _refused_by(_candidates(best))[0] == "rule_covers_enough"
    virtual = replace(best, proposed_by="virtual robot")
    assert _refused_by(_candidates(virtual))[0] == "rule_covers_enough"
    covering = _small(psi=0.9, overlap_fraction=0.3)
    assert _refused_by(_candidates(covering))[0] == "rule_small_overlap_fits_tightly"


# -- ambiguity settled at the input resolution (settle_ratio) -----------------------------------


def _walls(missed_cells: int, walls: int = 1000) -> WallMatch:
    """A wall match whose worse map misses ``missed_cells`` of ``walls`` (plus one)."""
    return WallMatch(
        walls1=walls,
        matched1=walls - missed_cells,
        walls2=walls,
        matched2=walls,
    )


@pytest.mark.parametrize(
    ("rival_missed", "accepted"),
    [(499, True), (600, True), (498, False), (20, False)],
)
def test_a_rival_missing_five_times_the_walls_is_settled(rival_missed: int, accepted: bool) -> None:
    # The best misses (99 + 1) / 1001 of its walls; the rival (m + 1) / 1001: settled from
    # m + 1 = 5 x 100 (settle_ratio 5).
    best = replace(_candidate(0.0, score=100.0), fine_walls=_walls(99))
    turned = _candidate(0.0, math.pi / 2, score=95.0)  # the same place, turned by 90°
    rival = replace(turned, fine_walls=_walls(rival_missed))
    assert settled(best, rival, PIVOT, CONFIG) is accepted
    decision = decide(_candidates(best, rival), CONFIG)
    assert (decision.chosen is best) is accepted
    if accepted:
        assert decision.reason == (
            "score 100.0 m², next confident candidate 95.0 m², settled at the input "
            f"resolution (walls missed 10.0%, rivals {(rival_missed + 1) / 1001:.1%} or more)"
        )
    else:
        assert decision.reason == (
            "no confident merge: ambiguous: two different transforms fit (scores 100.0 and "
            "95.0 m²; walls missed at the input resolution 10.0% and "
            f"{(rival_missed + 1) / 1001:.1%}, 0.0 m apart)"
        )


def test_an_ambiguity_is_settled_only_when_both_were_rejudged() -> None:
    best = replace(_candidate(0.0, score=100.0), fine_walls=_walls(0))
    rival = _candidate(0.0, math.pi / 2, score=95.0)
    assert not settled(best, rival, PIVOT, CONFIG)
    assert not settled(rival, best, PIVOT, CONFIG)
    assert _refused_by(_candidates(best, rival))[0] == "rule_unambiguous"
    # and every rival must be settled, not only the first
    settled_rival = replace(_candidate(0.0, math.pi / 2, score=95.0), fine_walls=_walls(900))
    third = replace(_candidate(0.0, math.pi, score=90.0), fine_walls=_walls(1))
    assert _refused_by(_candidates(best, settled_rival, third))[0] == "rule_unambiguous"
    assert decide(_candidates(best, settled_rival), CONFIG).chosen is best


@pytest.mark.parametrize(("x", "accepted"), [(1.9, True), (2.0, False), (6.0, False)])
def test_only_a_rival_placing_the_same_part_is_settled(x: float, accepted: bool) -> None:
    # A rival that puts m2's centre settle_distance (2 m) or more from the best's places
    # another part of the maps (the mirrored wing, the next aisle): however many walls
    # it misses, it keeps the answer ambiguous.
    best = replace(_candidate(0.0, score=100.0), fine_walls=_walls(0))
    rival = replace(_candidate(x, score=95.0), fine_walls=_walls(900))
    assert settled(best, rival, PIVOT, CONFIG) is accepted
    assert (decide(_candidates(best, rival), CONFIG).chosen is best) is accepted


def _thick(grid: GridMap) -> GridMap:
    """``grid`` with every wall drawn one cell thicker on each side (a real SLAM map's
    ragged, doubled walls)."""
    thick = ndimage.binary_dilation(grid.cells == OCCUPIED)
    cells = np.where(thick, OCCUPIED, grid.cells).astype(np.int8)
    return GridMap(cells=cells, resolution=grid.resolution, origin=grid.origin)


def _turn_about_centre(grid: GridMap) -> np.ndarray:
    """The transform that turns ``grid``'s raster by 180 degrees about its centre."""
    rows, cols = grid.cells.shape
    return np.array([cols * grid.resolution, rows * grid.resolution, math.pi])


def _turned_rival(m1: GridMap, m2: GridMap, truth: np.ndarray) -> tuple[bool, float, float]:
    """The truth and the room turned by 180 degrees about its centre (its walls land on
    walls, but for the inner stub), judged as :func:`settled` judges them, with equal
    scores: whether the turned one is settled, and both shares of walls missed."""
    rows, cols = m1.cells.shape
    turned = _turn_about_centre(m1)
    best = replace(_candidate(0.0, score=100.0), fine_walls=wall_match(m1, m2, truth))
    rival = replace(_candidate(6.0, score=100.0), fine_walls=wall_match(m1, m2, turned))
    rival = replace(rival, map1_from_map2=turned)
    assert best.fine_walls is not None and rival.fine_walls is not None
    centre = np.array([cols * m1.resolution / 2, rows * m1.resolution / 2])
    judged = settled(best, rival, centre, CONFIG)
    return judged, best.fine_walls.missed, rival.fine_walls.missed


def test_a_thick_walled_truth_settles_a_turned_rival() -> None:
    # The room with its inner wall stub, drawn with walls three cells thick in map 2: at
    # the truth every wall of either map has a wall of the other within a cell, while the
    # room turned by 180 degrees leaves the stub (30 of ~300 wall cells) unmatched.
    m1 = room_map()
    same, truth_missed, rival_missed = _turned_rival(m1, _thick(m1), np.zeros(3))
    assert truth_missed < 0.01
    assert rival_missed > 0.05
    assert same


def test_a_close_rival_is_not_settled() -> None:
    # Without the stub the room looks the same turned by 180 degrees: both placements
    # explain every wall, so the rival stays and the answer is refused.
    m1 = room_map()
    cells = m1.cells.copy()
    cells[1:-1, 1:-1] = FREE
    bare = GridMap(cells=cells, resolution=m1.resolution, origin=m1.origin)
    same, truth_missed, rival_missed = _turned_rival(bare, _thick(bare), np.zeros(3))
    assert rival_missed < CONFIG.settle_ratio * truth_missed
    assert not same


def test_the_pipeline_rejudges_the_best_and_its_rivals_when_settle_is_on() -> None:
    # merge_maps' settle stage (MergeConfig.settle) on the room with its stub at 0.05 m,
    # its walls thick in map 2, judged at 0.1 m: the truth and the room turned by 180
    # degrees, both confident with close scores. Off: nothing is re-judged and the
    # answer is ambiguous; on (the default): both are refined and judged at 0.05 m, the
    # turned room leaves the stub unmatched, and the truth is accepted.
    m1 = room_map()
    m2 = _thick(m1)
    turned = _turn_about_centre(m1)
    candidates = replace(
        _candidates(
            replace(_candidate(0.0, score=100.0), map1_from_map2=np.zeros(3)),
            replace(_candidate(0.0, score=95.0), map1_from_map2=turned),
        ),
        pivot=np.array([2.0, 1.5]),
    )
    assert _refused_by(candidates)[0] == "rule_unambiguous"
    work = _prepare(m1, m2, CONFIG)
    assert work.resolution > m1.resolution
    rng = np.random.default_rng(0)
    assert _settle(m1, m2, work, candidates, replace(CONFIG, settle=False), rng) is candidates
    assert CONFIG.settle
    rejudged = _settle(m1, m2, work, candidates, CONFIG, rng)
    best, rival = rejudged.hypotheses
    assert best.fine_walls is not None and rival.fine_walls is not None
    decision = decide(rejudged, CONFIG)
    assert decision.chosen is best
    assert "settled at the input resolution" in decision.reason


# -- rival switching (settle_ratio, the other way) and the mirrored twin --------------------------


def _switch_missed(ratio: float) -> int:
    """Unmatched wall cells of a best that misses just over ``ratio`` times the share of a
    rival missing 99 of 1,000 (``(m + 1) / 1001`` against ``100 / 1001``)."""
    return math.ceil(ratio * 100 - 1e-9)


def test_a_rival_missing_far_fewer_walls_takes_the_best_place() -> None:
    # The best turned by 180° about the same centre scores a little more at the working
    # resolution; at the input resolution it misses settle_ratio times the rival's share
    # (one ratio both ways).
    ratio = CONFIG.settle_ratio
    rival = replace(_candidate(0.0, score=95.0), fine_walls=_walls(99))
    best = replace(_candidate(0.0, math.pi, score=100.0), fine_walls=_walls(_switch_missed(ratio)))
    assert switching_rival([best, rival], PIVOT, CONFIG) is rival
    # just short of the ratio: no switch, and the answer stays ambiguous
    short = replace(best, fine_walls=_walls(_switch_missed(ratio) - 2))
    assert switching_rival([short, rival], PIVOT, CONFIG) is None
    assert _refused_by(_candidates(short, rival))[0] == "rule_unambiguous"
    # never without both re-judged, nor for a rival placing another part of the maps
    assert switching_rival([replace(best, fine_walls=None), rival], PIVOT, CONFIG) is None
    far = replace(_candidate(6.0, score=95.0), fine_walls=_walls(99))
    assert switching_rival([best, far], PIVOT, CONFIG) is None


def test_the_switched_rival_is_accepted_over_the_best_it_replaced() -> None:
    # Once in front, the rival is judged like any best: the best it replaced (scoring
    # more at the working resolution) is settled by the comparison that switched them;
    # a third rival still needs settle_ratio times the new best's share.
    ratio = CONFIG.settle_ratio
    rival = replace(_candidate(0.0, score=95.0), fine_walls=_walls(99))
    best = replace(_candidate(0.0, math.pi, score=100.0), fine_walls=_walls(_switch_missed(ratio)))
    assert settled(rival, best, PIVOT, CONFIG)
    decision = decide(_candidates(rival, best), CONFIG)
    assert decision.chosen is rival
    turned = replace(_candidate(0.0, math.pi / 2, score=90.0), fine_walls=_walls(300))
    assert _refused_by(_candidates(rival, best, turned))[0] == "rule_unambiguous"
    settled_turned = replace(turned, fine_walls=_walls(600))
    assert decide(_candidates(rival, best, settled_turned), CONFIG).chosen is rival


def test_the_rival_missing_the_fewest_walls_is_the_one_switched_to() -> None:
    best = replace(_candidate(0.0, math.pi, score=100.0), fine_walls=_walls(900))
    worse = replace(_candidate(0.0, math.pi / 2, score=98.0), fine_walls=_walls(300))
    fewest = replace(_candidate(0.3, score=95.0), fine_walls=_walls(50))
    assert switching_rival([best, worse, fewest], PIVOT, CONFIG) is fewest


def test_the_pipeline_switches_to_a_rival_that_lays_the_walls_on_each_other() -> None:
    # The room with its stub, thick-walled in map 2, with the room turned by 180° ranked
    # best and the truth its rival: re-judged at 0.05 m, the turned room leaves the stub
    # unmatched, the truth takes its place and is accepted. Without switching (a ratio
    # no placement reaches) the answer stays ambiguous.
    m1 = room_map()
    m2 = _thick(m1)
    turned = _turn_about_centre(m1)
    candidates = replace(
        _candidates(
            replace(_candidate(0.0, score=100.0), map1_from_map2=turned),
            replace(_candidate(0.0, score=95.0), map1_from_map2=np.zeros(3)),
            reasons=["", ""],
        ),
        pivot=np.array([2.0, 1.5]),
    )
    work = _prepare(m1, m2, CONFIG)
    never = replace(CONFIG, settle_ratio=1e9)
    kept = _settle(m1, m2, work, candidates, never, np.random.default_rng(0))
    assert np.allclose(kept.hypotheses[0].map1_from_map2, turned, atol=0.1)
    assert _refused_by(kept, never)[0] == "rule_unambiguous"
    switched = _settle(m1, m2, work, candidates, CONFIG, np.random.default_rng(0))
    decision = decide(switched, CONFIG)
    assert decision.chosen is switched.hypotheses[0]
    assert np.allclose(decision.chosen.map1_from_map2, np.zeros(3), atol=0.1)


def test_the_twin_turns_the_best_by_180_degrees_about_the_pivot() -> None:
    pivot = np.array([2.0, 1.0])
    best = _candidate(0.5, 0.3)
    twin = twin_proposal([best], pivot, CONFIG)
    assert twin is not None
    assert twin[2] == pytest.approx(0.3 - math.pi)
    point = pivot[None, :]
    assert np.allclose(transform_points(twin, point), transform_points(best.map1_from_map2, point))
    # already judged: not proposed again
    judged = replace(_candidate(0.0), map1_from_map2=twin + np.array([0.1, 0.0, 0.05]))
    assert twin_proposal([best, judged], pivot, CONFIG) is None


@pytest.mark.parametrize("ratio", [1.0, 0.5])
def test_settle_ratio_must_exceed_one(ratio: float) -> None:
    # a ratio of 1 or less would let two placements take each other's place for ever
    with pytest.raises(ValueError, match=r"MergeConfig.settle_ratio must be > 1"):
        MergeConfig(settle_ratio=ratio)


def test_an_accepted_switch_says_whose_place_it_took() -> None:
    rival = replace(_candidate(0.0, score=95.0), fine_walls=_walls(99))
    best = replace(_candidate(0.0, math.pi, score=100.0), fine_walls=_walls(600))
    decision = decide(_candidates(rival, best), CONFIG)
    assert decision.reason == (
        "score 95.0 m², next confident candidate 100.0 m², settled at the input resolution "
        "(walls missed 10.0%, rivals 60.0% or more), in place of a candidate scoring 100.0 m²"
    )
