"""Independent benchmark runs, run at once: in a local process pool (the default) or as
Ray tasks (``--ray``), with the results back in task order.

The pool is one machine's way; Ray is the way past it. ``ray=""`` starts a local Ray
instance for the sweep (and stops it after); ``ray="ADDRESS"`` (``"auto"``,
``"ray://head:10001"``, ...) joins an existing cluster, whose workers must have mrslam
installed. Each task is a module-level function and a picklable argument tuple, so the
same task runs in either engine and gives the same row: the table is the same whichever
ran it (a test checks that).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from typing import TypeVar

__all__ = ["RAY_EXTRA", "run_tasks"]

T = TypeVar("T")
R = TypeVar("R")

RAY_EXTRA = "pip install 'mrslam[ray]'"
"""What to install for ``--ray``."""


def run_tasks(
    function: Callable[[T], R],
    tasks: Sequence[T],
    *,
    jobs: int = 1,
    ray: str | None = None,
    on_result: Callable[[R], None] | None = None,
) -> list[R]:
    """``[function(task) for task in tasks]``, run ``jobs`` at a time in processes, or as
    Ray tasks when ``ray`` is not None (module notes).

    ``on_result`` sees each result as it arrives (the pool: in task order; Ray: in the
    order the tasks finish); the returned list is always in task order.
    """
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    if ray is not None:
        return _run_on_ray(function, tasks, jobs, ray, on_result)
    results: list[R] = []
    # Spawned, not forked: a fork of a process whose libraries keep thread pools (torch,
    # BLAS, numba) can deadlock in the child.
    with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
        for result in pool.map(function, tasks):
            results.append(result)
            if on_result is not None:
                on_result(result)
    return results


def _run_on_ray(
    function: Callable[[T], R],
    tasks: Sequence[T],
    jobs: int,
    address: str,
    on_result: Callable[[R], None] | None,
) -> list[R]:
    try:
        import ray
    except ImportError as error:
        raise ValueError(f"--ray needs Ray: {RAY_EXTRA}") from error
    started = not ray.is_initialized()
    if started:
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            # A local instance of ``jobs`` CPUs: as many runs at a time as the pool.
            ray.init(num_cpus=jobs, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(function)
        pending = {remote.remote(task): index for index, task in enumerate(tasks)}
        results: dict[int, R] = {}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                result = ray.get(ref)
                results[pending.pop(ref)] = result
                if on_result is not None:
                    on_result(result)
        return [results[index] for index in range(len(tasks))]
    finally:
        if started:
            ray.shutdown()
