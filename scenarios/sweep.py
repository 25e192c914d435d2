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

Joining a cluster on this machine, the driver uses token authentication when a token is at
hand (``RAY_AUTH_TOKEN``, ``RAY_AUTH_TOKEN_PATH`` or ``~/.ray/auth_token``) and
``RAY_AUTH_MODE`` is not set: the rule ``ray start --head`` applied here. Since Ray 2.59 the
first local ``ray.init()`` writes ``~/.ray/auth_token``, and a later ``ray start --head``
finds it and turns token authentication on, while ``ray.init(address="HOST:PORT")`` by
itself only uses tokens with ``RAY_AUTH_MODE=token``: joining the address that
``ray start --head`` printed failed after 20 s of ``Unauthenticated`` lines. The token goes
only where it came from (:func:`uses_local_token`): to an address whose host is this machine
(a loopback address, or a name or address that resolves only to addresses of this
machine's own interfaces). A cluster elsewhere, by ``ADDRESS``, ``ray://`` or
``RAY_ADDRESS``, gets Ray's own rule: an explicit address never sends the token unless
``RAY_AUTH_MODE=token`` says so. ``RAY_AUTH_MODE=disabled`` opts out here too. Ray turns
token mode on through the process environment (``RAY_AUTH_MODE=token``) and its cached
configuration; both are put back when the sweep ends (if Ray's private configuration call
ever fails, the cached mode stays on for the rest of the process). If that Ray code moves or
changes, the sweep falls back to Ray's own behaviour.

The workers get the run's environment that a task may read: every variable whose name
starts with ``MRSLAM_`` (e.g. ``MRSLAM_SB3_MODEL``, the model examples/sb3_policy.py
loads), through Ray's ``runtime_env`` (``env_vars``). Paths in them are opened on the
worker's machine: give absolute paths there. (The process pool's workers inherit the
whole environment.)

A task that raises stops the sweep with :class:`TaskError`: which task, and the worker's
own error line (``ValueError: ...``), the same from the pool and from Ray; so does a Ray
worker that dies (``WorkerCrashedError``, ``OutOfMemoryError``, ...: any ``RayError``). It is
a ``RuntimeError``, never the cause's type (Ray's ``RayTaskError`` subclasses it): a
``ValueError`` in a worker is a failed run, not bad input to the command (exit 1, not 2).
The other tasks are stopped at once, not waited for: the pool cancels those not started
and terminates its worker processes (SIGTERM, then SIGKILL after
:data:`POOL_STOP_GRACE_S`), so no run is left behind; Ray cancels the remaining tasks.

Each task is a module-level function and a picklable argument tuple, so the same task
runs in either engine and gives the same row: the table is the same whichever ran it (a
test checks that).
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import os
import reprlib
import socket
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context
from typing import Any, TypeVar
from urllib.parse import urlsplit

__all__ = [
    "POOL_STOP_GRACE_S",
    "RAY_ENV_PREFIX",
    "RAY_EXTRA",
    "TaskError",
    "ray_env_vars",
    "ray_init_arguments",
    "run_tasks",
    "uses_local_token",
]

T = TypeVar("T")
R = TypeVar("R")

RAY_EXTRA = "pip install 'mrslam[ray]'"
"""What to install for ``--ray``."""

RAY_ENV_PREFIX = "MRSLAM_"
"""The environment variables whose names start with this reach the Ray workers."""

POOL_STOP_GRACE_S = 5.0
"""After a failed task, how long the pool's running workers have to end after SIGTERM (a
run notes the signal and ends at its next step; scenarios/interrupts.py) before SIGKILL."""

