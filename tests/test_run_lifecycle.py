"""A run's life from claiming its folder to its last output (issue 36): runs started
together never share a folder, ``--overwrite`` never deletes an input, a signal at any
moment ends the run with its report marked, and a world too large is refused up front."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.mapio import save_map
from scenarios import experiment, interrupts, run_folder
from scenarios.cli import main
from scenarios.run_folder import prepare_run_dir, release_run_dir

ROOT = Path(__file__).resolve().parents[1]
DEADLINE_S = 240.0
"""Bound on any wait for a subprocess's folder or exit (a failure, not a timing)."""


def mrslam() -> str:
    beside = Path(sys.executable).parent / "mrslam"
    found = str(beside) if beside.exists() else shutil.which("mrslam")
    assert found is not None
    return found


def small_map(folder: Path, name: str = "world") -> Path:
    """A 6 x 4 m room with a wall stub, at 0.05 m, saved as ``folder/name.yaml``."""
    cells = np.full((80, 120), FREE, dtype=np.int8)
    cells[:2], cells[-2:], cells[:, :2], cells[:, -2:] = OCCUPIED, OCCUPIED, OCCUPIED, OCCUPIED
    cells[:50, 60:62] = OCCUPIED
    folder.mkdir(parents=True, exist_ok=True)
    return save_map(folder / f"{name}.yaml", GridMap(cells=cells, resolution=0.05))


# --- 1, 2: claiming the run folder ---------------------------------------------------------


def test_an_existing_folder_even_empty_is_not_claimed(tmp_path: Path) -> None:
    first = prepare_run_dir(tmp_path, "a")
    assert first == tmp_path / "a"
    (tmp_path / "b").mkdir()  # empty, but someone made it: not ours
    assert prepare_run_dir(tmp_path, "b") == tmp_path / "b-2"
    release_run_dir(first)
    assert prepare_run_dir(tmp_path, "a") == tmp_path / "a-2"


def _race(n: int, claim: Callable[[], Path]) -> list[Path | BaseException]:
    barrier = threading.Barrier(n)

    def one(_: int) -> Path | BaseException:
        barrier.wait()
        try:
            return claim()
        except ValueError as error:
            return error

    with ThreadPoolExecutor(n) as pool:
        return list(pool.map(one, range(n)))


def test_runs_racing_for_a_name_each_claim_a_folder_of_their_own(tmp_path: Path) -> None:
    claimed = _race(8, lambda: prepare_run_dir(tmp_path, "a"))
    assert all(isinstance(c, Path) for c in claimed), claimed
    assert len(set(claimed)) == 8
    assert {p.name for p in claimed if isinstance(p, Path)} == {"a"} | {
        f"a-{i}" for i in range(2, 9)
    }


def test_overwrite_runs_racing_for_one_folder_only_one_holds_it(tmp_path: Path) -> None:
    folder = tmp_path / "a"
    folder.mkdir()
    (folder / "report.json").write_text("{}")
    claimed = _race(6, lambda: prepare_run_dir(tmp_path, "a", overwrite=True))
    held = [c for c in claimed if isinstance(c, Path)]
    refused = [c for c in claimed if isinstance(c, ValueError)]
    assert held == [folder] and len(refused) == 5, claimed
    assert all("held by another run" in str(error) for error in refused)
    # A folder a run holds is not taken by --overwrite until the run lets it go.
    with pytest.raises(ValueError, match="held by another run"):
        prepare_run_dir(tmp_path, "a", overwrite=True)
    release_run_dir(folder)
    assert prepare_run_dir(tmp_path, "a", overwrite=True) == folder


