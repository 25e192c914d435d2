"""``mrslam bench explore``: the summary and its table, on a tiny run."""

from __future__ import annotations

from typing import Any

from scenarios.bench.explore import _summarise, format_explore_table, run_explore_benchmark


def test_a_tiny_benchmark_pairs_coordinated_and_independent_runs() -> None:
    rows, runs = run_explore_benchmark(["maze"], [1], max_steps=120, modes=("team", "independent"))
    assert [(r["scenario"], r["seed"], r["mode"]) for r in runs] == [
        ("maze", 1, "team"),
        ("maze", 1, "independent"),
    ]
    (row,) = rows
    assert row["runs"] == 1 and row["wrong_accepted"] == 0
    # 12 s is too short for 90 %: both runs count their time limit.
    assert row["t90_coordinated"] == row["t90_independent"] == 12.0
    assert row["unfinished_coordinated"] == row["unfinished_independent"] == 1
    assert row["oracle_gain_share"] is None and "oracle" not in row["t90"]
    assert set(row["collisions"]) == {"team", "independent"}
    table = format_explore_table(rows).splitlines()
    assert table[0].startswith("| scenario | t90 team (s) | t90 independent (s)")
    assert table[2].startswith(
        "| maze | 12.0 (1✗) | 12.0 (1✗) | - | - | - | 1.00× | - | - | +0.0 | - | 0/1 | 0/1 |"
    )


def _run(
    mode: str,
    t90: float,
    verified: bool = False,
    error: float = 0.0,
    seed: int = 0,
    scenario: str = "s",
    collisions: int = 0,
) -> dict[str, Any]:
    return {
        "scenario": scenario,
        "seed": seed,
        "mode": mode,
        "t90": t90,
        "t90_or_limit": t90,
        "verified": verified,
        "translation_error": error if verified else None,
        "rotation_error": 0.1 if verified else None,
        "hypotheses_tested": 1,
        "collision_steps": collisions,
        "robot_steps": 1000,
    }


def test_summary_counts_wrong_merges_and_speed_up() -> None:
    runs = [
        _run("team", 50.0, True, 0.05, collisions=10),
        _run("team", 70.0, True, 0.8, seed=1, collisions=30),
        _run("independent", 90.0),
        _run("independent", 60.0, seed=1),
        _run("team", 30.0, scenario="t"),
        _run("independent", 30.0, scenario="t"),
    ]
    row = _summarise("s", runs)
    assert row["t90_coordinated"] == 60.0 and row["t90_independent"] == 75.0
    assert row["speedup"] == 1.25 and row["verified"] == 2 and row["wrong_accepted"] == 1
    assert row["max_translation_error"] == 0.8
    assert row["translation_error"] == (0.425, 0.725, 0.8)
    assert row["faster"] == 1  # seed 0 sooner, seed 1 later than alone
    assert row["collisions"]["team"] == {"median": 20.0, "max": 30.0, "median_percent": 2.0}
    total = _summarise(None, runs)
    assert total["scenario"] == "all" and total["runs"] == 3 and total["faster"] == 1
    assert total["t90_coordinated"] == 50.0 and total["t90_independent"] == 60.0
    # Robot-steps on rendezvous drives: summed where reported, "-" where no run did.
    assert row["rendezvous_steps"] is None
    runs[0]["rendezvous_steps"], runs[1]["rendezvous_steps"] = 40, 0
    row = _summarise("s", runs)
    assert row["rendezvous_steps"] == 40
    assert "| 0 | 40 | 0 |" in format_explore_table([row]).splitlines()[2]
