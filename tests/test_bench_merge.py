"""The merge benchmark harness: scoring, pair generation, the table, the feature baseline."""

from __future__ import annotations

import json
import math
import sys

import numpy as np
import pytest
from merge_fixtures import in_frame, poses_near, room_map, scan_map

from mrslam_env.evaluation import cell_agreement, relative_transform_error, true_overlap
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import UNKNOWN, GridMap
from mrslam_env.registry import build_world
from scenarios.bench.merge import methods as merge_methods
from scenarios.bench.merge import pairs as merge_pairs
from scenarios.bench.merge.methods import RandomWalkBaselineConfig, resolve_methods
from scenarios.bench.merge.pairs import (
    MergePair,
    PairGenerationConfig,
    load_or_generate_pairs,
    merge_pair_from_runs,
    reachable_starts,
    simulate_run,
)
from scenarios.bench.merge.report import format_merge_table, summarize, write_rows
from scenarios.bench.merge.run import Tolerance, classify_outcome, run_merge_benchmark
from scenarios.cli import main

TRUTH = np.array([1.0, -2.0, 0.5])


# --- scoring ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("estimate", "overlapping", "expected"),
    [
        (None, True, "refused"),
        (None, False, "correct_refusal"),
        (TRUTH + np.array([0.1, -0.1, math.radians(1.0)]), True, "success"),
        (TRUTH + np.array([0.0, 0.26, 0.0]), True, "wrong"),
        (TRUTH + np.array([0.0, 0.0, math.radians(2.5)]), True, "wrong"),
        (TRUTH, False, "wrong"),  # any transform on a pair without overlap is wrong
    ],
)
def test_classify_outcome(estimate, overlapping: bool, expected: str) -> None:
    assert classify_outcome(estimate, TRUTH, overlapping) == expected


def test_classify_outcome_tolerance_is_inclusive_and_configurable() -> None:
    at_edge = TRUTH + np.array([0.25, 0.0, math.radians(2.0) - 1e-12])
    assert classify_outcome(at_edge, TRUTH, True) == "success"
    assert classify_outcome(at_edge, TRUTH, True, Tolerance(translation=0.1)) == "wrong"
    with pytest.raises(ValueError, match=r"Tolerance\.translation"):
        Tolerance(translation=0.0)


# --- pair generation ---------------------------------------------------------------------


def test_reachable_starts_are_free_and_spread() -> None:
    world = build_world("office")
    starts = reachable_starts(world, 4, np.random.default_rng(3), spread=2)
    assert starts.shape == (4, 3)
    assert (world.clearance(starts[:, :2]) >= 0.45).all()
    assert np.all(np.abs(starts[:, 2]) <= math.pi)
    # Farthest-point sampling puts the second start far from the first.
    assert math.hypot(*(starts[1, :2] - starts[0, :2])) > 10.0


def test_two_simulated_runs_give_a_consistent_pair() -> None:
    world = build_world("office")
    start1 = np.array([5.0, 12.0, 0.4])
    start2 = np.array([6.5, 12.2, -2.0])
    run1 = simulate_run(world, start1, (150,), [0, 1])
    run2 = simulate_run(world, start2, (60, 150), [0, 2])
    assert set(run2[1]) == {60, 150}
    np.testing.assert_allclose(run1[0], start1, atol=1e-9)
    pair = merge_pair_from_runs("p", "office", (run1[0], run1[1][150]), (run2[0], run2[1][150]))
    np.testing.assert_allclose(pair.map1_from_map2, compose(inverse(start1), start2))
    assert 0.2 < pair.overlap <= 1.0
    # Warping map 2 into map 1 by the truth: the cells both know mostly agree, clearly
    # more than under a transform 0.5 m / 10° off.
    good = cell_agreement(pair.m1, pair.m2, pair.map1_from_map2)
    off = cell_agreement(pair.m1, pair.m2, compose(pair.map1_from_map2, [0.5, 0.0, 0.17]))
    assert good > 0.95
    assert good > off + 0.02


