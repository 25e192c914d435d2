"""Sweeps on Ray by Ray's conventions (issue 36): which ``ray.init`` arguments for which
``--ray`` and environment, joining a ``ray start --head`` cluster that uses token
authentication, ``RAY_ADDRESS``, the run's ``MRSLAM_*`` variables on the workers, and a
worker's failure reported by its own error line (exit 1, not 2).

One real head (``ray start --head --block``, its own temp dir and home, so that it never
meets another test's local instance) serves the module; each driver runs in a subprocess,
so that Ray's per-process authentication state never leaks into the test process. Every
subprocess has a deadline: nothing here waits forever."""

from __future__ import annotations

import ipaddress
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from scenarios import sweep
from scenarios.cli import main
from scenarios.sweep import (
    TaskError,
    ray_env_vars,
    ray_init_arguments,
    run_tasks,
    uses_local_token,
)

ROOT = Path(__file__).resolve().parents[1]
RAY = Path(sys.executable).with_name("ray")
HEAD_MARK = "SWEEP_TEST_HEAD"
"""Set in the head's environment only: a task that sees it ran on that cluster."""
HEAD_START_S = 120.0
"""The deadline for the head to print its address."""
DRIVER_S = 240.0
"""The deadline for one driver process."""
TOKEN_WARNING = "Token authentication is enabled for this Ray cluster"


# --- the decisions, as units ---------------------------------------------------------------


def test_plain_ray_starts_a_local_instance_of_jobs_cpus() -> None:
    assert ray_init_arguments("", 3, {}) == {
        "address": "local",
        "num_cpus": 3,
        "include_dashboard": False,
        "log_to_driver": False,
    }


def test_plain_ray_with_ray_address_set_joins_that_cluster_as_ray_init_does() -> None:
    # No num_cpus: Ray refuses it when joining, and reads RAY_ADDRESS itself.
    assert ray_init_arguments("", 3, {"RAY_ADDRESS": "10.0.0.5:6379"}) == {"log_to_driver": False}
    assert ray_init_arguments("", 3, {"RAY_ADDRESS": ""})["address"] == "local"


def test_an_address_joins_that_cluster() -> None:
    environ = {"RAY_ADDRESS": "10.0.0.5:6379"}
    assert ray_init_arguments("auto", 2, environ) == {"address": "auto", "log_to_driver": False}
    assert ray_init_arguments("ray://head:10001", 2, {}) == {
        "address": "ray://head:10001",
        "log_to_driver": False,
    }


