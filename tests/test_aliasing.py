"""The exhaustive placement search that labels how well a pair's maps single out the truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap, resample_cells
from scenarios.bench.merge import aliasing as aliasing_module
from scenarios.bench.merge.aliasing import (
    Aliasing,
    AliasingConfig,
    aliasing,
    load_or_compute_aliasing,
    placement_score,
)
from scenarios.bench.merge.pairs import MergePair
from scenarios.bench.merge.report import format_aliasing_breakdown, format_merge_table, summarize

RES = 0.05
ROOM = 120  # cells (6 m) between the two rooms' left walls


def twin_rooms(marker: bool = False) -> GridMap:
    """Two identical 6 m x 6 m rooms side by side with the same wall stub, fully known;
    ``marker`` puts a box in the left room only."""
    rows, cols = ROOM + 1, 2 * ROOM + 1
    cells = np.full((rows, cols), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, ROOM, -1]] = OCCUPIED
    cells[50:70, ROOM] = FREE  # a door between the rooms
    for left in (0, ROOM):
        cells[:60, left + 40] = OCCUPIED  # the same stub in each room
    if marker:
        cells[80:90, 80:90] = OCCUPIED
    return GridMap(cells=cells, resolution=RES, origin=(0.0, 0.0))


def left_room_seen_from(
    grid: GridMap, map1_from_map2: np.ndarray, *, side_walls: bool = True
) -> GridMap:
    """The left room of ``grid`` (the rest unknown) in a frame 2 with ``map1_from_map2``;
    without ``side_walls``, only the part between its two side walls."""
    left = grid.cells.copy()
    left[:, ROOM + 1 :] = UNKNOWN
    if not side_walls:
        left[:, [0, ROOM]] = UNKNOWN
    cropped = GridMap(cells=left, resolution=RES, origin=grid.origin)
    return GridMap(
        cells=resample_cells(cropped, inverse(map1_from_map2), (-5.0, -5.0), (260, 260), RES),
        resolution=RES,
        origin=(-5.0, -5.0),
    )


TRUTH = np.array([1.7, 1.3, 0.6])


def test_twin_rooms_are_misleading_or_close_and_the_rival_is_the_other_room() -> None:
    m1 = twin_rooms()
    m2 = left_room_seen_from(m1, TRUTH)
    found = aliasing(m1, m2, TRUTH)
    assert found.label in ("close", "misleading")
    assert found.ratio >= 0.9
    # The rival lays map 2 over the right room: the truth shifted 3 m along map 1's x.
    other_room = compose(np.array([ROOM * RES, 0.0, 0.0]), TRUTH)
    assert found.rival is not None
    centre = np.array([1.5, 1.5])  # a point of map 2's room, in map 2's frame
    moved = _apply(found.rival, centre)
    expected = _apply(other_room, centre)
    assert np.hypot(*(moved - expected)) <= 0.15
    assert abs(math.remainder(found.rival[2] - TRUTH[2], 2 * math.pi)) <= math.radians(1.5)


def test_a_room_whose_twin_fits_as_well_is_dominated() -> None:
    m1 = twin_rooms()
    m2 = left_room_seen_from(m1, TRUTH, side_walls=False)  # the same as the right room
    found = aliasing(m1, m2, TRUTH)
    assert found.dominated
    assert found.label == "misleading"
    assert found.truth_overlap > 0


def test_a_marker_seen_in_one_room_makes_the_pair_clear() -> None:
    m1 = twin_rooms(marker=True)
    m2 = left_room_seen_from(m1, TRUTH)
    found = aliasing(m1, m2, TRUTH)
    assert found.label == "clear"
    assert found.ratio < 0.8
    assert found.truth_score > 0
    assert not found.dominated


def test_search_scores_match_the_direct_count() -> None:
    m1 = twin_rooms(marker=True)
    m2 = left_room_seen_from(m1, TRUTH)
    found = aliasing(m1, m2, TRUTH)
    assert found.rival is not None
    assert placement_score(m1, m2, found.rival) == pytest.approx(found.rival_score, abs=0.5)
    # The truth's score is the best of its basin, at least the exact truth's.
    assert found.truth_score >= placement_score(m1, m2, TRUTH) - 0.5


def test_placement_score_counts_overlap_and_conflicts() -> None:
    m1 = twin_rooms()
    pooled_known = 61 * 121  # the 6.05 m x 12.05 m grid pooled to 0.1 m cells
    assert placement_score(m1, m1, np.zeros(3)) == pytest.approx(pooled_known)
    cells = m1.cells.copy()
    cells[90, 20] = OCCUPIED  # a wall cell in open floor, far from every wall of map 1
    m2 = GridMap(cells=cells, resolution=RES, origin=m1.origin)
    weight = AliasingConfig().conflict_weight
    assert placement_score(m1, m2, np.zeros(3)) == pytest.approx(pooled_known - weight)


def test_results_are_cached_beside_the_pairs(tmp_path, monkeypatch) -> None:
    m1 = twin_rooms(marker=True)
    pair = MergePair(
        pair_id="p", scenario="synthetic", m1=m1, m2=left_room_seen_from(m1, TRUTH),
        map1_from_map2=TRUTH, overlap=0.5,
    )  # fmt: skip
    first = load_or_compute_aliasing([pair], tmp_path)
    assert list(tmp_path.glob("aliasing-*.json"))

    def fail(*args: object, **kwargs: object) -> Aliasing:
        raise AssertionError("recomputed a cached pair")

    monkeypatch.setattr(aliasing_module, "aliasing", fail)
    again = load_or_compute_aliasing([pair], tmp_path)
    assert again["p"].label == first["p"].label
    assert again["p"].ratio == pytest.approx(first["p"].ratio)
    np.testing.assert_allclose(again["p"].rival, first["p"].rival)


def test_pairs_without_overlap_are_not_searched(tmp_path) -> None:
    m1 = twin_rooms()
    pair = MergePair(
        pair_id="none", scenario="synthetic", m1=m1, m2=m1, map1_from_map2=TRUTH, overlap=0.0
    )
    assert load_or_compute_aliasing([pair], tmp_path) == {}


def test_a_map_without_known_cells_is_refused() -> None:
    empty = GridMap(cells=np.full((10, 10), UNKNOWN, dtype=np.int8), resolution=RES)
    with pytest.raises(ValueError, match="map 2 has no known"):
        aliasing(twin_rooms(), empty, TRUTH)


@pytest.mark.parametrize(
    ("field", "value"),
    [("close_ratio", 0.0), ("close_ratio", 1.5), ("rotation_step_deg", 120.0),
     ("resolution", -0.1), ("conflict_weight", math.nan)],
)  # fmt: skip
def test_config_rejects_bad_values(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=f"AliasingConfig.{field}"):
        AliasingConfig(**{field: value})


def _row(pair_id: str, outcome: str, label: str | None, overlap: float = 0.5) -> dict:
    return {
        "pair_id": pair_id, "scenario": "office", "overlap": overlap, "overlapping": True,
        "method": "ours", "outcome": outcome, "returned": outcome != "refused",
        "translation_error": 0.01 if outcome == "success" else None,
        "rotation_error_deg": 0.1 if outcome == "success" else None, "seconds": 1.0,
        "largest_side_cells": 100, "agreement_truth": 1.0, "agreement_estimate": None,
        "aliasing": label,
    }  # fmt: skip


def test_summary_and_tables_report_success_on_clear_pairs() -> None:
    rows = [
        _row("a", "success", "clear"),
        _row("b", "refused", "clear"),
        {**_row("c", "refused", "misleading"), "aliasing_dominated": True},
        _row("d", "refused", "close"),
        _row("e", "success", "clear", overlap=0.2),  # below 30 %: not counted
    ]
    summary = summarize(rows, ["ours"])
    assert summary["ours"]["pairs_high"] == 4
    assert summary["ours"]["pairs_high_clear"] == 2
    assert summary["ours"]["success_rate_high_clear"] == pytest.approx(0.5)
    assert "maps single out the truth (n=2) | 50%" in format_merge_table(summary)
    breakdown = format_aliasing_breakdown(rows)
    assert "| clear: single out the truth | 2 | 1 | 1 | 0 |" in breakdown
    assert "| misleading: fit a wrong placement as well or better | 1 | 0 | 1 | 0 |" in breakdown
    assert "no more conflicts | 1 | 0 | 1 | 0 |" in breakdown


def test_tables_without_labels_leave_the_clear_row_out() -> None:
    rows = [_row("a", "success", None)]
    summary = summarize(rows, ["ours"])
    assert "single out" not in format_merge_table(summary)
    assert format_aliasing_breakdown(rows) == ""


def _apply(transform: np.ndarray, point: np.ndarray) -> np.ndarray:
    c, s = math.cos(transform[2]), math.sin(transform[2])
    return np.array(
        [c * point[0] - s * point[1] + transform[0], s * point[0] + c * point[1] + transform[1]]
    )
