"""``mrslam bench explore`` modes: the oracle (relative pose known from step 0), one robot
alone, the share of the oracle's gain and the strict notion of a wrong merge."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from agents.team import TeamState
from mrslam_env.geometry import compose, inverse
from scenarios import experiment
from scenarios.bench.explore import (
    _paired,
    _summarise,
    format_explore_table,
    is_wrong,
    late_oracle_given,
    oracle_gain_share,
    run_explore_benchmark,
)
from scenarios.experiment import RunConfig, run_experiment


def _config(tmp_path: Path, **fields: Any) -> RunConfig:
    settings: dict[str, Any] = {"scenario": "tb3_sandbox", "seed": 0, "max_steps": 60}
    settings.update(fields)
    return RunConfig(out=tmp_path, record=False, figure=False, progress=False, **settings)


def test_the_oracle_coordinates_from_step_0_with_the_true_transform(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    teams: list[Any] = []
    states: list[TeamState] = []
    build_team = experiment.build_team

    def spy(config: RunConfig, env_config: Any) -> Any:
        team = build_team(config, env_config)
        # Re-refining within the run would move a transform estimated from the maps; a
        # given one stays (checked below against the truth).
        team.config = dataclasses.replace(team.config, refine_every=10)
        act = team.act

        def recorded_act(observations: Any, maps: Any) -> Any:
            states.append(team.state)  # before the step's decisions
            return act(observations, maps)

        team.act = recorded_act  # type: ignore[method-assign]
        teams.append(team)
        return team

    monkeypatch.setattr(experiment, "build_team", spy)
    report = run_experiment(_config(tmp_path, oracle=True))
    (team,) = teams
    assert states and all(s is TeamState.COORDINATED_EXPLORATION for s in states)
    assert team.step_verified == 0 and team.hypotheses_tested == 0
    true = report["merge"]["robots"]["robot_1"]["true_transform"]
    expected = np.array([true["x"], true["y"], true["theta"]])
    assert np.allclose(team.transform, expected, atol=1e-3)
    assert report["oracle"] is True and report["merge"]["verified"]
    assert report["merge"]["worst_translation_error_m"] < 1e-3
    assert report["merge"]["worst_rotation_error_deg"] < 1e-2


def test_oracle_transform_is_the_start_poses_relation(tmp_path: Path) -> None:
    from mrslam_env.config import EnvConfig
    from mrslam_env.env import MultiRobotSlamEnv
    from mrslam_env.registry import build_world

    env = MultiRobotSlamEnv(scenario=build_world("tb3_sandbox"), seed=0, config=EnvConfig())
    env.reset()
    starts = env.simulator.starts
    report = run_experiment(_config(tmp_path, oracle=True, max_steps=1))
    true = report["merge"]["robots"]["robot_1"]["true_transform"]
    expected = compose(inverse(starts[0]), starts[1])
    assert np.allclose([true["x"], true["y"], true["theta"]], expected, atol=1e-3)


def test_single_explores_with_robot_0_alone(tmp_path: Path) -> None:
    from mrslam_env import env as env_module

    poses: list[dict[str, np.ndarray]] = []
    step = env_module.MultiRobotSlamEnv.step

    def spy(self: Any, actions: Any) -> Any:
        result = step(self, actions)
        poses.append({a: result[4][a]["true_pose"].copy() for a in self.possible_agents})
        return result

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(env_module.MultiRobotSlamEnv, "step", spy)
        report = run_experiment(_config(tmp_path, single=True, max_steps=100))
    first, last = poses[0], poses[-1]
    assert np.hypot(*(last["robot_0"][:2] - first["robot_0"][:2])) > 0.1
    assert np.allclose(last["robot_1"], first["robot_1"], atol=1e-6)
    assert report["single"] is True and not report["merge"]["verified"]
    assert report["team_state"] == str(TeamState.NO_INTERACTION)
    # Coverage counts robot 0's map alone.
    assert report["coverage"]["merged"] == report["coverage"]["robot_0"]


def test_modes_cannot_be_mixed() -> None:
    with pytest.raises(ValueError, match="oracle"):
        RunConfig(oracle=True, single=True)
    with pytest.raises(ValueError, match="oracle"):
        RunConfig(oracle=True, interaction=False)


def test_a_tiny_benchmark_in_a_real_building_runs_every_mode() -> None:
    rows, runs = run_explore_benchmark(["tb3_sandbox"], [0], max_steps=40)
    modes = ["team", "independent", "oracle", "single", "late-oracle"]
    assert [r["mode"] for r in runs] == modes
    (row,) = rows
    assert set(row["t90"]) == set(modes)
    assert format_explore_table(rows).splitlines()[2].startswith("| tb3_sandbox |")
    with pytest.raises(ValueError, match="unknown mode"):
        run_explore_benchmark(["tb3_sandbox"], [0], max_steps=40, modes=("solo",))
    with pytest.raises(ValueError, match="needs the team mode"):
        run_explore_benchmark(["tb3_sandbox"], [0], max_steps=40, modes=("late-oracle",))


def test_the_late_oracle_explores_alone_then_coordinates_with_what_it_is_given(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 40: the late oracle measures what the verification costs: independent robots
    until the team run's verification step, then the team run's own transform."""
    states: list[TeamState] = []
    teams: list[Any] = []
    build_team = experiment.build_team

    def spy(config: RunConfig, env_config: Any) -> Any:
        team = build_team(config, env_config)
        act = team.act

        def recorded_act(observations: Any, maps: Any) -> Any:
            states.append(team.state)
            return act(observations, maps)

        team.act = recorded_act  # type: ignore[method-assign]
        teams.append(team)
        return team

    monkeypatch.setattr(experiment, "build_team", spy)
    given = (8.5, 10.0, 3.1)  # any transform: the run takes it as it is
    report = run_experiment(
        _config(tmp_path, scenario="office", max_steps=60, given_at=30, given_transforms=(given,))
    )
    (team,) = teams
    # Steps 1-29 independent (not even a merge attempt), 30 on coordinated.
    assert states[:29] == [TeamState.NO_INTERACTION] * 29
    assert states[29:] == [TeamState.COORDINATED_EXPLORATION] * 31
    assert team.hypotheses_tested == 0 and team.first_hypothesis_step is None
    np.testing.assert_allclose(team.transform, given)
    assert report["given_at"] == 30 and report["merge"]["robots"]["robot_1"]["joined"]