def test_generate_pairs_caches_a_manifest(tmp_path, monkeypatch) -> None:
    config = PairGenerationConfig(
        n_pairs=3,
        worlds=("maze",),
        runs_per_world=3,
        checkpoints=(40, 120),
        no_overlap_fraction=0.34,
        min_known_area=1.0,
    )
    pairs, manifest = load_or_generate_pairs(config, tmp_path)
    folder = tmp_path / config.cache_key()
    saved = json.loads((folder / "manifest.json").read_text())
    assert saved["generator_version"] == merge_pairs.GENERATOR_VERSION
    assert len(pairs) + manifest["shortfall"] == 3
    assert len(pairs) >= 1
    for pair, entry in zip(pairs, saved["pairs"], strict=True):
        truth = compose(inverse(entry["start1_world"]), entry["start2_world"])
        np.testing.assert_allclose(pair.map1_from_map2, truth, atol=1e-9)
        assert (folder / entry["map1"]).exists() and (folder / entry["map2"]).exists()
        # The overlap from the world raster matches the one computed in map 1's frame.
        assert true_overlap(pair.m1, pair.m2, pair.map1_from_map2) == pytest.approx(
            pair.overlap, abs=0.05
        )

    # A second call reads the cache instead of simulating again.
    def refuse(*args, **kwargs):
        raise AssertionError("regenerated cached pairs")

    monkeypatch.setattr(merge_pairs, "generate_pairs", refuse)
    again, _ = load_or_generate_pairs(config, tmp_path)
    assert [p.pair_id for p in again] == [p.pair_id for p in pairs]
    np.testing.assert_array_equal(again[0].m1.cells, pairs[0].m1.cells)


def test_generation_config_validation() -> None:
    with pytest.raises(ValueError, match="checkpoints"):
        PairGenerationConfig(checkpoints=(100, 50))
    with pytest.raises(ValueError, match="no_overlap_max"):
        PairGenerationConfig(no_overlap_max=0.3)
    with pytest.raises(ValueError, match="acceptance_threshold"):
        RandomWalkBaselineConfig(acceptance_threshold=1.5)
    assert PairGenerationConfig().cache_key() != PairGenerationConfig(seed=1).cache_key()


# --- the run and the table ------------------------------------------------------------------


def synthetic_pairs() -> list[MergePair]:
    grid = room_map()
    pairs = []
    for k, (overlap, name) in enumerate([(0.8, "a"), (0.5, "b"), (0.25, "c"), (0.0, "d")]):
        truth = np.array([0.1 * k, 0.2, 0.3 * k])
        pairs.append(
            MergePair(
                pair_id=f"{k:03d}-{name}",
                scenario="synthetic",
                m1=grid,
                m2=grid,
                map1_from_map2=truth,
                overlap=overlap,
            )
        )
    return pairs


def oracle(truths: dict[int, np.ndarray | None]):
    """A stub method giving the table's answers in call order (the pairs, in order)."""
    calls = iter(truths.values())

    def method(m1: GridMap, m2: GridMap, rng: np.random.Generator):
        return next(calls)

    return method


def test_benchmark_rows_summary_and_table(tmp_path) -> None:
    pairs = synthetic_pairs()
    perfect = {k: (p.map1_from_map2 if p.overlap > 0 else None) for k, p in enumerate(pairs)}
    # Right on the first pair, 1 m off on the second, refuses the third, answers on the
    # pair without overlap.
    sloppy = {
        0: pairs[0].map1_from_map2 + np.array([0.05, 0.0, 0.0]),
        1: pairs[1].map1_from_map2 + np.array([1.0, 0.0, 0.0]),
        2: None,
        3: np.zeros(3),
    }
    methods = {"stub-perfect": oracle(perfect), "stub-sloppy": oracle(sloppy)}
    rows = run_merge_benchmark(pairs, methods, warm_up=False)
    assert len(rows) == 8
    outcomes = {(r["pair_id"], r["method"]): r["outcome"] for r in rows}
    assert outcomes[("003-d", "stub-perfect")] == "correct_refusal"
    assert outcomes[("003-d", "stub-sloppy")] == "wrong"
    assert outcomes[("001-b", "stub-sloppy")] == "wrong"
    assert outcomes[("002-c", "stub-sloppy")] == "refused"

    summary = summarize(rows, list(methods))
    best, worst = summary["stub-perfect"], summary["stub-sloppy"]
    assert best["success_rate_high"] == 1.0 and best["pairs_high"] == 2
    assert best["success_rate_overlapping"] == 1.0 and best["pairs_overlapping"] == 3
    assert best["wrong"] == 0 and best["refusal_rate"] == 1.0
    assert best["median_translation_error"] == 0.0
    assert worst["success_rate_high"] == 0.5
    assert worst["success_rate_overlapping"] == pytest.approx(1 / 3)
    assert worst["wrong"] == 2 and worst["wrong_rate"] == 0.5
    assert worst["correct_refusals"] == 0
    assert worst["median_translation_error"] == pytest.approx(0.525)
    assert best["pairs_small"] == 4  # 60 x 80 grids
    assert rows[0]["largest_side_cells"] == 80
    assert rows[0]["agreement_estimate"] is not None
    assert all(r["cpu_seconds"] >= 0.0 for r in rows)
    assert best["median_cpu_seconds"] >= 0.0

    table = format_merge_table(summary, {"features": "No module named 'cv2'"})
    lines = table.splitlines()
    assert lines[0] == "| | stub-perfect | stub-sloppy |"
    assert "| success, overlap ≥ 30% (n=2) | 100% | 50% |" in lines
    assert "| wrong answers, all pairs (n=4) | 0 (0%) | 2 (50%) |" in lines
    assert "skipped features: No module named 'cv2'" in table
    assert "| median time, grids ≤ 400×400 (n=4) (s) |" in table
    assert "| median CPU time per pair (s) |" in table

    csv_path = write_rows(tmp_path / "rows.csv", rows, {})
    assert csv_path.read_text().splitlines()[0].startswith("pair_id,scenario,overlap")
    json_path = write_rows(tmp_path / "rows.json", rows, {"summary": summary})
    assert len(json.loads(json_path.read_text())["rows"]) == 8


