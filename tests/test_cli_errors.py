"""Every CLI path fails with one line and the documented exit status, and never destroys or
mixes outputs (the reliability issue's cases, each reproduced)."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mrslam_env.mapio import load_map
from scenarios import cli
from scenarios.cli import main


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> tuple[int, str, str]:
    """``main`` as the console script runs it: argparse's usage errors exit through
    SystemExit, the rest return a status."""
    try:
        status = main([str(a) for a in argv])
    except SystemExit as exit_:
        status = int(exit_.code or 0)
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def digest(folder: Path) -> dict[str, str]:
    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.iterdir())
        if p.is_file()
    }


def assert_one_line(err: str, status: int, expected: int = 2) -> None:
    assert status == expected, err
    assert err.count("\n") == 1 and err.startswith("mrslam"), err
    assert "Traceback" not in err


@pytest.mark.parametrize("output", ["a.yaml", "a.pgm", "./sub/../a.yaml", "b.pgm", "b"])
def test_an_output_that_is_an_input_is_refused_before_any_work(
    capsys, maps: Path, monkeypatch, output: str
) -> None:
    (maps / "sub").mkdir()
    before = digest(maps)
    monkeypatch.chdir(maps)
    status, out, err = run_cli(capsys, "merge", "a.yaml", "b.yaml", "-o", output)
    assert_one_line(err, status)
    assert "would overwrite an input file" in err and out == ""
    assert digest(maps) == before


def test_an_output_through_a_link_to_an_input_is_refused(capsys, maps: Path) -> None:
    (maps / "link.yaml").symlink_to(maps / "a.yaml")
    status, _, err = run_cli(
        capsys, "merge", maps / "a.yaml", maps / "b.yaml", "-o", maps / "link.yaml"
    )
    assert_one_line(err, status)
    assert "would overwrite an input file" in err


@pytest.mark.parametrize("output", ["merged.pgm", "merged", "merged.yaml"])
def test_any_output_name_writes_the_yaml_and_pgm_pair(capsys, maps: Path, output: str) -> None:
    status, out, err = run_cli(
        capsys, "merge", maps / "a.yaml", maps / "b.yaml", "-o", maps / output
    )
    assert status == 0, err
    merged = load_map(maps / "merged.yaml")
    assert (maps / "merged.pgm").read_bytes().startswith(b"P5")
    assert merged.shape[0] > 0 and "merged.yaml" in out
    assert not list(maps.glob(".*part*")), "a temporary file was left behind"


def test_an_output_folder_is_refused_and_nothing_is_written(capsys, maps: Path) -> None:
    (maps / "out").mkdir()
    before = digest(maps)
    status, _, err = run_cli(capsys, "merge", maps / "a.yaml", maps / "b.yaml", "-o", maps / "out")
    assert_one_line(err, status)
    assert "is a folder" in err
    assert digest(maps) == before and not any((maps / "out").iterdir())


def test_an_unwritable_recording_is_refused_before_the_merge(capsys, maps: Path) -> None:
    status, _, err = run_cli(
        capsys,
        "merge",
        maps / "a.yaml",
        maps / "b.yaml",
        "-o",
        maps / "m.yaml",
        "--rrd",
        "/proc/x.rrd",
    )
    assert_one_line(err, status)
    assert "/proc" in err and not (maps / "m.yaml").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run", "--seed", "-1"], "--seed: must be a non-negative integer, got -1"),
        (["run", "--seed", "x"], "--seed: must be a non-negative integer, got 'x'"),
        (["merge", "a.yaml", "b.yaml", "--seed", "-3"], "--seed"),
        (["bench", "slam", "--seed", "-1"], "--seed"),
        (["bench", "merge", "--seed", "-1"], "--seed"),
        (["run", "--max-steps", "ten"], "--max-steps"),
        (["nothing"], "invalid choice: 'nothing'"),
        (["bench", "nothing"], "invalid choice: 'nothing'"),
        (["merge", "a.yaml"], "merge needs at least two maps, got 1"),
        (["merge"], "the following arguments are required"),
        (["scenarios", "--export", "office"], "--export"),
        (["scenarios", "--export", "office", "x.yaml", "--resolution", "0.001"], "the limit is"),
        (["scenarios", "--export", "office", "x.yaml", "--resolution", "nan"], "--resolution"),
        (["bench", "explore", "--seeds", "0"], "--seeds: must be an integer >= 1"),
        (["bench", "merge", "--pairs", "0"], "--pairs: must be an integer >= 1"),
        (["run", "--scenario", "nowhere", "--no-record"], "unknown scenario 'nowhere'"),
        (["run", "--map", "missing.yaml", "--no-record"], "missing.yaml"),
    ],
)
def test_every_subcommand_rejects_bad_arguments_in_one_line(
    capsys, tmp_path: Path, monkeypatch, argv: list[str], message: str
) -> None:
    monkeypatch.chdir(tmp_path)
    status, out, err = run_cli(capsys, *argv)
    assert_one_line(err, status)
    assert message in err and out == "", err
    assert list(tmp_path.iterdir()) == [], "a failed command left files behind"


def test_an_unexpected_failure_is_one_line_with_a_pointer_to_debug(capsys, monkeypatch) -> None:
    def broken(args: object) -> int:
        raise RuntimeError("the world ended\nsecond line")

    monkeypatch.setattr(cli, "_cmd_scenarios", broken)
    status, _, err = run_cli(capsys, "scenarios")
    assert_one_line(err, status, expected=1)
    assert "RuntimeError: the world ended" in err and "--debug" in err
    with pytest.raises(RuntimeError, match="the world ended"):
        main(["--debug", "scenarios"])


def test_ctrl_c_is_one_line_and_exit_130(capsys, monkeypatch) -> None:
    def interrupted(args: object) -> int:
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_cmd_scenarios", interrupted)
    status, _, err = run_cli(capsys, "scenarios")
    assert_one_line(err, status, expected=130)
    assert "interrupted" in err


def test_usage_errors_in_a_real_process_are_one_line(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "scenarios.cli", "run", "--seed", "-1"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "--seed" in done.stderr


def test_bench_soak_reports_speed_and_memory_per_stretch(capsys) -> None:
    status, out, _ = run_cli(
        capsys, "bench", "soak", "--steps", "30", "--every", "20", "--scenario", "maze", "--json"
    )
    rows = json.loads(out)
    assert status == 0 and [r["step"] for r in rows] == [20, 30]
    assert all(r["steps_per_s"] > 0 and r["rss_mb"] > 10 and r["known_m2"] > 0 for r in rows)


def test_two_outputs_that_are_one_file_are_refused(capsys, maps: Path) -> None:
    status, _, err = run_cli(
        capsys, "merge", maps / "a.yaml", maps / "b.yaml", "-o", maps / "m", "--rrd", maps / "m.pgm"
    )
    assert_one_line(err, status)
    assert "two outputs are the same file" in err and not (maps / "m.yaml").exists()


def test_export_never_overwrites_a_packaged_map(capsys) -> None:
    from scenarios.worlds.real import map_file

    before = map_file("tb3_sandbox").read_bytes()
    status, _, err = run_cli(
        capsys, "scenarios", "--export", "tb3_sandbox", map_file("tb3_sandbox")
    )
    assert_one_line(err, status)
    assert "would overwrite an input file" in err
    assert map_file("tb3_sandbox").read_bytes() == before


def test_atomic_outputs_get_the_mode_a_plain_write_would(tmp_path: Path) -> None:
    from mrslam_env.atomic import write_text_atomic

    old = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644