def test_what_the_late_oracle_is_given_comes_from_the_team_run() -> None:
    merge = {
        "all_joined": True,
        "step_all_joined": 135,
        "robots": {"robot_1": {"transform": {"x": 8.5, "y": 10.0, "theta": 3.14}}},
    }
    assert late_oracle_given({"merge": merge}) == (135, ((8.5, 10.0, 3.14),))
    assert late_oracle_given({"merge": {**merge, "all_joined": False}}) is None


def test_paired_differences_have_a_students_t_interval() -> None:
    def run(seed: int, t90: float) -> dict[str, Any]:
        return {"scenario": "s", "seed": seed, "policy": "p", "robots": 2, "t90_or_limit": t90}

    solo = [run(0, 50.0), run(1, 60.0), run(2, 70.0)]
    team = [run(0, 48.0), run(1, 56.0), run(2, 64.0), run(3, 10.0)]  # seed 3 has no pair
    paired = _paired(solo, team)
    # Differences 2, 4, 6: mean 4, standard error 2 / sqrt(3), t(0.975, 2) = 4.303.
    assert paired == {"mean": 4.0, "ci95": round(4.303 * 2 / 3**0.5, 1), "n": 3}
    assert _paired(solo, [run(1, 61.0)]) == {"mean": -1.0, "ci95": None, "n": 1}
    assert _paired(solo, []) is None


def test_given_transforms_are_checked() -> None:
    with pytest.raises(ValueError, match="go together"):
        RunConfig(given_at=10)
    with pytest.raises(ValueError, match="given_at must be a step"):
        RunConfig(given_at=0, given_transforms=((0.0, 0.0, 0.0),))
    with pytest.raises(ValueError, match="1 finite"):
        RunConfig(given_at=5, given_transforms=((0.0, float("nan"), 0.0),))
    with pytest.raises(ValueError, match="need interaction"):
        RunConfig(given_at=5, given_transforms=((0.0, 0.0, 0.0),), oracle=True)


def _run(mode: str, t90: float, seed: int = 0, scenario: str = "s") -> dict[str, Any]:
    return {
        "scenario": scenario,
        "seed": seed,
        "mode": mode,
        "t90": t90,
        "t90_or_limit": t90,
        "verified": mode == "team",
        "translation_error": 0.01 if mode == "team" else None,
        "rotation_error": 0.1 if mode == "team" else None,
        "hypotheses_tested": 1,
        "collision_steps": 0,
        "robot_steps": 100,
    }


