"""Issue 36: every command's help works, every writer checks its outputs (against its inputs,
for writability, against overwriting) before any work, bad values are refused in one line,
the human-readable angle is in degrees, and ``--version`` answers."""

from __future__ import annotations

import argparse
import hashlib
import importlib.metadata
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios import cli
from scenarios.cli import main


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> tuple[int, str, str]:
    try:
        status = main([str(a) for a in argv])
    except SystemExit as exit_:
        status = int(exit_.code or 0)
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def assert_refused(err: str, status: int) -> None:
    assert status == 2, err
    assert err.count("\n") == 1 and err.startswith("mrslam"), err
    assert "Traceback" not in err


def digest(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def no_work(*args: object, **kwargs: object) -> object:
    raise AssertionError("the work started before the outputs were checked")


# -- 1. help of every command ---------------------------------------------------------------


def command_paths(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()) -> list:
    paths = [prefix]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                paths += command_paths(sub, (*prefix, name))
    return paths


def test_the_walk_finds_every_bench() -> None:
    paths = command_paths(cli._build_parser())
    assert {("bench", b) for b in ("sim", "slam", "explore", "soak", "merge")} <= set(paths)
    assert {("run",), ("merge",), ("scenarios",)} <= set(paths)


@pytest.mark.parametrize("path", command_paths(cli._build_parser()), ids=" ".join)
def test_help_of_every_command_exits_0(capsys, path: tuple[str, ...]) -> None:
    status, out, err = run_cli(capsys, *path, "-h")
    assert status == 0 and err == "", err
    assert out.startswith("usage: mrslam") and "Traceback" not in out


def test_bench_help_in_a_real_process(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "scenarios.cli", "bench", "-h"],
        capture_output=True,
        text=True,
        cwd=Path(__file__).resolve().parents[1],
        check=False,
        timeout=120,  # TimeoutExpired (the process killed) rather than a hang
    )
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert "90 % coverage" in done.stdout or "90% coverage" in done.stdout


# -- 7. --version -----------------------------------------------------------------------------


def test_version_is_the_installed_one(capsys) -> None:
    status, out, _ = run_cli(capsys, "--version")
    assert status == 0
    assert out.strip() == f"mrslam {importlib.metadata.version('mrslam')}"


# -- 2, 3. outputs checked before any work; never overwritten without --overwrite ------------


def test_merge_refuses_an_existing_output_unless_overwrite(capsys, maps: Path) -> None:
    (maps / "m.yaml").write_text("mine\n")
    before = digest(maps)
    status, out, err = run_cli(capsys, "merge", maps / "a.yaml", maps / "b.yaml", "-o", maps / "m")
    assert_refused(err, status)
    assert "exists" in err and "--overwrite" in err and out == ""
    assert digest(maps) == before
    status, out, err = run_cli(
        capsys, "merge", maps / "a.yaml", maps / "b.yaml", "-o", maps / "m", "--overwrite"
    )
    assert status == 0, err
    assert (maps / "m.yaml").read_text() != "mine\n" and (maps / "m.pgm").is_file()


def test_merge_refuses_an_existing_image_output_and_recording(capsys, maps: Path) -> None:
    (maps / "m.pgm").write_bytes(b"mine")
    (maps / "r.rrd").write_bytes(b"mine")
    before = digest(maps)
    for extra in (["-o", maps / "m.yaml"], ["--rrd", maps / "r.rrd"]):
        status, _, err = run_cli(capsys, "merge", maps / "a.yaml", maps / "b.yaml", *extra)
        assert_refused(err, status)
        assert "exists" in err
    assert digest(maps) == before


def test_export_refuses_an_existing_output_unless_overwrite(capsys, tmp_path: Path) -> None:
    (tmp_path / "x.pgm").write_bytes(b"mine")
    status, _, err = run_cli(capsys, "scenarios", "--export", "maze", tmp_path / "x.yaml")
    assert_refused(err, status)
    assert "x.pgm" in err and "--overwrite" in err
    assert (tmp_path / "x.pgm").read_bytes() == b"mine" and not (tmp_path / "x.yaml").exists()
    status, _, err = run_cli(
        capsys, "scenarios", "--export", "maze", tmp_path / "x.yaml", "--overwrite"
    )
    assert status == 0, err
    assert (tmp_path / "x.pgm").read_bytes().startswith(b"P5")


@pytest.mark.parametrize("out", ["a.yaml", "a.pgm", "./b.pgm"])
def test_bench_merge_never_writes_over_its_input_maps(
    capsys, maps: Path, monkeypatch, out: str
) -> None:
    import scenarios.bench.merge.pairs as pairs

    monkeypatch.setattr(pairs, "load_or_generate_pairs", no_work)
    monkeypatch.chdir(maps)
    before = digest(maps)
    argv = ["bench", "merge", "--maps", "a.yaml", "b.yaml", "--out", out, "--overwrite"]
    status, _, err = run_cli(capsys, *argv)
    assert_refused(err, status)
    assert "would overwrite an input file" in err
    assert digest(maps) == before


