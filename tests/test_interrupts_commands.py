"""A signal ends a command other than ``mrslam run`` at once, by the signal itself
(scenarios/interrupts.py): one line on stderr, no traceback, no exception raised inside C
code; ``main()`` called from Python installs no such handler."""

from __future__ import annotations

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
