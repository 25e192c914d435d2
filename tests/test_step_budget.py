"""The default step budget of ``mrslam run``: from the building's reachable floor and the
team size (issue 37: a 60 m building must be explorable), never below 3000 steps."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from mrslam_env.evaluation import CoverageEvaluator
from mrslam_env.registry import build_world
from scenarios.experiment import (
    MIN_STEPS,
    ROBOT_STEPS_PER_M2,
    RunConfig,
    run_experiment,
    step_budget,
)


def test_small_buildings_keep_the_floor_and_big_ones_grow_with_their_area() -> None:
    assert step_budget(0.0, 2) == MIN_STEPS
    assert step_budget(100.0, 2) == MIN_STEPS
    big = 1000.0
    assert step_budget(big, 2) == round(ROBOT_STEPS_PER_M2 * big / 2) > MIN_STEPS
    # Twice the robots, half the steps (but never below the floor).
    assert step_budget(big, 4) == round(ROBOT_STEPS_PER_M2 * big / 4)
    assert step_budget(big, 8) == max(MIN_STEPS, round(ROBOT_STEPS_PER_M2 * big / 8))


@pytest.mark.parametrize(("scenario", "grows"), [("office", False), ("procedural_huge-0", True)])
def test_the_budget_of_the_shipped_worlds(scenario: str, grows: bool) -> None:
    """The default run (office) keeps 5 minutes; a 60-80 m building gets hours of steps
    enough to be covered (its reachable floor is about 3,100 m²)."""
    world = build_world(scenario)
    area = CoverageEvaluator(world, world.starts).area
    budget = step_budget(area, 2)
    assert (budget > 4 * MIN_STEPS) if grows else (budget <= 1.5 * MIN_STEPS)


def _run(tmp_path: Path, **fields: Any) -> dict[str, Any]:
    """A run in ``tb3_sandbox`` (19 m² of floor), nothing written but its report."""
    config = RunConfig(
        scenario="tb3_sandbox", out=tmp_path, record=False, figure=False, progress=False, **fields
    )
    return run_experiment(config)


def test_a_run_without_max_steps_reports_the_budget_it_chose(tmp_path: Path) -> None:
    report = _run(tmp_path, until_merged=False)
    assert report["max_steps"] == MIN_STEPS  # 19 m² of floor
    assert report["steps"] < MIN_STEPS  # it stopped at the target coverage


def test_max_steps_overrides_the_budget(tmp_path: Path) -> None:
    report = _run(tmp_path, max_steps=5)
    assert report["max_steps"] == 5 and report["steps"] == 5
