"""Sweeps on Ray by Ray's conventions (issue 36): which ``ray.init`` arguments for which
``--ray`` and environment, joining a ``ray start --head`` cluster that uses token
authentication, ``RAY_ADDRESS``, the run's ``MRSLAM_*`` variables on the workers, and a
worker's failure reported by its own error line (exit 1, not 2).

One real head (``ray start --head --block``, its own temp dir and home, so that it never
meets another test's local instance) serves the module; each driver runs in a subprocess,
so that Ray's per-process authentication state never leaks into the test process."""

from __future__ import annotations

import ipaddress
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

from scenarios.cli import main
from scenarios.sweep import TaskError, ray_env_vars, ray_init_arguments, run_tasks

ROOT = Path(__file__).resolve().parents[1]
RAY = Path(sys.executable).with_name("ray")
HEAD_MARK = "SWEEP_TEST_HEAD"
"""Set in the head's environment only: a task that sees it ran on that cluster."""


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
    assert "ValueError: (0, 'office', 0, 5, None, 2, 'team') does not appear to be" in error


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
    process = subprocess.Popen(
        command,
        env={**environ, HEAD_MARK: "yes"},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,  # its own process group: stopped with it, nothing else
    )
    try:
        assert process.stdout is not None
        lines = []
        for line in process.stdout:
            lines.append(line)
            found = re.search(r"ray start --address='([^']+)'", line)
            if found:
                break
        else:
            pytest.fail("ray start --head printed no address:\n" + "".join(lines))
        assert "Token authentication is enabled" in "".join(lines)
        yield found.group(1), environ
    finally:
        os.killpg(process.pid, signal.SIGKILL)  # this head's processes only
        process.wait()
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
    )


def test_joining_a_token_head_by_its_printed_address_passes_the_mrslam_variables(
    head: tuple[str, dict[str, str]],
) -> None:
    address, environ = head
    code = f"""
        names = ["{HEAD_MARK}", "MRSLAM_SB3_MODEL", "MRSLAM_UNSET"]
        print(json.dumps(run_tasks(os.getenv, names, ray={address!r})))
        """
    done = _driver({**environ, "MRSLAM_SB3_MODEL": "/models/ppo.zip"}, code)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.splitlines()[-1]) == ["yes", "/models/ppo.zip", None]


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