def test_resolve_methods_rejects_unknown_names() -> None:
    with pytest.raises(ValueError, match="unknown method 'bogus'"):
        resolve_methods(["bogus"])
    runnable, skipped = resolve_methods(["features"])
    assert set(runnable) | set(skipped) == {"features"}


def test_cli_bad_input_exits_2(capsys) -> None:
    assert main(["bench", "merge", "--methods", "bogus"]) == 2
    assert "unknown method 'bogus'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:  # refused by argparse, before any work
        main(["bench", "merge", "--pairs", "0"])
    assert exit_info.value.code == 2


# --- the feature-based baseline -------------------------------------------------------------


def test_features_baseline_recovers_a_rotated_shifted_copy() -> None:
    pytest.importorskip("cv2")
    from scenarios.bench.merge.features import estimate_transform_features

    world = build_world("office")
    rng = np.random.default_rng(0)
    m1 = scan_map(world, poses_near(world, (6.0, 4.0), 3.0, 10, rng), np.array([6.0, 4.0, 0.3]))
    truth = np.array([1.5, -0.8, math.pi / 2])
    m2 = in_frame(m1, truth)
    result = estimate_transform_features(m1, m2)
    assert result.transform is not None, f"confidence {result.confidence:.2f}"
    translation, rotation = relative_transform_error(result.transform, truth)
    assert translation <= m1.resolution
    assert math.degrees(rotation) <= 1.0
    assert result.confidence >= 1.0


def test_features_baseline_refuses_unrelated_maps() -> None:
    pytest.importorskip("cv2")
    from scenarios.bench.merge.features import estimate_transform_features

    empty = GridMap(cells=np.full((50, 50), UNKNOWN, dtype=np.int8), resolution=0.05)
    result = estimate_transform_features(room_map(), empty)
    assert result.transform is None and result.estimate is None