def _an_address_of_this_machine_that_is_not_loopback() -> str | None:
    """The source address of a route out (no packet is sent), if this machine has one."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))  # TEST-NET-1: routing only
        except OSError:
            return None
        address = str(probe.getsockname()[0])
    return None if address.startswith("127.") else address


def test_the_local_token_goes_only_to_a_cluster_on_this_machine() -> None:
    here = ["127.0.0.1:6379", "localhost:6379", "[::1]:6379", "ray://127.0.0.1:10001"]
    for address in here:
        assert uses_local_token(address, {}), address
    # Elsewhere, whatever the form: Ray's own rule (no token unless RAY_AUTH_MODE=token).
    # 203.0.113.0/24 is TEST-NET-3, .invalid never resolves (RFC 6761).
    elsewhere = ["203.0.113.9:6379", "ray://203.0.113.9:10001", "ray://remote.invalid:10001"]
    for address in elsewhere:
        assert not uses_local_token(address, {}), address
    # RAY_ADDRESS is the address for --ray alone and for "auto"; an explicit one wins.
    assert not uses_local_token("", {"RAY_ADDRESS": "203.0.113.9:6379"})
    assert not uses_local_token("auto", {"RAY_ADDRESS": "ray://203.0.113.9:10001"})
    assert uses_local_token("", {"RAY_ADDRESS": "127.0.0.1:6379"})
    assert not uses_local_token("203.0.113.9:6379", {"RAY_ADDRESS": "127.0.0.1:6379"})
    # A new local instance, or the local cluster Ray finds itself: left to Ray.
    for address in ("", "auto", "local"):
        assert not uses_local_token(address, {}), address


def test_this_machines_own_name_and_address_are_this_machine() -> None:
    name = socket.gethostname()
    try:
        socket.getaddrinfo(name, None)
    except OSError:
        pytest.skip(f"this machine's name {name!r} does not resolve")
    assert uses_local_token(f"{name}:6379", {})
    address = _an_address_of_this_machine_that_is_not_loopback()
    if address is None:
        pytest.skip("no address besides loopback")
    assert uses_local_token(f"{address}:6379", {})
    assert uses_local_token(f"ray://{address}:10001", {"RAY_ADDRESS": "203.0.113.9:1"})


@pytest.mark.parametrize(
    "changed",
    [lambda: True, lambda warn_if_disabled: 1 / 0],
    ids=["signature changed", "raises"],
)
def test_when_rays_private_token_call_fails_the_sweep_keeps_rays_own_behaviour(
    monkeypatch: pytest.MonkeyPatch, changed: object
) -> None:
    pytest.importorskip("ray")
    from ray._private.authentication import authentication_token_setup as setup

    monkeypatch.setattr(setup, "maybe_enable_token_auth_if_token_available", changed)
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    sweep._use_local_token()  # no TypeError / ZeroDivisionError
    assert "RAY_AUTH_MODE" not in os.environ


def test_every_mrslam_variable_and_only_those_go_to_the_workers() -> None:
    environ = {"MRSLAM_SB3_MODEL": "/m/ppo.zip", "MRSLAM_X": "1", "HOME": "/h", "PATH": "/b"}
    assert ray_env_vars(environ) == {"MRSLAM_SB3_MODEL": "/m/ppo.zip", "MRSLAM_X": "1"}


# --- a worker's failure: its own error line, exit 1 ----------------------------------------


def test_a_pool_worker_failure_names_the_task_and_the_workers_error_line() -> None:
    with pytest.raises(TaskError) as raised:
        run_tasks(ipaddress.ip_address, ["10.0.0.1", "x", "::1"], jobs=2)
    message = str(raised.value)
    assert not isinstance(raised.value, ValueError)  # not "bad input"
    assert "task 2 of 3" in message
    assert message.endswith("ValueError: 'x' does not appear to be an IPv4 or IPv6 address")
    assert "\n" not in message


def test_the_cli_exits_1_with_the_workers_error_when_a_run_fails(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import scenarios.bench.explore as explore

    # Every run raises ValueError in its worker (ip_address refuses the task tuple).
    monkeypatch.setattr(explore, "_task", ipaddress.ip_address)
    argv = ["bench", "explore", "--scenarios", "office", "--seeds", "1", "--modes", "team"]
    assert main([*argv, "--max-steps", "5"]) == 1
    error = capsys.readouterr().err
    assert "task 1 of 1" in error
    assert "ValueError: (0, 'office', 0, 5, None, 2, 'team', None) does not appear to be" in error


# --- a real cluster: ray start --head with a token, joined by address or RAY_ADDRESS --------


@pytest.fixture(scope="module")
def head(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, dict[str, str]]]:
    """A one-CPU head with token authentication on (as ``ray start --head`` turns it on
    when a token exists, e.g. after any local ``ray.init()``); its address and the
    environment a driver on this machine has (the same home, hence the same token)."""
    pytest.importorskip("ray")
    home = tmp_path_factory.mktemp("home")
    (home / ".ray").mkdir()
    (home / ".ray" / "auth_token").write_text("0123456789abcdef" * 4, encoding="utf-8")
    # Short socket paths: Ray's temp dir under /tmp, not pytest's deep tmp_path.
    temp_dir = Path(tempfile.mkdtemp(prefix="mrslam-ray-", dir="/tmp"))
    environ = {
        key: value for key, value in os.environ.items() if not key.startswith(("RAY_", "MRSLAM_"))
    }
    environ.update(HOME=str(home), TMPDIR="/tmp")
    command = [str(RAY), "start", "--head", "--block", "--port", "0", "--num-cpus", "1"]
    command += ["--include-dashboard=false", "--disable-usage-stats", "--temp-dir", str(temp_dir)]
    # Its output goes to a file, read against a deadline: a pipe nobody drains would block
    # the head once full, and reading a pipe line by line has no deadline.
    log = tmp_path_factory.mktemp("head") / "head.log"
    with log.open("wb") as output:
        process = subprocess.Popen(
            command,
            env={**environ, HEAD_MARK: "yes"},
            stdout=output,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # its own process group: stopped with it, nothing else
        )
    try:
        found = None
        deadline = time.monotonic() + HEAD_START_S
        while found is None and process.poll() is None and time.monotonic() < deadline:
            text = log.read_text(encoding="utf-8", errors="replace")
            found = re.search(r"ray start --address='([^']+)'", text)
            if found is None:
                time.sleep(0.2)  # polling the log, bounded by the deadline
        text = log.read_text(encoding="utf-8", errors="replace")
        if found is None:
            state = "exited" if process.poll() is not None else f"silent {HEAD_START_S:.0f} s"
            pytest.fail(f"ray start --head printed no address ({state}):\n{text[-3000:]}")
        assert TOKEN_WARNING in text
        yield found.group(1), environ
    finally:
        os.killpg(process.pid, signal.SIGKILL)  # this head's processes only
        process.wait(timeout=60)
        shutil.rmtree(temp_dir, ignore_errors=True)


def _driver(environ: dict[str, str], code: str) -> subprocess.CompletedProcess[str]:
    """Run ``code`` (after ``from scenarios.sweep import ...``) in a fresh driver process."""
    script = "import json, os\nfrom ipaddress import ip_address\n"
    script += "from scenarios.sweep import TaskError, run_tasks\n"
    return subprocess.run(
        [sys.executable, "-c", script + textwrap.dedent(code)],
        env=environ,
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
        timeout=DRIVER_S,  # TimeoutExpired (the driver killed) rather than a hang
    )


def test_joining_a_token_head_by_its_printed_address_passes_the_mrslam_variables(
    head: tuple[str, dict[str, str]],
) -> None:
    address, environ = head
    code = f"""
        names = ["{HEAD_MARK}", "MRSLAM_SB3_MODEL", "MRSLAM_UNSET"]
        print(json.dumps(run_tasks(os.getenv, names, ray={address!r})))
        from ray._raylet import AuthenticationMode, get_authentication_mode
        token_mode = get_authentication_mode() == AuthenticationMode.TOKEN
        print(json.dumps([os.environ.get("RAY_AUTH_MODE"), token_mode]))
        """
    done = _driver({**environ, "MRSLAM_SB3_MODEL": "/models/ppo.zip"}, code)
    assert done.returncode == 0, done.stderr[-2000:]
    joined, after = done.stdout.splitlines()[-2:]
    assert json.loads(joined) == ["yes", "/models/ppo.zip", None]
    # Token mode was on for the sweep only: the environment and Ray's cached setting are
    # back as they were, and Ray's warning meant for `ray start` was not shown.
    assert json.loads(after) == [None, False]
    assert TOKEN_WARNING not in done.stderr


def test_plain_ray_joins_the_cluster_ray_address_names_and_reports_a_worker_error(
    head: tuple[str, dict[str, str]],
) -> None:
    address, environ = head
    code = f"""
        print(json.dumps(run_tasks(os.getenv, ["{HEAD_MARK}"], jobs=2, ray="")))
        try:
            run_tasks(ip_address, ["10.0.0.1", "x"], ray="")
        except TaskError as error:
            print(json.dumps([isinstance(error, ValueError), str(error)]))
        """
    done = _driver({**environ, "RAY_ADDRESS": address}, code)
    assert done.returncode == 0, done.stderr[-2000:]
    joined, failed = done.stdout.splitlines()[-2:]
    assert json.loads(joined) == ["yes"]
    is_value_error, message = json.loads(failed)
    assert not is_value_error
    assert "task 2 of 2" in message and "ray::" not in message
    assert message.endswith("ValueError: 'x' does not appear to be an IPv4 or IPv6 address")


def test_a_crashed_ray_worker_is_a_task_error_and_the_other_tasks_are_cancelled(
    head: tuple[str, dict[str, str]],
) -> None:
    address, environ = head
    code = f"""
        def task(n):
            if n == 2:
                os._exit(1)  # the worker process dies: WorkerCrashedError, not RayTaskError
            return n
        try:
            run_tasks(task, [1, 2, 3], ray={address!r})
        except TaskError as error:
            print(json.dumps([type(error.__cause__).__name__, str(error)]))
        # The driver can sweep again on the same cluster after it.
        print(json.dumps(run_tasks(os.getenv, ["{HEAD_MARK}"], ray={address!r})))
        """
    done = _driver(environ, code)
    assert done.returncode == 0, done.stderr[-2000:]
    failed, again = done.stdout.splitlines()[-2:]
    cause, message = json.loads(failed)
    assert cause == "WorkerCrashedError"
    assert message.startswith("task 2 of 3 2 failed: WorkerCrashedError: ")
    assert "\n" not in message
    assert json.loads(again) == ["yes"]
