"""Sweeps: the process pool and Ray give the same results in task order, and the same
`bench explore` table; a folder of kept reports rebuilds it."""

from __future__ import annotations

import json
import os
import posixpath
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from scenarios.bench.explore import format_explore_table, run_explore_benchmark, summarise_reports
from scenarios.bench.merge.pairs import PairGenerationConfig, generate_pairs
from scenarios.cli import main
from scenarios.sweep import TaskError, run_tasks

PATHS = ["a/b", "c/d", "e", "f/g/h"]
basename: Callable[[str], str] = posixpath.basename  # one signature of the overloads


def test_the_pool_returns_results_in_task_order_and_streams_each() -> None:
    seen: list[str] = []
    assert run_tasks(basename, PATHS, jobs=2, on_result=seen.append) == [
        "b",
        "d",
        "e",
        "h",
    ]
    assert seen == ["b", "d", "e", "h"]


def test_no_tasks_give_no_results() -> None:
    assert run_tasks(basename, [], jobs=1) == []


def test_jobs_below_one_are_refused() -> None:
    with pytest.raises(ValueError, match="jobs must be >= 1"):
        run_tasks(basename, PATHS, jobs=0)


def test_ray_missing_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(ValueError, match=r"--ray needs Ray: pip install 'mrslam\[ray\]'"):
        run_tasks(basename, PATHS, ray="")


BLOCKED_S = 60.0
"""How long the blocking task of the next test runs unless it is ended: the old pool
waited for it, and then finished it."""


def _fail_once_the_other_runs_or_block(task: tuple[str, str]) -> str:
    """``("block", folder)``: note this process, then run until a file that never comes
    (``BLOCKED_S`` at most) and note that it finished. ``("fail", folder)``: raise once
    the blocking task runs (polled against a deadline)."""
    role, folder = task
    where = Path(folder)
    deadline = time.monotonic() + BLOCKED_S
    if role == "block":
        (where / f"running-{os.getpid()}").touch()
        while not (where / "never").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        (where / "finished").touch()
        return role
    while not any(where.glob("running-*")) and time.monotonic() < deadline:
        time.sleep(0.05)
    raise ValueError("failed on purpose")


def test_a_failed_task_ends_the_running_ones_instead_of_waiting_for_them(
    tmp_path: Path,
) -> None:
    tasks = [("fail", str(tmp_path)), ("block", str(tmp_path)), ("block", str(tmp_path))]
    with pytest.raises(TaskError, match=r"task 1 of 3 .* ValueError: failed on purpose$"):
        run_tasks(_fail_once_the_other_runs_or_block, tasks, jobs=2)
    # The running task was ended, not waited for, and so were the others.
    # (The third may have started too, in the worker the failed task freed.)
    running = list(tmp_path.glob("running-*"))
    assert 1 <= len(running) <= 2
    assert not (tmp_path / "finished").exists()
    for noted in running:
        pid = int(noted.name.removeprefix("running-"))
        with pytest.raises(ProcessLookupError):  # terminated and reaped: none left behind
            os.kill(pid, 0)


# --- bench explore: the same table from the pool, from Ray, and from kept reports ----------

SWEEP = {"scenarios": ["office"], "seeds": range(2), "max_steps": 120, "modes": ("team",)}


def _without_wall_time(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in run.items() if k != "wall_time"} for run in runs]


def _without_times(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in row.items() if "wall" not in k} for row in rows]


@pytest.fixture(scope="module")
def pool_sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any, Any]:
    out = tmp_path_factory.mktemp("sweep") / "kept"
    rows, runs = run_explore_benchmark(**SWEEP, jobs=2, out=out)  # type: ignore[arg-type]
    return out, rows, runs


def test_a_ray_sweep_gives_the_same_table_as_the_pool(
    pool_sweep: tuple[Path, Any, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("ray")
    monkeypatch.setenv("TMPDIR", "/tmp")  # Ray's socket paths must stay short
    _, rows, runs = pool_sweep
    ray_rows, ray_runs = run_explore_benchmark(**SWEEP, jobs=2, ray="")  # type: ignore[arg-type]
    assert len(runs) == 2
    assert _without_wall_time(ray_runs) == _without_wall_time(runs)
    assert _without_times(ray_rows) == _without_times(rows)
    assert format_explore_table(ray_rows) == format_explore_table(rows)


def test_out_keeps_each_report_and_the_table_and_the_summary_rebuilds_from_them(
    pool_sweep: tuple[Path, Any, Any],
) -> None:
    out, rows, runs = pool_sweep
    reports = sorted((out / "reports").glob("*.json"))
    assert [r.name for r in reports] == ["office-0-team-2.json", "office-1-team-2.json"]
    report = json.loads(reports[0].read_text(encoding="utf-8"))
    assert report["seed"] == 0 and report["steps"] >= 1 and "coverage_curve" in report
    assert (out / "explore.md").read_text(encoding="utf-8") == format_explore_table(rows) + "\n"
    assert json.loads((out / "summary.json").read_text(encoding="utf-8"))["runs"] == runs
    rebuilt_rows, rebuilt_runs = summarise_reports(out)
    assert rebuilt_runs == runs and rebuilt_rows == rows


def test_the_cli_rebuilds_the_table_from_a_folder_of_reports(
    pool_sweep: tuple[Path, Any, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    out, rows, _ = pool_sweep
    assert main(["bench", "explore", "--from", str(out)]) == 0
    assert capsys.readouterr().out == format_explore_table(rows) + "\n"


def test_out_refuses_a_folder_that_holds_something(tmp_path: Path) -> None:
    (tmp_path / "old.txt").write_text("keep me", encoding="utf-8")
    with pytest.raises(ValueError, match="already exists and is not an empty folder"):
        run_explore_benchmark(**SWEEP, out=tmp_path)  # type: ignore[arg-type]
    assert (tmp_path / "old.txt").read_text(encoding="utf-8") == "keep me"


def test_a_folder_without_reports_is_one_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no run reports"):
        summarise_reports(tmp_path)
    (tmp_path / "reports").mkdir()
    (tmp_path / "reports" / "x.json").write_text("{}", encoding="utf-8")
    with pytest.raises(ValueError, match="not a bench explore run report"):
        summarise_reports(tmp_path)


# --- bench merge: the same pairs simulated one world at a time, in processes, on Ray ------

PAIRS = PairGenerationConfig(
    n_pairs=3,
    worlds=("maze", "office"),
    runs_per_world=2,
    checkpoints=(40, 100),
    no_overlap_fraction=0.34,
    min_known_area=1.0,
)


def _generated(folder: Path, **engine: Any) -> tuple[dict[str, Any], list[bytes]]:
    generate_pairs(PAIRS, folder, **engine)
    manifest = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    manifest.pop("generation_seconds")
    maps = [(folder / e[key]).read_bytes() for e in manifest["pairs"] for key in ("map1", "map2")]
    return manifest, maps


def test_pairs_are_the_same_from_the_pool_and_from_ray(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    serial = _generated(tmp_path / "serial")
    assert serial[0]["pairs"], "the tiny set made no pair"
    assert _generated(tmp_path / "pool", jobs=2) == serial
    pytest.importorskip("ray")
    monkeypatch.setenv("TMPDIR", "/tmp")
    assert _generated(tmp_path / "ray", jobs=2, ray="") == serial
