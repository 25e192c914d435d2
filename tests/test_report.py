"""report.json a reader can trust (issue 36): one merge entry per robot, each with its own
transform, truth, errors and step; a top-level summary that names what it summarises; units
in the key names; readers of reports (``bench explore --from``) also read the old keys."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrslam_env.evaluation import relative_transform_error
from scenarios import experiment
from scenarios.bench.explore import run_row, summarise_reports
from scenarios.experiment import RunConfig, run_experiment

UNITLESS_TIME_KEYS = {"sim_time", "wall_time", "t90", "translation_error", "rotation_error", "ate"}


def _keys(tree: Any) -> set[str]:
    if isinstance(tree, dict):
        return set(tree) | {k for value in tree.values() for k in _keys(value)}
    if isinstance(tree, list):
        return {k for value in tree for k in _keys(value)}
    return set()


def _pose(entry: dict[str, float]) -> np.ndarray:
    return np.array([entry["x"], entry["y"], entry["theta"]])


@pytest.fixture(scope="module")
def three_robot_report(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A 3-robot oracle run whose given transforms are off by different amounts per robot
    (robot_1 by 0.03 m, robot_2 by 0.2 m and 2°), so that entries mixed between robots show."""
    offsets = {1: np.array([0.03, 0.0, 0.0]), 2: np.array([0.0, 0.2, math.radians(2.0)])}
    build_team = experiment.build_team

    def off_team(config: RunConfig, env_config: Any) -> Any:
        team = build_team(config, env_config)
        start = team.start_coordinated

        def shifted(transforms: Any, maps: Any) -> None:
            given = np.array(transforms, dtype=np.float64)
            for k, offset in offsets.items():
                given[k - 1] += offset
            start(given, maps)

        team.start_coordinated = shifted  # type: ignore[method-assign,assignment]
        return team

    patch = pytest.MonkeyPatch()
    patch.setattr(experiment, "build_team", off_team)
    try:
        config = RunConfig(
            scenario="maze",
            robots=3,
            oracle=True,
            max_steps=4,
            out=tmp_path_factory.mktemp("runs"),
            name="r",
            record=False,
            figure=False,
            progress=False,
        )
        report = run_experiment(config)
    finally:
        patch.undo()
    return report


def test_every_robot_but_robot_0_has_its_own_merge_entry(three_robot_report) -> None:
    merge = three_robot_report["merge"]
    assert set(merge["robots"]) == {"robot_1", "robot_2"}
    errors = {}
    for name, entry in merge["robots"].items():
        assert entry["joined"] is True and entry["step_joined"] == 0
        transform, truth = _pose(entry["transform"]), _pose(entry["true_transform"])
        translation, rotation = relative_transform_error(transform, truth)
        # Each entry's errors are those of its own transform against its own truth.
        assert entry["translation_error_m"] == pytest.approx(translation, abs=1e-3)
        assert entry["rotation_error_deg"] == pytest.approx(math.degrees(rotation), abs=1e-2)
        errors[name] = entry["translation_error_m"]
    assert errors["robot_1"] == pytest.approx(0.03, abs=0.005)
    assert errors["robot_2"] == pytest.approx(0.2, abs=0.02)
    assert merge["robots"]["robot_2"]["rotation_error_deg"] == pytest.approx(2.0, abs=0.05)
    truths = [_pose(e["true_transform"]) for e in merge["robots"].values()]
    assert not np.allclose(truths[0], truths[1])


def test_the_top_level_summary_names_what_it_summarises(three_robot_report) -> None:
    merge = three_robot_report["merge"]
    # No bare transform, truth or error at the top that belongs to one robot.
    assert not {"transform", "true_transform", "preliminary_transform"} & set(merge)
    assert merge["joined"] == 2 and merge["all_joined"] is True and merge["verified"] is True
    robots = merge["robots"].values()
    assert merge["worst_translation_error_m"] == max(r["translation_error_m"] for r in robots)
    assert merge["worst_rotation_error_deg"] == max(r["rotation_error_deg"] for r in robots)
    assert merge["step_first_joined"] == 0 and merge["step_all_joined"] == 0


def test_units_are_in_the_key_names(three_robot_report) -> None:
    report = three_robot_report
    assert not UNITLESS_TIME_KEYS & _keys(report), UNITLESS_TIME_KEYS & _keys(report)
    assert report["sim_time_s"] == pytest.approx(0.4)
    assert report["wall_time_s"] > 0 and report["t90_s"] is None
    assert set(report["slam"]["robot_0"]) == {"ate_m", "map_agreement"}


def test_a_two_robot_report_has_robot_1s_entry(tmp_path: Path) -> None:
    config = RunConfig(
        scenario="maze", max_steps=3, out=tmp_path, name="r", record=False, progress=False
    )
    merge = run_experiment(config)["merge"]
    assert set(merge["robots"]) == {"robot_1"}
    entry = merge["robots"]["robot_1"]
    assert entry["joined"] is False and entry["transform"] is None
    assert entry["translation_error_m"] is None and entry["true_transform"] is not None
    assert merge["joined"] == 0 and merge["all_joined"] is False and not merge["verified"]


def _bench_report(report: dict[str, Any], mode: str = "team") -> dict[str, Any]:
    bench = {"index": 0, "scenario": "maze", "seed": 0, "max_steps": 4, "mode": mode}
    return {**report, "bench": {**bench, "policy_spec": None, "robots": report["robots"]}}


