"""A signal ends a command other than ``mrslam run`` at once, by the signal itself
(scenarios/interrupts.py): one line on stderr, no traceback, no exception raised inside C
code; ``main()`` called from Python installs no such handler."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scenarios import cli, interrupts

ROOT = Path(__file__).resolve().parents[1]
DEADLINE_S = 60.0


def _console_script() -> str:
    """The installed ``mrslam`` console script (argv[0]'s name is what makes the process
    the console script)."""
    beside = Path(sys.executable).parent / "mrslam"
    found = str(beside) if beside.exists() else shutil.which("mrslam")
    if found is None:
        pytest.skip("the mrslam console script is not installed")
    return found


def _has_loaded(pid: int, library: str) -> bool:
    try:
        return library in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_ends_bench_sim_by_the_signal_in_one_line(signum: int) -> None:
    proc = subprocess.Popen(
        [_console_script(), "bench", "sim", "--steps", "100000", "--no-irsim", "--repeats", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        # Running: the simulator's C library (pymunk's chipmunk) is loaded.
        deadline = time.monotonic() + DEADLINE_S
        while not _has_loaded(proc.pid, "_chipmunk"):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "bench sim never loaded the simulator"
            time.sleep(0.02)
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=DEADLINE_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    name = signal.Signals(signum).name
    assert proc.returncode == -signum, (proc.returncode, err)
    assert err == f"mrslam: interrupted by {name}\n", err
    assert out == ""


def test_main_from_python_leaves_the_sigint_handler_as_it_found_it(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Even where the console script's flag would apply (argv[0] "mrslam"), main() called
    # from a program that did not start as the console script installs nothing.
    monkeypatch.setattr(sys, "argv", ["mrslam", "scenarios"])
    seen: list[object] = []

    def scenarios(args: object) -> int:
        seen.append(signal.getsignal(signal.SIGINT))
        os.kill(os.getpid(), signal.SIGINT)
        return 0

    def mine(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_cmd_scenarios", scenarios)
    previous = signal.signal(signal.SIGINT, mine)
    try:
        status = cli.main(["scenarios"])
        assert signal.getsignal(signal.SIGINT) is mine
    finally:
        signal.signal(signal.SIGINT, previous)
    assert seen == [mine]
    assert status == cli.EXIT_INTERRUPTED
    assert capsys.readouterr().err == "mrslam: interrupted by SIGINT\n"
    assert interrupts.received() is None


def _children(pid: int) -> list[int]:
    """The live child processes of ``pid`` (from /proc)."""
    found = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            fields = dict(
                line.split(":\t", 1) for line in status.read_text().splitlines() if ":\t" in line
            )
        except OSError:
            continue
        if fields.get("PPid", "").strip() == str(pid) and not fields["State"].startswith("Z"):
            found.append(int(status.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\nState:\tZ" not in state


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
def test_an_interrupted_sweep_leaves_no_worker_behind(tmp_path: Path) -> None:
    # bench explore runs its runs in spawned pool workers: ended at once by the signal,
    # the parent must take them with it (they would wait forever on a parent that is gone,
    # holding the caller's stdout and stderr open).
    command = [_console_script(), "bench", "explore", "--seeds", "1", "--max-steps", "3000"]
    command += ["--scenarios", "office", "--modes", "team", "--out", str(tmp_path / "bx")]
    with open(tmp_path / "err.txt", "w") as err:
        proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=err, cwd=tmp_path)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + DEADLINE_S
        while not workers:
            assert proc.poll() is None, (tmp_path / "err.txt").read_text()
            assert time.monotonic() < deadline, "bench explore never started a worker"
            workers = [p for p in _children(proc.pid) if _has_loaded(p, "numpy")]
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=DEADLINE_S) == -signal.SIGINT
        deadline = time.monotonic() + DEADLINE_S
        while any(_alive(p) for p in workers):
            assert time.monotonic() < deadline, "the sweep's workers outlived it"
            time.sleep(0.05)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid in workers:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
    # Then multiprocessing's resource tracker may warn that it cleans up the pool's
    # semaphores: its own lines, after ours, never a traceback.
    err = (tmp_path / "err.txt").read_text()
    assert err.startswith("mrslam: interrupted by SIGINT\n") and "Traceback" not in err, err