def test_share_of_the_oracle_gain() -> None:
    assert oracle_gain_share(100.0, 80.0, 60.0) == pytest.approx(0.5)
    assert oracle_gain_share(100.0, 60.0, 60.0) == pytest.approx(1.0)
    assert oracle_gain_share(100.0, 110.0, 60.0) == pytest.approx(-0.25)
    assert oracle_gain_share(100.0, 80.0, 100.0) is None  # the oracle gains nothing
    runs = [
        _run("team", 80.0),
        _run("team", 70.0, seed=1),
        _run("independent", 100.0),
        _run("independent", 100.0, seed=1),
        _run("oracle", 60.0),
        _run("oracle", 50.0, seed=1),
        _run("single", 150.0),
        _run("single", 170.0, seed=1),
    ]
    row = _summarise("s", runs)
    assert row["t90"] == {"team": 75.0, "independent": 100.0, "oracle": 55.0, "single": 160.0}
    assert row["oracle_gain_share"] == pytest.approx(25.0 / 45.0, abs=1e-3)
    assert row["speedup"] == pytest.approx(100.0 / 75.0, abs=1e-3)
    assert row["runs"] == 2 and row["verified"] == 2  # oracle runs are not merges
    line = format_explore_table([row]).splitlines()[2]
    assert line.startswith("| s | 75.0 | 100.0 | 55.0 | - | 160.0 | 1.33× | 56% | - | +25.0")


def test_wrong_means_off_by_more_than_ten_centimetres_or_one_degree() -> None:
    assert not is_wrong(0.05, 0.5)
    assert not is_wrong(0.10, 1.0)
    assert is_wrong(0.11, 0.2)  # wrong now, right under the old 0.5 m / 5°
    assert is_wrong(0.02, 1.5)
    assert is_wrong(0.6, 6.0)
    runs = [
        {**_run("team", 50.0, seed=k), "translation_error": t, "rotation_error": r}
        for k, (t, r) in enumerate([(0.02, 0.1), (0.3, 0.2), (0.05, 2.0), (0.09, 0.9)])
    ]
    row = _summarise("s", runs)
    assert row["verified"] == 4 and row["wrong_accepted"] == 2
    assert row["translation_error"][2] == 0.3 and row["rotation_error"][2] == 2.0


def test_cli_selects_modes(capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from scenarios.cli import main

    status = main(["bench", "explore", "--modes", "team,solo", "--seeds", "1"])
    assert status != 0 and "--modes" in capsys.readouterr().err
    argv = ["bench", "explore", "--scenarios", "maze", "--seeds", "1", "--max-steps", "20"]
    assert main([*argv, "--modes", "oracle,single", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert [run["mode"] for run in result["runs"]] == ["oracle", "single"]


def test_a_team_run_goes_on_after_coverage_until_its_merge_is_verified(tmp_path: Path) -> None:
    # tb3_sandbox seed 0 reaches 95 % at step 40, before any merge is verified.
    stopped = run_experiment(_config(tmp_path, max_steps=400, until_merged=False, name="a"))
    assert stopped["steps"] == 40 and stopped["coverage_step"] == 40
    assert not stopped["merge"]["verified"] and stopped["steps_after_coverage"] == 0
    went_on = run_experiment(_config(tmp_path, max_steps=400, name="b"))
    merge = went_on["merge"]
    assert went_on["until_merged"] and merge["verified"]
    assert went_on["coverage_step"] == 40 and went_on["t90_s"] == stopped["t90_s"]
    # Stopped at the first coverage check after the merge was verified.
    assert merge["step_first_joined"] <= went_on["steps"] < merge["step_first_joined"] + 20
    assert went_on["steps_after_coverage"] == went_on["steps"] - 40
    assert not is_wrong(merge["worst_translation_error_m"], merge["worst_rotation_error_deg"])


def test_a_team_run_with_no_merge_under_way_stops_after_the_idle_steps(tmp_path: Path) -> None:
    # No link: no merge can ever be under way, so the run stops ``until_merged_idle``
    # steps after its coverage; a run without interaction is never kept on.
    alone = run_experiment(_config(tmp_path, max_steps=400, comm=False, until_merged_idle=60))
    assert alone["coverage_step"] == 40 and alone["steps"] == 100
    assert not alone["merge"]["verified"]
    independent = run_experiment(_config(tmp_path, max_steps=400, interaction=False))
    assert not independent["until_merged"] and independent["steps"] == 40
    with pytest.raises(ValueError, match="until_merged_idle"):
        _config(tmp_path, until_merged_idle=0)
