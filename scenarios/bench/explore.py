"""The exploration benchmark behind ``mrslam bench explore``.

Per scenario and seed, the end-to-end experiment (:func:`scenarios.experiment.run_experiment`)
runs twice from the same starts: with the team coordinator (merge by virtual robot motion,
rendezvous verification, coordinated exploration of the merged map) and with the same
robots exploring independently (no interaction). Reported per scenario:

====================  ===============================================================
``t90_coordinated``   mean simulated time (s) until the robots' maps together cover 90 %
                      of the free area, with coordination; a run that never gets there
                      counts as its time limit (and is counted in ``unfinished``)
``t90_independent``   the same without interaction
``speedup``           ``t90_independent / t90_coordinated``
``verified``          runs with a verified merge / runs
``wrong_accepted``    verified merges off by more than 0.5 m or 5° (must be 0)
``max_error``         largest translation (m) and rotation (°) error of a verified merge
``faster``            runs in which coordination reached 90 % sooner than the same
                      seed's independent run
====================  ===============================================================

With several scenarios a last row, ``all``, summarises every run.

Coverage is judged against the ground truth (evaluation only); runs stop as ``mrslam
run`` does, at 95 % (or the step limit), so that the merge figures are those of the main
job.
"""

from __future__ import annotations

import math
import statistics
import tempfile
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from scenarios.experiment import RunConfig, run_experiment

__all__ = ["DEFAULT_SCENARIOS", "format_explore_table", "run_explore_benchmark"]

DEFAULT_SCENARIOS = ("office", "warehouse", "maze", "twin_wings", "procedural-0")
WRONG_TRANSLATION = 0.5
WRONG_ROTATION_DEG = 5.0


def _run(scenario: str, seed: int, max_steps: int, interaction: bool, out: Path) -> dict[str, Any]:
    config = RunConfig(
        scenario=scenario,
        seed=seed,
        max_steps=max_steps,
        out=out,
        name=f"{scenario}-{seed}-{'team' if interaction else 'solo'}",
        record=False,
        figure=False,
        interaction=interaction,
        progress=False,
    )
    return run_experiment(config)


def _task(args: tuple[str, int, int, bool, str]) -> dict[str, Any]:
    scenario, seed, max_steps, interaction, folder = args
    report = _run(scenario, seed, max_steps, interaction, Path(folder))
    merge = report["merge"]
    limit = max_steps * 0.1
    return {
        "scenario": scenario,
        "seed": seed,
        "interaction": interaction,
        "t90": report["t90"],
        "t90_or_limit": report["t90"] if report["t90"] is not None else limit,
        "verified": merge["verified"],
        "translation_error": merge["translation_error"],
        "rotation_error": merge["rotation_error"],
        "hypotheses_tested": merge["hypotheses_tested"],
        "step_verified": merge["step_verified"],
        "coverage": report["coverage"]["merged"],
        "wall_time": report["wall_time"],
    }


def run_explore_benchmark(
    scenarios: Sequence[str] = DEFAULT_SCENARIOS,
    seeds: Sequence[int] = range(5),
    max_steps: int = 4000,
    *,
    jobs: int = 1,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Run the benchmark (``jobs`` runs at a time, in processes); returns (summary rows
    per scenario, per-run rows)."""
    with tempfile.TemporaryDirectory(prefix="mrslam-bench-explore-") as folder:
        tasks = [
            (scenario, seed, max_steps, interaction, folder)
            for scenario in scenarios
            for seed in seeds
            for interaction in (True, False)
        ]
        runs: list[dict[str, Any]] = []
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for row in pool.map(_task, tasks):
                runs.append(row)
                if progress is not None:
                    mode = "team" if row["interaction"] else "solo"
                    progress(f"{row['scenario']} seed {row['seed']} {mode}: t90 {row['t90']}")
    rows = [_summarise(scenario, runs) for scenario in scenarios]
    if len(scenarios) > 1:
        rows.append(_summarise(None, runs))
    return rows, runs


def _summarise(scenario: str | None, runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The summary row of one scenario, or of all runs (``scenario=None``, named "all")."""
    mine = [r for r in runs if scenario is None or r["scenario"] == scenario]
    team = [r for r in mine if r["interaction"]]
    solo = [r for r in mine if not r["interaction"]]
    solo_time = {(r["scenario"], r["seed"]): r["t90_or_limit"] for r in solo}
    faster = sum(
        r["t90_or_limit"] < solo_time.get((r["scenario"], r["seed"]), -math.inf) for r in team
    )
    verified = [r for r in team if r["verified"]]
    wrong = [
        r
        for r in verified
        if r["translation_error"] > WRONG_TRANSLATION or r["rotation_error"] > WRONG_ROTATION_DEG
    ]
    t_team = statistics.fmean(r["t90_or_limit"] for r in team)
    t_solo = statistics.fmean(r["t90_or_limit"] for r in solo)
    return {
        "scenario": "all" if scenario is None else scenario,
        "runs": len(team),
        "faster": faster,
        "t90_coordinated": round(t_team, 1),
        "t90_independent": round(t_solo, 1),
        "speedup": round(t_solo / t_team, 3) if t_team > 0 else None,
        "unfinished_coordinated": sum(r["t90"] is None for r in team),
        "unfinished_independent": sum(r["t90"] is None for r in solo),
        "verified": len(verified),
        "wrong_accepted": len(wrong),
        "max_translation_error": max((r["translation_error"] for r in verified), default=None),
        "max_rotation_error": max((r["rotation_error"] for r in verified), default=None),
        "hypotheses_tested": sum(r["hypotheses_tested"] for r in team),
    }


def format_explore_table(rows: Sequence[dict[str, Any]]) -> str:
    """The summary as a markdown table."""
    lines = [
        "| scenario | t90 coordinated (s) | t90 independent (s) | speed-up | faster | verified | "
        "wrong accepted | max error (m / °) | hypotheses tested |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in rows:
        if row["max_translation_error"] is None:
            error = "-"
        else:
            error = f"{row['max_translation_error']:.3f} / {row['max_rotation_error']:.2f}"
        unfinished = ""
        if row["unfinished_coordinated"] or row["unfinished_independent"]:
            unfinished = (
                f" ({row['unfinished_coordinated']}/{row['unfinished_independent']} "
                "never reached 90 %)"
            )
        lines.append(
            f"| {row['scenario']}{unfinished} | {row['t90_coordinated']:.1f} | "
            f"{row['t90_independent']:.1f} | {row['speedup']:.2f}× | "
            f"{row['faster']}/{row['runs']} | "
            f"{row['verified']}/{row['runs']} | {row['wrong_accepted']} | {error} | "
            f"{row['hypotheses_tested']} |"
        )
    return "\n".join(lines)
