"""Sweeps: the process pool and Ray give the same results in task order."""

from __future__ import annotations

import posixpath
import sys

import pytest

from scenarios.sweep import run_tasks

PATHS = ["a/b", "c/d", "e", "f/g/h"]


def test_the_pool_returns_results_in_task_order_and_streams_each() -> None:
    seen: list[str] = []
    assert run_tasks(posixpath.basename, PATHS, jobs=2, on_result=seen.append) == [
        "b",
        "d",
        "e",
        "h",
    ]
    assert seen == ["b", "d", "e", "h"]


def test_no_tasks_give_no_results() -> None:
    assert run_tasks(posixpath.basename, [], jobs=1) == []


def test_jobs_below_one_are_refused() -> None:
    with pytest.raises(ValueError, match="jobs must be >= 1"):
        run_tasks(posixpath.basename, PATHS, jobs=0)


def test_ray_missing_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(ValueError, match=r"--ray needs Ray: pip install 'mrslam\[ray\]'"):
        run_tasks(posixpath.basename, PATHS, ray="")