@pytest.mark.parametrize("out", ["/proc/results.json", "exists.csv", "missing/r.csv", "."])
def test_bench_merge_checks_its_out_before_the_benchmark(
    capsys, tmp_path: Path, monkeypatch, out: str
) -> None:
    import scenarios.bench.merge.pairs as pairs

    monkeypatch.setattr(pairs, "load_or_generate_pairs", no_work)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "exists.csv").write_text("mine\n")
    status, _, err = run_cli(capsys, "bench", "merge", "--set", "builtin", "--out", out)
    assert_refused(err, status)
    assert (tmp_path / "exists.csv").read_text() == "mine\n"


@pytest.mark.parametrize("out", ["/proc/explore", "full", "file.txt"])
def test_bench_explore_checks_its_out_folder_before_the_benchmark(
    capsys, tmp_path: Path, monkeypatch, out: str
) -> None:
    import scenarios.bench.explore as explore

    monkeypatch.setattr(explore, "run_tasks", no_work)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "kept.json").write_text("{}")
    (tmp_path / "file.txt").write_text("mine")
    status, _, err = run_cli(capsys, "bench", "explore", "--out", out)
    assert_refused(err, status)
    assert out in err
    assert (tmp_path / "file.txt").read_text() == "mine"


def test_bench_explore_refuses_out_with_from(capsys, tmp_path: Path) -> None:
    status, _, err = run_cli(
        capsys, "bench", "explore", "--from", tmp_path, "--out", tmp_path / "new"
    )
    assert_refused(err, status)
    assert "--out" in err and "--from" in err and not (tmp_path / "new").exists()


# -- 5. bad values refused before any work ----------------------------------------------------


@pytest.mark.parametrize("value", ["1e300", "inf", "-0.05", "0", "nan", "1e-300", "20"])
def test_export_resolution_must_be_sane(capsys, tmp_path: Path, value: str) -> None:
    status, out, err = run_cli(
        capsys, "scenarios", "--export", "office", tmp_path / "x.yaml", "--resolution", value
    )
    assert_refused(err, status)
    assert "--resolution" in err and out == ""
    assert list(tmp_path.iterdir()) == []


COUNTS = [
    ("sim", "--steps"),
    ("sim", "--repeats"),
    ("slam", "--steps"),
    ("explore", "--seeds"),
    ("explore", "--max-steps"),
    ("explore", "--jobs"),
    ("soak", "--steps"),
    ("soak", "--every"),
    ("merge", "--pairs"),
    ("merge", "--real-pairs"),
    ("merge", "--cut-pairs"),
    ("merge", "--jobs"),
]


@pytest.mark.parametrize(("bench", "option"), COUNTS)
@pytest.mark.parametrize("value", ["0", "-2", "1.5"])
def test_every_bench_count_is_at_least_1(
    capsys, monkeypatch, bench: str, option: str, value: str
) -> None:
    monkeypatch.setattr(cli, "_cmd_bench", no_work)
    status, out, err = run_cli(capsys, "bench", bench, option, value)
    assert_refused(err, status)
    assert f"{option}: must be an integer >= 1, got" in err and out == ""


def test_every_bench_count_option_is_tested() -> None:
    parser = cli._build_parser()
    kinds = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    bench = kinds.choices["bench"]
    benches = next(a for a in bench._actions if isinstance(a, argparse._SubParsersAction))
    counts = {
        (name, action.option_strings[-1])
        for name, sub in benches.choices.items()
        for action in sub._actions
        if action.type is cli._count
    }
    assert counts == set(COUNTS)


# -- 6. degrees in human-readable output ------------------------------------------------------


def test_merge_prints_degrees(capsys, maps: Path) -> None:
    status, out, err = run_cli(capsys, "merge", maps / "a.yaml", maps / "b.yaml")
    assert status == 0, err
    found = re.search(r"theta (-?\d+\.\d+)°", out)
    assert found is not None and " rad" not in out, out
    assert abs(float(found.group(1))) < 1.0
    assert math.isfinite(float(found.group(1)))


# -- 4. input files that are not regular files ------------------------------------------------


def test_merge_of_a_fifo_or_a_device_is_one_line(capsys, maps: Path) -> None:
    import os

    os.mkfifo(maps / "fifo.yaml")
    for bad in (maps / "fifo.yaml", Path("/dev/zero")):
        status, out, err = run_cli(capsys, "merge", bad, maps / "b.yaml")
        assert_refused(err, status)
        assert f"{bad}: not a regular file" in err and out == ""


class Unprintable:
    def __str__(self) -> str:
        raise RuntimeError("cannot be written")


@pytest.mark.parametrize("name", ["rows.csv", "rows.json"])
def test_a_failed_bench_merge_write_keeps_the_earlier_file(tmp_path: Path, name: str) -> None:
    from scenarios.bench.merge.report import write_rows

    path = tmp_path / name
    path.write_text("earlier\n")
    with pytest.raises((RuntimeError, TypeError)):
        write_rows(path, [{"pair_id": 1, "bad": Unprintable()}], {"summary": {}})
    assert path.read_text() == "earlier\n"
    assert [p.name for p in tmp_path.iterdir()] == [name], "a temporary file was left behind"