_AUTH_MODE = "RAY_AUTH_MODE"


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
        When a task raises, or its Ray worker dies (the first in task order for the pool,
        the first to finish for Ray). The other tasks are not waited for: those not yet
        started are cancelled, and those running end with the sweep (the pool terminates
        its workers; Ray cancels them).
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
                _stop_pool(pool)
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


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel the tasks not started and end the running ones now, without waiting for
    them (``shutdown(wait=True)`` would wait minutes for runs whose rows are not used):
    SIGTERM to every worker, SIGKILL to those alive after :data:`POOL_STOP_GRACE_S`, and
    each one joined, so none is left running. (What Python 3.14's
    ``terminate_workers`` does, and a bounded wait after it.)"""
    # shutdown() forgets the processes: take them first (a private attribute; Python
    # 3.14's terminate_workers reads it the same way).
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    deadline = time.monotonic() + POOL_STOP_GRACE_S
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
        if process.is_alive():
            process.kill()
            process.join()


def uses_local_token(address: str, environ: Mapping[str, str]) -> bool:
    """Whether ``--ray ADDRESS`` joins with this machine's Ray token (module notes): only
    when the cluster's address (``address``, or ``RAY_ADDRESS`` for ``""`` and
    ``"auto"``) names this machine. ``"local"``, and ``"auto"`` or ``""`` without
    ``RAY_ADDRESS``, are left to Ray (a new local instance, or the local cluster Ray
    finds, where Ray applies the same rule itself)."""
    target = address if address not in ("", "auto") else environ.get("RAY_ADDRESS", "")
    if target in ("", "auto", "local"):
        return False
    host = urlsplit("//" + target.split("://", 1)[-1]).hostname
    return bool(host) and _is_this_machine(str(host))


def _is_this_machine(host: str) -> bool:
    """``host`` resolves, and only to loopback addresses or addresses of this machine's
    own interfaces (a socket binds to it); a name that does not resolve is not."""
    try:
        found = socket.getaddrinfo(host, None, type=socket.SOCK_DGRAM)
    except (OSError, UnicodeError):
        return False
    return bool(found) and all(_is_own_address(info[0], info[4]) for info in found)


def _is_own_address(family: int, sockaddr: Any) -> bool:
    try:
        if ipaddress.ip_address(str(sockaddr[0]).split("%")[0]).is_loopback:
            return True
    except ValueError:
        return False
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as probe:
            probe.bind(sockaddr)  # port 0: only an address of this machine binds
    except OSError:
        return False
    return True


def _use_local_token() -> None:
    """Turn token authentication on for this process, as Ray does for the local cluster it
    finds, when ``RAY_AUTH_MODE`` is unset and a token is at hand (module notes). Ray's
    private function: any failure of it (Ray before 2.52, moved, changed) leaves Ray's own
    behaviour; its warning, meant for ``ray start``, is not shown."""
    try:
        from ray._private.authentication import authentication_token_setup as setup

        logger = logging.getLogger(setup.__name__)
        level = logger.level
        logger.setLevel(logging.ERROR)
        try:
            setup.maybe_enable_token_auth_if_token_available(warn_if_disabled=False)
        finally:
            logger.setLevel(level)
    except Exception:  # a fallback to Ray's own behaviour, by design
        return


def _restore_auth_mode(before: str | None) -> None:
    """Put ``RAY_AUTH_MODE`` back as it was before the sweep joined, and Ray's cached
    configuration with it (after ``ray.shutdown``: nothing uses it any more)."""
    if os.environ.get(_AUTH_MODE) == before:
        return
    if before is None:
        os.environ.pop(_AUTH_MODE, None)
    else:
        os.environ[_AUTH_MODE] = before
    try:
        from ray._raylet import Config  # type: ignore[attr-defined]  # not in its stub

        Config.initialize("")  # Ray re-reads RAY_AUTH_MODE
    except Exception:  # then the cached mode stays (module notes)
        return


def _run_on_ray(
    function: Callable[[T], R],
    tasks: Sequence[T],
    jobs: int,
    address: str,
    on_result: Callable[[R], None] | None,
) -> list[R]:
    try:
        import ray
        from ray.exceptions import RayError, RayTaskError
    except ImportError as error:
        raise ValueError(f"--ray needs Ray: {RAY_EXTRA}") from error
    started = not ray.is_initialized()
    auth_mode = os.environ.get(_AUTH_MODE)
    try:
        if started:
            arguments = ray_init_arguments(address, jobs, os.environ)
            if uses_local_token(address, os.environ):
                _use_local_token()
            ray.init(**arguments)
        try:
            return _ray_results(ray, function, tasks, on_result, RayError, RayTaskError)
        finally:
            if started:
                ray.shutdown()
    finally:
        if started:
            _restore_auth_mode(auth_mode)


def _ray_results(
    ray: Any,
    function: Callable[[T], R],
    tasks: Sequence[T],
    on_result: Callable[[R], None] | None,
    ray_error: type[BaseException],
    ray_task_error: type[BaseException],
) -> list[R]:
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
            except ray_error as error:
                for other in pending:
                    # Best effort: the job's tasks end anyway as the driver disconnects.
                    with contextlib.suppress(Exception):
                        ray.cancel(other)
                line = _ray_error_line(error, ray_task_error)
                raise _task_failed(index, len(tasks), tasks[index], line) from error
            results[index] = result
            if on_result is not None:
                on_result(result)
    return [results[index] for index in range(len(tasks))]


def _ray_error_line(error: BaseException, ray_task_error: type[BaseException]) -> str:
    """The worker's own error line for a ``RayTaskError``; the error's first line for
    the others (``WorkerCrashedError: The worker died unexpectedly ...``)."""
    if not isinstance(error, ray_task_error):
        return _error_line(error)
    cause = getattr(error, "cause", None)
    return _error_line(cause) if isinstance(cause, BaseException) else _last_line(error)


def _last_line(error: BaseException) -> str:
    """The last line of a ``RayTaskError`` whose cause did not travel back (the
    traceback's ``Type: message``)."""
    lines = [line for line in str(error).strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else type(error).__name__