def _old_keys(report: dict[str, Any]) -> dict[str, Any]:
    """The report as the version before issue 36 wrote it."""
    old = {k: v for k, v in report.items() if k not in ("sim_time_s", "wall_time_s", "t90_s")}
    old.update(sim_time=report["sim_time_s"], wall_time=report["wall_time_s"], t90=report["t90_s"])
    merge = dict(report["merge"])
    for key in ("worst_translation_error_m", "worst_rotation_error_deg", "step_first_joined"):
        merge.pop(key)
    merge.pop("all_joined")
    merge.pop("step_all_joined")
    merge.update(
        translation_error=report["merge"]["worst_translation_error_m"],
        rotation_error=report["merge"]["worst_rotation_error_deg"],
        step_verified=report["merge"]["step_first_joined"],
    )
    old["merge"] = merge
    return old


def test_bench_explore_reads_new_and_old_reports_alike(three_robot_report, tmp_path) -> None:
    new = _bench_report(three_robot_report)
    old = _old_keys(new)
    assert run_row(old) == run_row(new)
    row = run_row(new)
    assert row["translation_error"] == three_robot_report["merge"]["worst_translation_error_m"]
    assert row["wall_time"] == three_robot_report["wall_time_s"]
    for name, report in (("old", old), ("new", new)):
        (tmp_path / name / "reports").mkdir(parents=True)
        (tmp_path / name / "reports" / "r.json").write_text(json.dumps(report))
    assert summarise_reports(tmp_path / "old") == summarise_reports(tmp_path / "new")


def _old_two_robot_report(verified: bool) -> dict[str, Any]:
    """A two-robot team report as the version before issue 36 wrote it (9e7e1c6): no
    ``merge.joined`` and no ``merge.robots``; robot_1's transform and errors at the top of
    ``merge``; ``sim_time`` / ``wall_time`` / ``t90`` and ``step_verified``."""
    pose = {"x": 1.2, "y": -0.4, "theta": 0.3}
    merge: dict[str, Any] = {
        "verified": verified,
        "transform": pose if verified else None,
        "true_transform": {"x": 1.25, "y": -0.38, "theta": 0.31},
        "translation_error": 0.0539 if verified else None,
        "rotation_error": 0.573 if verified else None,
        "hypotheses_tested": 3,
        "step_verified": 812 if verified else None,
        "seeking_steps": 140,
        "sighting_hypotheses": 1,
        "first_hypothesis_step": 400,
        "first_rendezvous_step": 650,
        "rendezvous_steps": 162,
        "radio_rejections": 0,
    }
    if verified:
        merge["preliminary_transform"] = {"x": 1.21, "y": -0.41, "theta": 0.29}
    return {
        "complete": True,
        "interrupted": None,
        "scenario": "maze",
        "seed": 3,
        "steps": 1500,
        "sim_time": 150.0,
        "wall_time": 61.234,
        "interaction": True,
        "comm": True,
        "oracle": False,
        "single": False,
        "robots": 2,
        "policy": "frontier",
        "policy_spec": None,
        "merge": merge,
        "coverage": {"merged": 0.9612, "robot_0": 0.71, "robot_1": 0.66},
        "t90": 120.5,
        "until_merged": True,
        "coverage_step": 1400,
        "steps_after_coverage": 100,
        "coverage_curve": [[1500, 0.9612]],
        "slam": {r: {"ate": 0.05, "map_agreement": 0.97} for r in ("robot_0", "robot_1")},
        "merged_map_accuracy": 0.95 if verified else None,
        "collision_steps": {"robot_0": 2, "robot_1": 1},
        "team_state": "coordinated" if verified else "exploring",
        "decisions": [],
        "outputs": {"run_dir": "runs/maze-seed3"},
        "bench": {
            "index": 0,
            "scenario": "maze",
            "seed": 3,
            "max_steps": 1500,
            "mode": "team",
            "policy_spec": None,
            "robots": 2,
        },
    }


@pytest.mark.parametrize("verified", [True, False])
def test_bench_explore_reads_a_real_old_two_robot_report(verified: bool) -> None:
    row = run_row(_old_two_robot_report(verified))
    assert row["joined"] == int(verified) and row["verified"] is verified
    assert row["translation_error"] == (0.0539 if verified else None)
    assert row["rotation_error"] == (0.573 if verified else None)
    assert row["step_verified"] == (812 if verified else None)
    # Step 812 of 1500 (150 s) is 81.2 s, before t90 = 120.5 s.
    assert row["verified_before_t90"] is verified
    assert row["t90"] == 120.5 and row["t90_or_limit"] == 120.5
    assert row["wall_time"] == 61.234 and row["steps"] == 1500
    assert row["collision_steps"] == 3 and row["robot_steps"] == 3000
    assert row["seeking_steps"] == 140 and row["rendezvous_steps"] == 162
    assert row["coverage"] == 0.9612


def test_an_old_two_robot_report_reads_as_the_new_one(tmp_path: Path) -> None:
    from scenarios.bench.explore import upgrade_report

    old = _old_two_robot_report(True)
    upgraded = upgrade_report(old)
    assert upgraded["sim_time_s"] == 150.0 and upgraded["t90_s"] == 120.5
    merge = upgraded["merge"]
    assert merge["worst_translation_error_m"] == 0.0539
    assert merge["worst_rotation_error_deg"] == 0.573
    assert merge["step_first_joined"] == 812
    assert "translation_error" not in merge and "step_verified" not in merge
    (tmp_path / "reports").mkdir()
    (tmp_path / "reports" / "r.json").write_text(json.dumps(old))
    summary, runs = summarise_reports(tmp_path)  # summarised, not refused
    assert runs == [run_row(old)] and summary
