"""The exploration-policy protocol: the built-in policies implement it, a policy written
outside the package runs in ``mrslam run --policy`` and ``mrslam bench explore --policy``
(its rows beside the frontier baseline's), and a bad spec is refused in one line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from agents.explorer import ExplorerPolicy, frontier_policy
from agents.policy import (
    ExplorationPolicy,
    PolicyContext,
    build_policy,
    load_policy_factory,
    policy_label,
)
from agents.team import TeamCoordinator, TeamState
from agents.wander import WanderPolicy, wander_policy
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.gridmap import FREE, UNKNOWN, GridMap
from scenarios.cli import main
from scenarios.experiment import MapCache

# A user's policy: straight ahead, slowly turning; counts its calls and the contexts seen.
FORWARD = """
import numpy as np

CALLS = []


class Forward:
    def reset(self):
        CALLS.clear()

    def act(self, observation, context):
        CALLS.append((context.robot, context.in_common_frame, context.goal))
        return np.array([0.6, 0.2], dtype=np.float32)


def forward(env, rng):
    return Forward()


def not_a_policy(env, rng):
    return 42
"""


@pytest.fixture
def forward_module(tmp_path: Path) -> Path:
    path = tmp_path / "my_policy.py"
    path.write_text(FORWARD)
    return path


def test_the_built_in_policies_implement_the_protocol() -> None:
    env = EnvConfig()
    explorer = frontier_policy(env, np.random.default_rng(0))
    wander = wander_policy(env, np.random.default_rng(0))
    assert isinstance(explorer, ExplorerPolicy) and isinstance(explorer, ExplorationPolicy)
    assert isinstance(wander, WanderPolicy) and isinstance(wander, ExplorationPolicy)
    assert not isinstance(object(), ExplorationPolicy)
    # Loaded by spec, as a user's would be.
    assert load_policy_factory("agents.wander:wander_policy") is wander_policy
    assert load_policy_factory("agents.explorer:frontier_policy") is frontier_policy


def _context(grid: GridMap, pose: np.ndarray, **fields: Any) -> PolicyContext:
    return PolicyContext(robot=0, step=1, map=grid, pose=pose, own_map=grid, **fields)


def test_the_protocol_form_acts_as_the_rich_one() -> None:
    cells = np.full((60, 100), FREE, dtype=np.int8)
    cells[:, 70:] = UNKNOWN  # beyond x = 7 m: a frontier to go to
    grid = GridMap(cells=cells, resolution=0.1)
    pose = np.array([2.0, 3.0, 0.0])
    scan = np.full(360, 8.0)
    rich, protocol = (ExplorerPolicy(np.random.default_rng(5)) for _ in range(2))
    for _ in range(5):
        expected = rich.act({"pose": pose, "scan": scan}, grid)
        got = protocol.act({"pose": pose, "scan": scan}, _context(grid, pose))
        assert np.array_equal(expected, got)
    assert protocol.target is not None and np.allclose(protocol.target, rich.target)
    # A goal in the context is driven to as a given goal.
    protocol.act({"pose": pose, "scan": scan}, _context(grid, pose, goal=np.array([2.0, 5.0])))
    assert protocol.status == "to_goal" and np.allclose(protocol.target, [2.0, 5.0])
    # Wander reads the scan of the observation, or a bare scan, alike.
    wander = [WanderPolicy(360, np.random.default_rng(1)) for _ in range(2)]
    a = wander[0].act({"scan": scan, "pose": pose}, _context(grid, pose))
    b = wander[1].act(scan)
    assert np.array_equal(a, b) and a.dtype == np.float32


def test_bad_specs_are_refused_in_one_line(forward_module: Path) -> None:
    cases = {
        "no_colon": "expected 'module:factory'",
        "no_such_module_xyz:factory": "cannot import 'no_such_module_xyz'",
        "agents.wander:no_such_factory": "has no callable 'no_such_factory'",
        f"{forward_module.parent / 'missing.py'}:forward": "cannot import",
    }
    for spec, message in cases.items():
        with pytest.raises(ValueError, match=message) as error:
            load_policy_factory(spec)
        assert "\n" not in str(error.value)
    spec = f"{forward_module}:not_a_policy"
    with pytest.raises(ValueError, match="returned int, which has no reset") as error:
        build_policy(load_policy_factory(spec), EnvConfig(), np.random.default_rng(0), spec)
    assert "\n" not in str(error.value)
    with pytest.raises(ValueError, match="calling factory"):
        build_policy(lambda: None, EnvConfig(), np.random.default_rng(0))  # type: ignore[arg-type,misc]
    assert policy_label(None) == "frontier"
    assert policy_label(f"{forward_module}:forward") == "my_policy:forward"


def test_the_cli_refuses_a_bad_policy_in_one_line(
    forward_module: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for argv in (
        ["run", "--policy", f"{forward_module}:not_a_policy", "--out", str(tmp_path / "r")],
        ["bench", "explore", "--policy", "nope_module_xyz:f", "--seeds", "1"],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("mrslam: error: policy") and "\n" not in err, err
    assert not (tmp_path / "r").exists(), "a bad policy is refused before any output"


def test_a_policy_of_ones_own_runs_in_mrslam_run(
    forward_module: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["run", "--scenario", "maze", "--max-steps", "30", "--out", str(tmp_path)]
    argv += ["--no-record", "--json", "--policy", f"{forward_module}:forward"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["policy"] == "my_policy:forward"
    assert report["policy_spec"] == f"{forward_module}:forward"
    assert report["steps"] == 30 and report["complete"]
    saved = json.loads((Path(report["outputs"]["run_dir"]) / "report.json").read_text())
    assert saved["policy"] == "my_policy:forward"
    # The default names its policy too.
    assert main([*argv[:-2]]) == 0
    assert json.loads(capsys.readouterr().out)["policy"] == "frontier"


def test_a_policy_of_ones_own_sits_beside_the_frontier_baseline_in_the_benchmark(
    forward_module: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["bench", "explore", "--scenarios", "maze", "--seeds", "1", "--max-steps", "20"]
    argv += ["--modes", "team,independent", "--policy", f"{forward_module}:forward"]
    assert main([*argv, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    runs = [(r["seed"], r["mode"], r["policy"]) for r in result["runs"]]
    assert runs == [
        (0, "team", "frontier"),
        (0, "independent", "frontier"),
        (0, "team", "my_policy:forward"),
        (0, "independent", "my_policy:forward"),
    ]
    assert [(r["scenario"], r["policy"]) for r in result["summary"]] == [
        ("maze", "frontier"),
        ("maze", "my_policy:forward"),
    ]
    assert main(argv) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].startswith("| scenario | policy | t90 team (s) |")
    assert table[2].startswith("| maze | frontier | 2.0 (1✗) |")
    assert table[3].startswith("| maze | my_policy:forward | 2.0 (1✗) |")


def test_the_team_verifies_by_rendezvous_whatever_the_policy(forward_module: Path) -> None:
    """The team drives the rendezvous legs itself: with a policy that never heads for a
    goal, a true hypothesis is still accepted at the meeting point, and afterwards the
    policy explores in the common frame with a frontier assigned as its goal."""
    from test_agents_team import STARTS, TRUE_TRANSFORM

    factory = load_policy_factory(f"{forward_module}:forward")
    env = MultiRobotSlamEnv(scenario="office", seed=0, config=EnvConfig(starts=STARTS))
    observations, _ = env.reset()
    agents = env.possible_agents
    maps = MapCache(env)
    team = TeamCoordinator(rng=np.random.default_rng(0), policy_factory=factory)
    assert not any(isinstance(p, ExplorerPolicy) for p in team.policies)
    team.hypotheses = [TRUE_TRANSFORM]
    team._last_poses = [observations[a]["pose"] for a in agents]
    team.proposals.retry_area = {(0, 1): np.inf}
    team.verification.start(0, maps)
    assert team.state is TeamState.HYPOTHESIS_VERIFICATION and all(team._on_goal)
    decisions: list[str] = []
    for _ in range(600):
        actions = team.act([observations[a] for a in agents], maps)
        observations, *_ = env.step({a: actions[i] for i, a in enumerate(agents)})
        decisions += [d.text for d in team.pop_decisions()]
        if team.state is TeamState.COORDINATED_EXPLORATION:
            break
    assert team.state is TeamState.COORDINATED_EXPLORATION, decisions
    assert not any(team._on_goal)
    calls = factory.__globals__["CALLS"]  # type: ignore[attr-defined]
    calls.clear()
    for _ in range(30):
        actions = team.act([observations[a] for a in agents], maps)
        observations, *_ = env.step({a: actions[i] for i, a in enumerate(agents)})
    assert {robot for robot, _, _ in calls} == {0, 1}
    assert all(common for _, common, _ in calls)
    assert any(goal is not None for _, _, goal in calls), "a frontier was assigned"
