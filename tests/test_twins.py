"""Pairs no method can decide: map 2 fits the world as well from a second start."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_aliasing import RES, ROOM, _apply, left_room_seen_from, twin_rooms
from test_aliasing import _row as aliasing_row

from mrslam_env.evaluation import true_overlap
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.registry import build_world
from scenarios.bench.merge import twins as twins_module
from scenarios.bench.merge.pairs import MergePair
from scenarios.bench.merge.report import format_merge_table, format_twin_breakdown, summarize
from scenarios.bench.merge.twins import (
    WorldTwin,
    load_or_compute_world_twins,
    world_grid,
    world_starts,
    world_twin,
)

START1 = np.array([2.2, 3.1, -0.4])  # robot 1, in the left room
START2 = np.array([1.7, 1.3, 0.6])  # robot 2, in the left room
NEXT_ROOM = np.array([ROOM * RES, 0.0, 0.0])  # the left room carried onto the right one


def closed_rooms(marker: bool = False) -> GridMap:
    """The rooms of ``test_aliasing.twin_rooms`` without the door between them
    (the world as a map, each room the other carried 6 m along x); ``marker`` puts a box
    in the left room only."""
    world = twin_rooms(marker=marker)
    cells = world.cells.copy()
    cells[:, ROOM] = OCCUPIED
    return GridMap(cells=cells, resolution=world.resolution, origin=world.origin)


def pair_in(marker: bool, start2: np.ndarray, pair_id: str = "p") -> MergePair:
    """Robot 1 maps the left room from START1; robot 2's map is the left room seen from
    START2, which is what the right room looks like from START2 carried there too (without
    the marker). Robot 2's world start is ``start2``: START2, or START2 carried into the
    right room."""
    world = closed_rooms(marker)
    m1 = left_room_seen_from(world, START1)
    m2 = left_room_seen_from(world, START2)
    truth = compose(inverse(START1), start2)
    return MergePair(
        pair_id=pair_id, scenario="twin rooms", m1=m1, m2=m2, map1_from_map2=truth,
        overlap=true_overlap(m1, m2, truth),
        info={"start1_world": START1.tolist(), "start2_world": start2.tolist()},
    )  # fmt: skip


def test_a_map_that_fits_the_next_identical_room_is_undecidable() -> None:
    pair = pair_in(False, START2)
    assert pair.overlap > 0.5
    found = world_twin(pair, closed_rooms())
    assert found.undecidable
    assert found.twin is not None
    # The twin start is robot 2's start carried into the right room.
    expected = compose(inverse(START1), compose(NEXT_ROOM, START2))
    centre = np.array([1.0, 0.5])  # a point of map 2's room, in map 2's frame
    assert np.hypot(*(_apply(found.twin, centre) - _apply(expected, centre))) <= 0.15
    assert abs(math.remainder(found.twin[2] - expected[2], 2 * math.pi)) <= math.radians(1.5)
    assert found.twin_overlap == pytest.approx(true_overlap(pair.m1, pair.m2, found.twin))


def test_a_marker_only_one_room_has_makes_the_pair_decidable() -> None:
    # The marker is in the left room, and map 2 saw it: the right room lacks it.
    world = closed_rooms(marker=True)
    pair = pair_in(True, START2)
    found = world_twin(pair, world)
    assert not found.undecidable
    assert found.twin is None and found.twin_overlap == 0.0


def test_a_no_overlap_pair_is_undecidable_when_its_twin_overlaps() -> None:
    # Robot 2 really started in the right room: the maps do not overlap, but the same map
    # 2 from START2 in the left room would overlap map 1.
    pair = pair_in(False, compose(NEXT_ROOM, START2))
    assert not pair.overlapping()
    found = world_twin(pair, closed_rooms())
    assert found.undecidable
    assert found.twin_overlap > 0.5


def test_world_grid_frees_only_the_floor_the_robots_reach() -> None:
    spec = build_world("twin_wings")
    grid = world_grid(spec, spec.starts[:1])
    start = spec.starts[0]
    assert grid.cells[_cell(grid, start)] == FREE
    outside = (spec.bounds[0] - 1.0, spec.bounds[1] - 1.0)  # in the margin, out of reach
    assert grid.cells[_cell(grid, outside)] == OCCUPIED
    assert set(np.unique(grid.cells)) == {FREE, OCCUPIED}
    with pytest.raises(ValueError, match="is not on the floor of twin_wings"):
        world_grid(spec, [(spec.bounds[0] - 50.0, 0.0, 0.0)])


def test_a_pair_without_world_starts_gives_a_one_line_error() -> None:
    pair = pair_in(False, START2)
    bare = MergePair(
        pair_id="bare", scenario="x", m1=pair.m1, m2=pair.m2,
        map1_from_map2=pair.map1_from_map2, overlap=pair.overlap,
    )  # fmt: skip
    with pytest.raises(ValueError, match="pair bare has no world start pose 'start1_world'"):
        world_starts(bare)


def test_results_are_cached_and_pairs_without_starts_left_out(tmp_path, monkeypatch) -> None:
    pair = pair_in(False, START2)
    bare = MergePair(
        pair_id="bare", scenario="x", m1=pair.m1, m2=pair.m2,
        map1_from_map2=pair.map1_from_map2, overlap=pair.overlap,
    )  # fmt: skip
    monkeypatch.setattr(twins_module, "world_grid", lambda spec, starts: closed_rooms())
    first = load_or_compute_world_twins([pair, bare], tmp_path, worlds=lambda name: None)
    assert list(first) == ["p"] and first["p"].undecidable
    assert list(tmp_path.glob("twins-*.json"))

    def fail(*args: object, **kwargs: object) -> WorldTwin:
        raise AssertionError("recomputed a cached pair")

    monkeypatch.setattr(twins_module, "world_twin", fail)
    again = load_or_compute_world_twins([pair], tmp_path, worlds=lambda name: None)
    assert again["p"].undecidable
    assert again["p"].twin_overlap == pytest.approx(first["p"].twin_overlap)
    np.testing.assert_allclose(again["p"].twin, first["p"].twin)


def _row(pair_id: str, outcome: str, undecidable: bool | None, overlap: float = 0.5) -> dict:
    return {
        **aliasing_row(pair_id, outcome, None, overlap),
        "overlapping": overlap >= 0.02,
        "returned": outcome in ("success", "wrong"),
        "undecidable": undecidable,
    }


def test_summary_and_tables_report_decidable_pairs_and_the_ceiling() -> None:
    rows = [
        _row("a", "success", False),
        _row("b", "refused", False),
        _row("c", "refused", True),
        _row("d", "success", True),
        _row("e", "success", True, overlap=0.2),
        _row("f", "wrong", True, overlap=0.0),
        _row("g", "correct_refusal", False, overlap=0.0),
    ]
    summary = summarize(rows, ["ours"])["ours"]
    assert summary["pairs_high"] == 4
    assert summary["pairs_high_undecidable"] == 2
    assert summary["pairs_high_decidable"] == 2
    assert summary["success_rate_high_decidable"] == pytest.approx(0.5)
    assert summary["wrong_undecidable"] == 1
    assert "decidable pairs (n=2) | 50%" in format_merge_table({"ours": summary})
    table = format_twin_breakdown(rows)
    assert "| overlap ≥ 30%, decidable | 2 | 1 | 1 | 0 | 0 |" in table
    assert "| overlap ≥ 30%, undecidable | 2 | 1 | 1 | 0 | 0 |" in table
    assert "| overlap < 30%, undecidable | 1 | 1 | 0 | 0 | 0 |" in table
    assert "| no overlap, undecidable | 1 | 0 | 0 | 1 | 0 |" in table
    assert "no method passes 50% at overlap ≥ 30%" in table


def test_tables_without_the_label_leave_the_rows_out() -> None:
    rows = [_row("a", "success", None)]
    summary = summarize(rows, ["ours"])
    assert "decidable" not in format_merge_table(summary)
    assert format_twin_breakdown(rows) == ""


def _cell(grid, point) -> tuple[int, int]:
    return (
        math.floor((point[1] - grid.origin[1]) / grid.resolution),
        math.floor((point[0] - grid.origin[0]) / grid.resolution),
    )
