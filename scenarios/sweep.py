"""Independent benchmark runs, run at once: in a local process pool (the default) or as
Ray tasks (``--ray``), with the results back in task order.

The pool is one machine's way; Ray is the way past it. Which cluster ``--ray`` uses
follows ``ray.init``'s conventions (:func:`ray_init_arguments`):

* ``ray=""`` (``--ray`` alone) starts a local Ray instance of ``jobs`` CPUs for the sweep
  and stops it after, even if another instance runs on the machine; but with
  ``RAY_ADDRESS`` set it joins that cluster, as ``ray.init()`` and Ray's own tools do.
* ``ray="ADDRESS"`` (``"auto"``, ``"HOST:PORT"`` as ``ray start --head`` prints it,
  ``"ray://head:10001"``, ...) joins that cluster, whose workers must have mrslam
  installed.

Joining, the driver uses token authentication when a token is at hand (``RAY_AUTH_TOKEN``,
``RAY_AUTH_TOKEN_PATH`` or ``~/.ray/auth_token``) and ``RAY_AUTH_MODE`` is not set: the
rule ``ray start --head`` applied on this machine. Since Ray 2.59 the first local
``ray.init()`` writes ``~/.ray/auth_token``, and a later ``ray start --head`` finds it and
turns token authentication on, while ``ray.init(address="HOST:PORT")`` by itself only
uses tokens with ``RAY_AUTH_MODE=token``, so it was refused. A token sent to a cluster
without authentication does no harm; ``RAY_AUTH_MODE=disabled`` opts out.

The workers get the run's environment that a task may read: every variable whose name
starts with ``MRSLAM_`` (e.g. ``MRSLAM_SB3_MODEL``, the model examples/sb3_policy.py
loads), through Ray's ``runtime_env`` (``env_vars``). Paths in them are opened on the
worker's machine: give absolute paths there. (The process pool's workers inherit the
whole environment.)

A task that raises stops the sweep with :class:`TaskError`: which task, and the worker's
own error line (``ValueError: ...``), the same from the pool and from Ray. It is a
``RuntimeError``, never the cause's type (Ray's ``RayTaskError`` subclasses it): a
``ValueError`` in a worker is a failed run, not bad input to the command (exit 1, not 2).

Each task is a module-level function and a picklable argument tuple, so the same task
runs in either engine and gives the same row: the table is the same whichever ran it (a
test checks that).
"""

from __future__ import annotations

import os
import reprlib
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context
from typing import Any, TypeVar

__all__ = [
    "RAY_ENV_PREFIX",
    "RAY_EXTRA",
    "TaskError",
    "ray_env_vars",
    "ray_init_arguments",
    "run_tasks",
]

T = TypeVar("T")
R = TypeVar("R")

RAY_EXTRA = "pip install 'mrslam[ray]'"
"""What to install for ``--ray``."""

RAY_ENV_PREFIX = "MRSLAM_"
"""The environment variables whose names start with this reach the Ray workers."""


class TaskError(RuntimeError):
    """A task raised in its worker: which task, and the worker's own error line."""


def _task_failed(index: int, total: int, task: Any, line: str) -> TaskError:
    return TaskError(f"task {index + 1} of {total} {reprlib.repr(task)} failed: {line}")


def _error_line(error: BaseException) -> str:
    """``"Type: first line of the message"``, as a traceback ends."""
    lines = str(error).strip().splitlines()
    name = type(error).__name__
    return f"{name}: {lines[0]}" if lines else name


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

    Raises
    ------
    TaskError
        When a task raises (the first in task order for the pool, the first to finish
        for Ray); the tasks not yet started are cancelled.
    ValueError
        For ``jobs < 1``, or ``ray`` without Ray installed.
    """
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    if ray is not None:
        return _run_on_ray(function, tasks, jobs, ray, on_result)
    results: list[R] = []
    # Spawned, not forked: a fork of a process whose libraries keep thread pools (torch,
    # BLAS, numba) can deadlock in the child.
    with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
        futures: list[Future[R]] = [pool.submit(function, task) for task in tasks]
        for index, future in enumerate(futures):
            try:
                result = future.result()
            except BrokenProcessPool:
                raise
            except Exception as error:
                pool.shutdown(wait=True, cancel_futures=True)
                raise _task_failed(index, len(tasks), tasks[index], _error_line(error)) from error
            results.append(result)
            if on_result is not None:
                on_result(result)
    return results


def ray_env_vars(environ: Mapping[str, str]) -> dict[str, str]:
    """The variables of ``environ`` that go to the Ray workers (``MRSLAM_*``)."""
    return {key: value for key, value in environ.items() if key.startswith(RAY_ENV_PREFIX)}


def ray_init_arguments(address: str, jobs: int, environ: Mapping[str, str]) -> dict[str, Any]:
    """``ray.init``'s keyword arguments for ``--ray [ADDRESS]`` (module notes): a local
    instance of ``jobs`` CPUs (``address="local"``: a new one, whatever else runs here)
    for ``""`` without ``RAY_ADDRESS``; else no resources (Ray refuses them when joining),
    and the address when one is given (with none, ``ray.init`` reads ``RAY_ADDRESS``)."""
    if address:
        return {"address": address, "log_to_driver": False}
    if environ.get("RAY_ADDRESS"):
        return {"log_to_driver": False}
    return {
        "address": "local",
        "num_cpus": jobs,
        "include_dashboard": False,
        "log_to_driver": False,
    }


def _use_token_if_available() -> None:
    """Join with token authentication when ``RAY_AUTH_MODE`` is unset and a token is at
    hand: Ray's own rule for ``ray start --head`` and ``ray.init("auto")``, which
    ``ray.init("HOST:PORT")`` does not apply (module notes)."""
    try:
        from ray._private.authentication.authentication_token_setup import (
            maybe_enable_token_auth_if_token_available,
        )
    except ImportError:  # Ray before token authentication (2.52), or it moved
        return
    maybe_enable_token_auth_if_token_available(warn_if_disabled=False)


def _run_on_ray(
    function: Callable[[T], R],
    tasks: Sequence[T],
    jobs: int,
    address: str,
    on_result: Callable[[R], None] | None,
) -> list[R]:
    try:
        import ray
        from ray.exceptions import RayTaskError
    except ImportError as error:
        raise ValueError(f"--ray needs Ray: {RAY_EXTRA}") from error
    started = not ray.is_initialized()
    if started:
        arguments = ray_init_arguments(address, jobs, os.environ)
        if arguments.get("address") != "local":
            _use_token_if_available()
        ray.init(**arguments)
    try:
        options: dict[str, Any] = {"num_cpus": 1, "max_retries": 0}
        env_vars = ray_env_vars(os.environ)
        if env_vars:
            options["runtime_env"] = {"env_vars": env_vars}
        remote = ray.remote(**options)(function)
        pending = {remote.remote(task): index for index, task in enumerate(tasks)}
        results: dict[int, R] = {}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                index = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except RayTaskError as error:
                    for other in pending:
                        ray.cancel(other)
                    cause = error.cause if isinstance(error.cause, BaseException) else None
                    line = _error_line(cause) if cause is not None else _last_line(error)
                    raise _task_failed(index, len(tasks), tasks[index], line) from error
                results[index] = result
                if on_result is not None:
                    on_result(result)
        return [results[index] for index in range(len(tasks))]
    finally:
        if started:
            ray.shutdown()


def _last_line(error: BaseException) -> str:
    """The last line of a ``RayTaskError`` whose cause did not travel back (the
    traceback's ``Type: message``)."""
    lines = [line for line in str(error).strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else type(error).__name__
