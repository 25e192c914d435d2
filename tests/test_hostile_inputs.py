"""Hostile inputs found by an outside tester: run names that escape ``--out``, an ``--out``
that is a file, oversized PNG headers, a full disk under the recording, ``n_robots=True``."""

from __future__ import annotations

import errno
import json
import struct
import warnings
import zlib
from pathlib import Path

import pytest

from mrslam_env.env import parallel_env
from mrslam_env.mapio import MapFileError, read_image
from mrslam_env.recording import Recorder
from scenarios import experiment
from scenarios.cli import main
from scenarios.experiment import RunConfig, run_experiment

# -- 1. run names --------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["", ".", "..", "../escape", "/tmp/abs", "a/b", "a\0b"])
def test_a_run_name_is_one_plain_folder_name(name: str) -> None:
    with pytest.raises(ValueError, match="--name") as refused:
        RunConfig(name=name)
    assert repr(name) in str(refused.value) and "\n" not in str(refused.value)


def test_out_that_is_a_file_is_refused_in_one_line(capsys, tmp_path: Path) -> None:
    (tmp_path / "afile").write_text("x")
    status = main(["run", "--out", str(tmp_path / "afile"), "--max-steps", "1", "--no-record"])
    err = capsys.readouterr().err
    assert status == 2
    assert f"--out {tmp_path / 'afile'}: exists and is not a folder" in err


def test_the_default_name_of_a_map_run_is_the_yaml_stem(capsys, tmp_path: Path) -> None:
    assert main(["scenarios", "--export", "maze", str(tmp_path / "m.yaml")]) == 0
    out = tmp_path / "out"
    args = ["run", "--map", str(tmp_path / "m.yaml"), "--max-steps", "2", "--out", str(out)]
    assert main([*args, "--no-record"]) == 0
    assert [p.name for p in out.iterdir()] == ["m-seed0"]


# -- 2. oversized images -----------------------------------------------------------------------


def _png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG whose header says ``width`` x ``height`` grey pixels, with almost no data."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\0" * 16))
        + chunk(b"IEND", b"")
    )


@pytest.mark.parametrize("side", [30_000, 12_000])  # Pillow's error, Pillow's warning
def test_an_oversized_png_is_refused_in_one_line_without_warnings(tmp_path, side) -> None:
    path = tmp_path / "b.png"
    _png_header_only(path, side, side)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(MapFileError, match="the limit is 100,000,000"):
            read_image(path)
    assert not caught


def test_oversized_png_map_exits_2(capsys, tmp_path: Path) -> None:
    _png_header_only(tmp_path / "b.png", 30_000, 30_000)
    yaml = "image: b.png\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
    yaml += "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    (tmp_path / "b.yaml").write_text(yaml)
    assert main(["merge", str(tmp_path / "b.yaml"), str(tmp_path / "b.yaml")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "unexpected" not in err


# -- 3. a full disk under the recording ---------------------------------------------------------


def test_a_recorder_close_that_fails_names_the_file_and_the_cause(tmp_path: Path) -> None:
    recorder = Recorder(tmp_path / "r.rrd", n_robots=2)

    def fail() -> None:
        raise RuntimeError("File-writer thread shut down prematurely")

    recorder._stream.flush = fail  # type: ignore[method-assign,assignment]
    with pytest.raises(OSError, match=r"cannot write recording .*r\.rrd"):
        recorder.close()
    recorder.close()  # idempotent: closed, nothing raised again


def test_a_failed_recording_leaves_no_partial_file_and_a_report(monkeypatch, tmp_path) -> None:
    close = Recorder.close

    def full(self: Recorder) -> None:
        close(self)
        raise OSError(errno.ENOSPC, f"cannot write recording {self.path}: no space left")

    monkeypatch.setattr(Recorder, "close", full)
    with pytest.raises(OSError, match="cannot write recording"):
        run_experiment(RunConfig(out=tmp_path, name="r", max_steps=3, progress=False, figure=False))
    folder = tmp_path / "r"
    assert not list(folder.glob(".*")) and not (folder / "recording.rrd").exists()
    report = json.loads((folder / "report.json").read_text())
    assert "recording" not in report["outputs"]
    assert any("cannot write recording" in e for e in report["errors"])


def test_a_recording_that_cannot_start_lets_the_run_write_its_report(monkeypatch, tmp_path) -> None:
    def full(self: Recorder, path: Path, **_kwargs: object) -> None:
        Path(path).write_bytes(b"RRF")
        raise RuntimeError("Failed to write: No space left on device (os error 28)")

    monkeypatch.setattr(Recorder, "__init__", full)
    with pytest.raises(OSError, match=r"cannot write recording .*: no space left on device"):
        run_experiment(RunConfig(out=tmp_path, name="r", max_steps=3, progress=False, figure=False))
    folder = tmp_path / "r"
    assert not list(folder.glob(".*"))
    assert json.loads((folder / "report.json").read_text())["errors"]


def test_a_crash_with_a_failing_recording_keeps_the_crash(monkeypatch, tmp_path) -> None:
    def full(self: Recorder) -> None:
        raise OSError(errno.ENOSPC, "no space left on device")

    def crash(*_args: object, **_kwargs: object) -> None:
        raise OSError(errno.ENOSPC, "map: no space left on device")

    monkeypatch.setattr(Recorder, "close", full)
    monkeypatch.setattr(experiment, "save_map", crash)
    with pytest.raises(OSError, match="map: no space"):
        run_experiment(RunConfig(out=tmp_path, name="r", max_steps=3, progress=False, figure=False))
    assert not list((tmp_path / "r").glob(".*"))


# -- 4. n_robots ------------------------------------------------------------------------------


def test_n_robots_true_is_refused() -> None:
    with pytest.raises(ValueError, match="n_robots"):
        parallel_env(n_robots=True)