def test_cli_bench_merge_prints_the_table_and_writes_rows(tmp_path, monkeypatch, capsys) -> None:
    pairs = synthetic_pairs()

    def load(config, cache, *, regenerate=False, progress=None, jobs=1, ray=None):
        assert config.n_pairs == 4 and config.seed == 5 and cache == tmp_path
        return pairs, {"generation_seconds": 1.5, "shortfall": 0}

    def stub(m1: GridMap, m2: GridMap, rng: np.random.Generator):
        return np.zeros(3)

    monkeypatch.setattr(merge_pairs, "load_or_generate_pairs", load)
    monkeypatch.setattr(merge_methods, "_METHODS", {"stub": (stub, ())})
    out = tmp_path / "rows.json"
    argv = [
        "bench",
        "merge",
        "--set",
        "builtin",
        "--pairs",
        "4",
        "--seed",
        "5",
        "--methods",
        "stub",
    ]
    assert main([*argv, "--cache", str(tmp_path), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "4 pairs (3 overlapping), generated in 2 s" in printed
    assert "| | stub |" in printed
    saved = json.loads(out.read_text())
    assert len(saved["rows"]) == 4 and saved["summary"]["stub"]["wrong"] >= 1
    labels = {row["pair_id"]: row["aliasing"] for row in saved["rows"]}
    assert all(
        (label in ("clear", "close", "misleading")) == pair.overlapping()
        for pair, label in zip(pairs, labels.values(), strict=True)
    )
    assert main([*argv, "--cache", str(tmp_path), "--json", "--no-aliasing"]) == 0
    assert json.loads(capsys.readouterr().out)["summary"]["stub"]["aliasing_labelled"] is False
    assert main([*argv, "--cache", str(tmp_path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["summary"]["stub"]["pairs"] == 4


def test_cli_bench_merge_marks_undecidable_pairs(tmp_path, monkeypatch, capsys) -> None:
    from scenarios.bench.merge import twins
    from scenarios.bench.merge.twins import WorldTwin

    pairs = synthetic_pairs()
    monkeypatch.setattr(
        merge_pairs,
        "load_or_generate_pairs",
        lambda config, cache, **kwargs: (pairs, {"generation_seconds": 1.0, "shortfall": 0}),
    )
    monkeypatch.setattr(merge_methods, "_METHODS", {"ours": (lambda m1, m2, rng: None, ())})
    twin = WorldTwin(undecidable=True, twin=np.zeros(3), twin_overlap=0.4, truth_conflicts=0.0)
    monkeypatch.setattr(
        twins, "load_or_compute_world_twins", lambda pairs, folder, **kwargs: {"000-a": twin}
    )
    out = tmp_path / "rows.json"
    argv = ["bench", "merge", "--set", "builtin", "--pairs", "4", "--methods", "ours"]
    argv += ["--cache", str(tmp_path)]
    assert main([*argv, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "| overlap ≥ 30%, undecidable | 1 | 0 | 1 | 0 | 0 |" in printed
    assert "success, overlap ≥ 30%, decidable pairs (n=0)" in printed
    rows = {row["pair_id"]: row for row in json.loads(out.read_text())["rows"]}
    assert rows["000-a"]["undecidable"] is True and rows["000-a"]["twin_overlap"] == 0.4
    assert rows["001-b"]["undecidable"] is None


def test_features_method_is_skipped_without_opencv(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "cv2", None)  # makes `import cv2` fail
    runnable, skipped = resolve_methods(["features"])
    assert runnable == {}
    assert "baselines" in skipped["features"]


# --- the random-walk baseline ----------------------------------------------------------------


def test_random_initial_transform_lands_on_map1() -> None:
    grid = room_map()
    rng = np.random.default_rng(1)
    known2 = grid.cell_to_world(np.argwhere(grid.cells != UNKNOWN)).mean(axis=0)
    thetas = []
    for _ in range(20):
        transform = merge_methods._random_initial_transform(grid, grid, rng)
        centroid = transform_points(transform, known2[None])
        assert grid.contains(grid.world_to_cell(centroid)).all()
        thetas.append(transform[2])
    assert np.ptp(thetas) > math.pi  # any rotation


def test_random_walk_baseline_returns_only_accepted_transforms() -> None:
    pytest.importorskip("mrslam_env.merge.refine")
    from mrslam_env.merge.dissimilarity import acceptance_index

    world = build_world("office")
    rng = np.random.default_rng(0)
    m1 = scan_map(world, poses_near(world, (6.0, 4.0), 3.0, 10, rng), np.array([6.0, 4.0, 0.3]))
    m2 = in_frame(m1, np.array([1.5, -0.8, 2.0]))
    config = RandomWalkBaselineConfig(starts=3)
    for seed in range(2):
        estimate = merge_methods.method_random_walk(m1, m2, np.random.default_rng(seed), config)
        if estimate is not None:
            agreement = acceptance_index(m1, m2, estimate)
            assert agreement.index >= config.acceptance_threshold
            assert agreement.overlap_fraction >= config.min_overlap_fraction
    empty = GridMap(cells=np.full((20, 20), UNKNOWN, dtype=np.int8), resolution=0.05)
    assert merge_methods.method_random_walk(m1, empty, np.random.default_rng(0)) is None


def test_scenario_breakdown_counts_outcomes_per_world() -> None:
    from scenarios.bench.merge.report import format_scenario_breakdown

    rows = [
        {"method": "ours", "scenario": "maze", "outcome": "success"},
        {"method": "ours", "scenario": "procedural-1", "outcome": "refused"},
        {"method": "ours", "scenario": "procedural-2", "outcome": "success"},
        {"method": "features", "scenario": "maze", "outcome": "wrong"},
    ]
    table = format_scenario_breakdown(rows).splitlines()
    assert table[2] == "| maze | 1 | 0 | 0 | 0 |"
    assert table[3] == "| procedural | 1 | 1 | 0 | 0 |"
    assert len(table) == 4