def test_runs_started_together_keep_a_folder_and_a_report_each(tmp_path: Path) -> None:
    # Two recording runs and a --no-comm one under the same --name, all started at once.
    base = [mrslam(), "run", "--out", str(tmp_path), "--name", "x", "--max-steps", "5"]
    variants = [["--json"], ["--json"], ["--no-record", "--no-comm", "--json"]]
    runs = [
        subprocess.Popen([*base, *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for extra in variants
    ]
    done = [run.communicate(timeout=DEADLINE_S) for run in runs]
    for run, (_, err) in zip(runs, done, strict=True):
        assert run.returncode == 0, err
    reports = [json.loads(out) for out, _ in done]
    folders = [Path(report["outputs"]["run_dir"]) for report in reports]
    assert sorted(f.name for f in folders) == ["x", "x-2", "x-3"]
    for report, folder, extra in zip(reports, folders, variants, strict=True):
        assert json.loads((folder / "report.json").read_text()) == report
        assert report["comm"] is ("--no-comm" not in extra)
        assert (folder / "recording.rrd").exists() is ("--no-record" not in extra)
        assert not [p.name for p in folder.iterdir() if p.name.startswith(".")]


def test_the_partial_recording_is_named_for_its_process(tmp_path: Path) -> None:
    assert str(os.getpid()) in run_folder.partial_recording(tmp_path).name


# --- 3: --overwrite never deletes an input ---------------------------------------------------


@pytest.mark.parametrize("how", ["image-in-run-folder", "image-linked-into-it", "yaml-linked"])
def test_overwrite_refuses_when_an_input_file_lies_in_the_run_folder(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, how: str
) -> None:
    folder = tmp_path / "out" / "x"
    earlier = small_map(folder, "merged")  # an earlier run's merged map
    elsewhere = tmp_path / "in"
    elsewhere.mkdir()
    if how == "image-in-run-folder":
        yaml_path = elsewhere / "world.yaml"
        text = earlier.read_text().replace("image: merged.pgm", f"image: {folder / 'merged.pgm'}")
        yaml_path.write_text(text)
    elif how == "image-linked-into-it":
        (elsewhere / "merged.pgm").symlink_to(folder / "merged.pgm")
        yaml_path = elsewhere / "world.yaml"
        yaml_path.write_text(earlier.read_text())
    else:  # the YAML a link to one in the run folder (not an output's name)
        inside = folder / "world.yaml"
        inside.write_text(earlier.read_text())
        yaml_path = elsewhere / "world.yaml"
        yaml_path.symlink_to(inside)
        (elsewhere / "merged.pgm").symlink_to(folder / "merged.pgm")
    assert "merged.pgm" in yaml_path.read_text()
    argv = ["run", "--map", str(yaml_path), "--out", str(tmp_path / "out"), "--name", "x"]
    status = main([*argv, "--overwrite", "--max-steps", "5", "--no-record"])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith("mrslam: error: ") and err.count("\n") == 1, err
    assert "input" in err
    assert (folder / "merged.pgm").exists() and (folder / "merged.yaml").exists()


def test_overwrite_keeps_an_input_it_would_not_delete(tmp_path: Path) -> None:
    # The map's own files in the run folder are read and never touched: only an input
    # under an output's name (which --overwrite deletes) is refused.
    folder = tmp_path / "x"
    world = small_map(folder, "world")
    inputs = run_folder.input_files(world)
    (folder / "report.json").write_text("{}")  # the earlier run's
    assert prepare_run_dir(tmp_path, "x", overwrite=True, inputs=inputs) == folder
    release_run_dir(folder)
    assert sorted(p.name for p in folder.iterdir()) == ["world.pgm", "world.yaml"]
    earlier = small_map(folder, "robot_0")  # an earlier run's map, read as the input
    with pytest.raises(ValueError, match=r"would delete the input map file .*robot_0"):
        prepare_run_dir(tmp_path, "x", overwrite=True, inputs=run_folder.input_files(earlier))
    assert earlier.exists() and not (folder / run_folder.RUN_MARKER).exists()


def test_a_failed_overwrite_lets_go_of_the_folder(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # An output's name taken by a folder: deleting it fails after the marker was made.
    folder = tmp_path / "x"
    (folder / "report.json").mkdir(parents=True)
    argv = ["run", "--out", str(tmp_path), "--name", "x", "--overwrite", "--max-steps", "1"]
    assert main([*argv, "--no-record"]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (folder / run_folder.RUN_MARKER).exists()
    (folder / "report.json").rmdir()
    assert prepare_run_dir(tmp_path, "x", overwrite=True) == folder  # not "held"
    release_run_dir(folder)


def test_a_marker_that_cannot_be_written_is_not_left(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    def full(*args: Any, **kwargs: Any) -> Any:
        raise OSError(28, "No space left on device")

    (tmp_path / "x").mkdir()
    with monkeypatch.context() as patch:
        patch.setattr(run_folder.os, "fdopen", full)
        with pytest.raises(OSError, match="No space"):
            prepare_run_dir(tmp_path, "x", overwrite=True)
    assert not (tmp_path / "x" / run_folder.RUN_MARKER).exists()


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait(timeout=DEADLINE_S)
    return child.pid


def test_a_stale_marker_of_a_dead_run_is_replaced(tmp_path: Path) -> None:
    import socket

    folder = tmp_path / "x"
    folder.mkdir()
    marker = folder / run_folder.RUN_MARKER
    marker.write_text(f"pid {_dead_pid()} on {socket.gethostname()}\n")  # killed by SIGKILL
    assert prepare_run_dir(tmp_path, "x", overwrite=True) == folder
    assert marker.read_text() == f"pid {os.getpid()} on {socket.gethostname()}\n"
    assert [p.name for p in folder.iterdir()] == [run_folder.RUN_MARKER]  # nothing aside
    release_run_dir(folder)
    # A live process on this host, or any on another host, still holds the folder.
    host = socket.gethostname()
    for holder in (f"pid {os.getppid()} on {host}", f"pid {_dead_pid()} on not-{host}"):
        marker.write_text(holder + "\n")
        with pytest.raises(ValueError, match="held by another run"):
            prepare_run_dir(tmp_path, "x", overwrite=True)
        assert marker.read_text() == holder + "\n"


def test_runs_racing_for_a_stale_folder_only_one_holds_it(tmp_path: Path) -> None:
    import socket

    folder = tmp_path / "a"
    folder.mkdir()
    (folder / run_folder.RUN_MARKER).write_text(f"pid {_dead_pid()} on {socket.gethostname()}\n")
    claimed = _race(6, lambda: prepare_run_dir(tmp_path, "a", overwrite=True))
    held = [c for c in claimed if isinstance(c, Path)]
    assert held == [folder], claimed
    assert [p.name for p in folder.iterdir()] == [run_folder.RUN_MARKER]


# --- 4: signals --------------------------------------------------------------------------


def _with_python_handlers() -> dict[int, Any]:
    """Python's own Ctrl-C handler, as in a console script (a test runner's worker may have
    replaced it); returns the handlers to put back."""
    signums = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous: dict[int, Any] = {s: signal.getsignal(s) for s in signums}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    return previous


def _run_main(argv: list[str]) -> int:
    previous = _with_python_handlers()
    try:
        return main(argv)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _kill_self_when(monkeypatch: pytest.MonkeyPatch, owner: Any, attribute: str, signum: int):
    """Make ``owner.attribute`` (a function) send ``signum`` to this process on its first
    call, then do its work."""
    original = getattr(owner, attribute)
    calls = {"n": 0}

    def wrapped(*args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 1:
            os.kill(os.getpid(), signum)
        return original(*args, **kwargs)

    monkeypatch.setattr(owner, attribute, wrapped)
    return calls


def test_a_signal_inside_a_step_lets_the_step_finish(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from agents.team import TeamCoordinator

    act = TeamCoordinator.act
    calls = {"n": 0}

    def counting(self: TeamCoordinator, *args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 11:
            os.kill(os.getpid(), signal.SIGINT)  # the handler must not raise in here
        return act(self, *args, **kwargs)

    monkeypatch.setattr(TeamCoordinator, "act", counting)
    status = _run_main(["run", "--max-steps", "100", "--no-record", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 130
    assert "interrupted by SIGINT after 11 steps" in err and err.count("\n") == 1, err
    report = json.loads((tmp_path / "office-seed0" / "report.json").read_text())
    assert report["complete"] is False and report["interrupted"] == "SIGINT"
    assert report["steps"] == 11


def test_a_signal_before_the_loop_still_leaves_a_marked_report(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # SIGTERM while the recording is set up: the run folder exists, no step was taken.
    _kill_self_when(monkeypatch, experiment, "Recorder", signal.SIGTERM)
    status = _run_main(["run", "--max-steps", "100", "--out", str(tmp_path), "--name", "r"])
    err = capsys.readouterr().err
    assert status == 143 and err.count("\n") == 1, err
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["complete"] is False and report["interrupted"] == "SIGTERM"
    assert report["steps"] == 0
    assert (tmp_path / "r" / "recording.rrd").exists()
    assert not [p.name for p in (tmp_path / "r").iterdir() if p.name.startswith(".")]


def test_a_signal_before_the_run_folder_is_claimed_leaves_nothing(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # SIGINT while the team is built (after the env and its kernels): no folder yet,
    # nothing written.
    _kill_self_when(monkeypatch, experiment, "build_team", signal.SIGINT)
    status = _run_main(["run", "--max-steps", "100", "--no-record", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 130
    assert err.startswith("mrslam: interrupted by SIGINT") and err.count("\n") == 1, err
    assert not tmp_path.exists() or not list(tmp_path.iterdir())


def test_a_signal_while_the_outputs_are_written_is_not_lost(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    calls = _kill_self_when(monkeypatch, experiment, "save_map", signal.SIGTERM)
    argv = ["run", "--max-steps", "10", "--no-record", "--out", str(tmp_path), "--name", "r"]
    status = _run_main(argv)
    err = capsys.readouterr().err
    assert calls["n"] >= 2, "the outputs were written whole after the signal"
    assert status == 143 and err.count("\n") == 1, err
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["complete"] is False and report["interrupted"] == "SIGTERM"
    assert report["steps"] == 10  # every step was done; the signal came after
    for name in ("robot_0.yaml", "robot_1.yaml", "figure.png"):
        assert (tmp_path / "r" / name).exists()


def _signal_when_the_folder_appears(
    tmp_path: Path, signum: int, extra: list[str], env: dict[str, str] | None = None
) -> tuple[int, str, str, Path]:
    folder = tmp_path / "out" / "r"
    argv = [mrslam(), "run", "--out", str(tmp_path / "out"), "--name", "r", "--json", *extra]
    run = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT
    )
    deadline = time.monotonic() + DEADLINE_S
    while not folder.exists():  # poll, bounded: the folder is the moment under test
        assert run.poll() is None, run.communicate()
        assert time.monotonic() < deadline, "the run folder never appeared"
        time.sleep(0.005)
    run.send_signal(signum)
    out, err = run.communicate(timeout=DEADLINE_S)
    return run.returncode, out, err, folder


def test_sigint_as_the_folder_appears_while_kernels_compile(tmp_path: Path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    status, out, err, folder = _signal_when_the_folder_appears(
        tmp_path, signal.SIGINT, ["--max-steps", "300", "--no-record"], env
    )
    assert status == 130, err
    # The first line says the kernels compile (a fresh cache); then the one line.
    notice, _, err = err.partition("\n")
    assert notice.startswith("mrslam: compiling the numba kernels"), notice
    assert err.count("\n") == 1 and err.startswith("mrslam: interrupted by SIGINT"), err
    report = json.loads((folder / "report.json").read_text())
    assert report == json.loads(out)
    assert report["complete"] is False and report["interrupted"] == "SIGINT"
    assert report["steps"] < 300


def test_sigterm_mid_run_with_recording(tmp_path: Path) -> None:
    status, _, err, folder = _signal_when_the_folder_appears(
        tmp_path, signal.SIGTERM, ["--max-steps", "3000"]
    )
    assert status == 143, err
    assert err.count("\n") == 1 and err.startswith("mrslam: interrupted by SIGTERM"), err
    report = json.loads((folder / "report.json").read_text())
    assert report["complete"] is False and report["interrupted"] == "SIGTERM"
    assert report["steps"] < 3000
    assert (folder / "recording.rrd").exists()
    assert not [p.name for p in folder.iterdir() if p.name.startswith(".")]


def test_sigint_while_the_command_is_imported_is_one_line(tmp_path: Path) -> None:
    # The console script notes a signal from its first import: a Ctrl-C while the heavy
    # modules load ends the command with one line, never a traceback.
    code = (
        "import os, signal, sys\n"
        "sys.argv = ['mrslam', 'run', '--out', sys.argv[1], '--max-steps', '5']\n"
        "import scenarios.cli as cli\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "import scenarios.experiment\n"
        "sys.exit(cli.main(sys.argv[1:]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "out")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=DEADLINE_S,
    )
    assert done.returncode == 130, done.stderr
    # With a cold numba cache the compile notice comes first (cli.kernels_compiled).
    err = done.stderr.removeprefix(
        "mrslam: compiling the numba kernels once (about 40 s more)...\n"
    )
    assert err.startswith("mrslam: interrupted by SIGINT"), done.stderr
    assert err.count("\n") == 1 and "Traceback" not in done.stderr
    assert not (tmp_path / "out").exists()


def test_sighup_ends_a_run_as_sigterm_does(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # The terminal or the ssh session closed: the run ends with its report marked, exit 129.
    _kill_self_when(monkeypatch, experiment, "Recorder", signal.SIGHUP)
    status = _run_main(["run", "--max-steps", "100", "--out", str(tmp_path), "--name", "r"])
    err = capsys.readouterr().err
    assert status == 129 and "mrslam: interrupted by SIGHUP after 0 steps" in err, err
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["complete"] is False and report["interrupted"] == "SIGHUP"


def test_a_signal_note_ends_with_the_block_that_installed_the_handlers(
    capsys: pytest.CaptureFixture[str],
) -> None:
    previous = _with_python_handlers()
    try:
        with interrupts.noting_signals():
            os.kill(os.getpid(), signal.SIGTERM)
            assert interrupts.received() == "SIGTERM"
            # main() called from a program checks no note it did not make itself.
            assert main(["scenarios"]) == 0
            assert interrupts.received() == "SIGTERM"  # still the block's
        assert interrupts.received() is None
        assert main(["scenarios"]) == 0  # a later command in the process is not ended
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    assert "interrupted" not in capsys.readouterr().err


def test_a_run_in_a_worker_thread_after_a_noted_signal_runs(tmp_path: Path) -> None:
    previous = _with_python_handlers()
    try:
        with interrupts.noting_signals():
            os.kill(os.getpid(), signal.SIGTERM)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    config = experiment.RunConfig(
        scenario="maze", out=tmp_path, name="r", max_steps=1, record=False, figure=False
    )
    with ThreadPoolExecutor(1) as pool:
        report = pool.submit(experiment.run_experiment, config).result(timeout=DEADLINE_S)
    assert report["complete"] is True and report["steps"] == 1


def test_a_signal_noted_as_the_block_fails_is_not_lost() -> None:
    # redeliver: the noted signal is sent again also when the block ends by an exception.
    previous = _with_python_handlers()
    calls: list[int] = []
    try:
        signal.signal(signal.SIGTERM, lambda signum, frame: calls.append(signum))
        # The caller's handler is called and returns: the error goes on.
        with pytest.raises(OSError, match="disk full"), interrupts.noting_signals(redeliver=True):
            os.kill(os.getpid(), signal.SIGTERM)
            raise OSError("disk full")
        assert calls == [signal.SIGTERM]
        # Python's own Ctrl-C handler: its KeyboardInterrupt replaces the error.
        with pytest.raises(KeyboardInterrupt) as stop, interrupts.noting_signals(redeliver=True):
            os.kill(os.getpid(), signal.SIGINT)
            raise OSError("disk full")
        assert isinstance(stop.value.__context__, OSError)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def test_a_handler_installed_from_c_is_put_back_as_the_default(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    previous = _with_python_handlers()
    try:
        with monkeypatch.context() as patch:  # what signal.getsignal gives for a C handler
            patch.setattr(signal, "getsignal", lambda signum: None)
            assert interrupts.install()
        interrupts.restore()
        assert signal.getsignal(signal.SIGINT) is signal.SIG_DFL
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    finally:
        interrupts.restore()
        for s, handler in previous.items():
            signal.signal(s, handler)


def test_the_console_scripts_note_ends_with_its_command() -> None:
    # A signal while the modules load ends a command other than run at once, by the
    # signal itself (one line, nothing after it). An empty sys.argv installs nothing (and
    # does not fail).
    code = (
        "import os, signal, sys\n"
        "sys.argv = ['mrslam', 'scenarios']\n"
        "import scenarios.cli as cli\n"
        "os.kill(os.getpid(), signal.SIGTERM)\n"
        "first = cli.main(['scenarios'])\n"
        "print(first, file=sys.stderr)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=DEADLINE_S
    )
    assert done.returncode == -signal.SIGTERM, done.stderr
    assert done.stderr == "mrslam: interrupted by SIGTERM\n"
    code = (
        "import signal, sys\n"
        "sys.argv = []\n"
        "import scenarios.cli\n"
        "assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=DEADLINE_S
    )
    assert done.returncode == 0, done.stderr


# --- 5: a world too large is refused before anything is allocated ----------------------------


def test_a_map_whose_world_is_too_large_is_refused_up_front(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # 300 x 200 pixels at 3 m/px: a 900 x 600 m world, 18,000 x 12,000 cells at 0.05 m.
    cells = np.full((200, 300), FREE, dtype=np.int8)
    cells[:2], cells[-2:], cells[:, :2], cells[:, -2:] = OCCUPIED, OCCUPIED, OCCUPIED, OCCUPIED
    yaml_path = save_map(tmp_path / "huge.yaml", GridMap(cells=cells, resolution=3.0))

    def never(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("the world of a map too large was built")

    monkeypatch.setattr(experiment, "world_from_map", never)  # refused before it is built
    with pytest.raises(ValueError, match="25,000,000"):
        experiment.resolve_world("office", yaml_path)
    status = main(["run", "--map", str(yaml_path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert err.startswith("mrslam: error: ")
    assert "25,000,000" in err and "cells" in err and "0.05 m" in err
    assert not (tmp_path / "out").exists()


def test_the_size_limit_leaves_room_for_a_large_real_building() -> None:
    from mrslam_env.sim.mapworld import MAX_WORLD_CELLS, check_world_extent

    check_world_extent((0.0, 0.0, 80.0, 60.0), 0.05)  # a large floor: 1.92 M cells
    assert MAX_WORLD_CELLS >= 10 * (80 / 0.05) * (60 / 0.05)
    check_world_extent((-125.0, -100.0, 125.0, 100.0), 0.05)  # 20 M cells: still run
    with pytest.raises(ValueError, match=r"world of 300 x 300 m .* 36,000,000 cells"):
        check_world_extent((0.0, 0.0, 300.0, 300.0), 0.05)


def test_a_python_callers_ctrl_c_reaches_it_after_the_run(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # run_experiment from Python (no CLI): the run ends with its report marked, then the
    # caller gets its KeyboardInterrupt (a loop of runs stops, as before).
    _kill_self_when(monkeypatch, experiment, "save_map", signal.SIGINT)
    config = experiment.RunConfig(
        out=tmp_path, name="r", max_steps=5, record=False, figure=False, progress=False
    )
    previous = _with_python_handlers()
    try:
        with pytest.raises(KeyboardInterrupt):
            experiment.run_experiment(config)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["complete"] is False and report["interrupted"] == "SIGINT"
    assert report["steps"] == 5
