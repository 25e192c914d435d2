"""`mrslam run`'s outputs: a used run folder is never mixed, interrupted runs keep what was
done (report marked incomplete, recording closed), every file is written atomically."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
from test_recording import Recording

from agents.team import TeamCoordinator
from scenarios.cli import main
from scenarios.experiment import RunConfig, run_experiment
from scenarios.run_folder import OUTPUT_FILES, prepare_run_dir, release_run_dir


def test_a_new_folder_is_used_as_named_an_existing_one_never(tmp_path: Path) -> None:
    assert prepare_run_dir(tmp_path, "a") == tmp_path / "a"
    assert prepare_run_dir(tmp_path, "a") == tmp_path / "a-2"  # even while still empty


def test_a_used_folder_is_never_mixed_the_run_goes_to_the_next_number(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "report.json").write_text("{}")
    assert prepare_run_dir(tmp_path, "a") == tmp_path / "a-2"
    (tmp_path / "a-2" / "report.json").write_text("{}")
    assert prepare_run_dir(tmp_path, "a") == tmp_path / "a-3"
    assert (tmp_path / "a" / "report.json").read_text() == "{}"


def test_overwrite_deletes_the_earlier_outputs_and_nothing_else(tmp_path: Path) -> None:
    folder = tmp_path / "a"
    folder.mkdir()
    for name in [*OUTPUT_FILES, "robot_0.yaml", "robot_0.pgm", "robot_1.yaml", "notes.txt"]:
        (folder / name).write_text("old")
    assert prepare_run_dir(tmp_path, "a", overwrite=True) == folder
    release_run_dir(folder)
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt"]


def test_a_file_in_the_way_is_refused(tmp_path: Path) -> None:
    (tmp_path / "a").write_text("x")
    with pytest.raises(ValueError, match="exists and is a file"):
        prepare_run_dir(tmp_path, "a")


def test_rerunning_with_the_same_seed_keeps_the_earlier_run(capsys, tmp_path: Path) -> None:
    argv = ["run", "--max-steps", "20", "--no-record", "--out", str(tmp_path), "--json"]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out)
    assert main([*argv[:-1], "--no-comm", "--json"]) == 0
    second = json.loads(capsys.readouterr().out)
    assert Path(first["outputs"]["run_dir"]) == tmp_path / "office-seed0"
    assert Path(second["outputs"]["run_dir"]) == tmp_path / "office-seed0-2"
    kept = json.loads((tmp_path / "office-seed0" / "report.json").read_text())
    assert kept["comm"] is True and kept["complete"] is True
    assert not list(tmp_path.glob("*/.*part*")), "a temporary file was left behind"


def interrupt_at(monkeypatch: pytest.MonkeyPatch, step: int, raise_it) -> None:
    """Make the team's act() call ``raise_it`` at the given step."""
    act = TeamCoordinator.act
    calls = {"n": 0}

    def counting(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == step:
            raise_it()
        return act(self, *args, **kwargs)

    monkeypatch.setattr(TeamCoordinator, "act", counting)


def test_ctrl_c_keeps_the_steps_done_and_closes_the_recording(monkeypatch, tmp_path: Path) -> None:
    def ctrl_c() -> None:
        raise KeyboardInterrupt

    interrupt_at(monkeypatch, 16, ctrl_c)
    report = run_experiment(RunConfig(out=tmp_path, name="r", max_steps=200, progress=False))
    assert report["complete"] is False and report["interrupted"] == "SIGINT"
    assert report["steps"] == 15
    saved = json.loads((tmp_path / "r" / "report.json").read_text())
    assert saved["complete"] is False and saved["steps"] == 15
    recording = Recording(tmp_path / "r" / "recording.rrd")  # a closed, readable file
    events = " ".join(str(v) for v in recording.column("/events", "TextLog:text"))
    assert "interrupted (SIGINT) after 15 steps" in events
    assert not list((tmp_path / "r").glob(".*"))  # no partial recording, no run marker
    assert (tmp_path / "r" / "robot_0.yaml").exists() and (tmp_path / "r" / "figure.png").exists()


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_ends_the_run_in_one_line_with_its_exit_status(
    capsys, monkeypatch, tmp_path: Path, signum: int, status: int
) -> None:
    interrupt_at(monkeypatch, 11, lambda: os.kill(os.getpid(), signum))
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    # Python's own Ctrl-C handler, as in a console script (a test runner's worker may
    # have replaced it).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        code = main(["run", "--max-steps", "100", "--no-record", "--out", str(tmp_path)])
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    err = capsys.readouterr().err
    assert code == status
    name = signal.Signals(signum).name
    # The handler only notes the signal: the step it came in is finished, then the run stops.
    assert f"interrupted by {name} after 11 steps" in err and err.count("\n") == 1, err
    report = json.loads((tmp_path / "office-seed0" / "report.json").read_text())
    assert report["complete"] is False and report["interrupted"] == name


def test_overwrite_keeps_files_that_only_look_like_robot_maps(tmp_path: Path) -> None:
    folder = tmp_path / "a"
    folder.mkdir()
    for name in ["robot_0.yaml", "robot_12.pgm", "robot_0.yaml.bak", "robot_notes.pam"]:
        (folder / name).write_text("old")
    release_run_dir(prepare_run_dir(tmp_path, "a", overwrite=True))
    assert sorted(p.name for p in folder.iterdir()) == ["robot_0.yaml.bak", "robot_notes.pam"]


def test_a_crash_closes_the_recording_and_leaves_no_partial_file(monkeypatch, tmp_path) -> None:
    def crash() -> None:
        raise RuntimeError("boom")

    interrupt_at(monkeypatch, 6, crash)
    with pytest.raises(RuntimeError, match="boom"):
        run_experiment(RunConfig(out=tmp_path, name="r", max_steps=50, progress=False))
    assert not list((tmp_path / "r").glob(".*"))  # no partial recording, no run marker


def test_overwrite_refuses_to_delete_the_input_map(capsys, tmp_path: Path) -> None:
    from mrslam_env.mapio import save_map
    from mrslam_env.registry import build_world
    from mrslam_env.sim.world import ground_truth_map

    folder = tmp_path / "x"
    folder.mkdir()
    save_map(folder / "robot_0.yaml", ground_truth_map(build_world("maze"), 0.1, margin=0.5))
    argv = ["run", "--map", str(folder / "robot_0.yaml"), "--out", str(tmp_path), "--name", "x"]
    assert main([*argv, "--overwrite", "--max-steps", "5", "--no-record"]) == 2
    assert "would delete the input map" in capsys.readouterr().err
    assert (folder / "robot_0.yaml").exists()
