"""``mrslam merge MAP1.yaml MAP2.yaml [-o merged.yaml] [--json] [--seed N]`` (docs/design.md §8).

Run in-process through ``scenarios.cli.main`` on ROS map files written with
:func:`mrslam_env.mapio.save_map`: the exit status (0 merged, 3 no confident merge, 2 bad
input with a one-line ``mrslam: error:``), the printed transform and JSON report, the merged
map file, and that the transform is expressed in the maps' world frames, honouring each
YAML's ``origin``. Merges are shared through module-scoped fixtures (about a second each).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml
from merge_fixtures import map_pair

from mrslam_env.evaluation import relative_transform_error
from mrslam_env.geometry import compose
from mrslam_env.gridmap import OCCUPIED, UNKNOWN, GridMap
from mrslam_env.mapio import load_map, save_map
from mrslam_env.merge.fuse import resample_map
from scenarios.cli import main

ONE_DEGREE = math.radians(1.0)
TOLERANCE_M = 0.1
CELL = 0.05  # m, the resolution of the pairs
# warehouse windows overlapping by about 60 %, m2 turned by 2.9 rad
TRUTH = np.array([0.4, -1.7, 2.9])
DESIGN_KEYS = {"transform", "score", "acceptance_index", "hypotheses", "seconds"}


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> tuple[int, str, str]:
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def run_captured(*argv: str | Path) -> tuple[int, str, str]:
    """``main`` with stdout/stderr captured, usable from module-scoped fixtures."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main([str(a) for a in argv])
    return status, out.getvalue(), err.getvalue()


def known_centroid(grid: GridMap) -> np.ndarray:
    return grid.cell_to_world(np.argwhere(~grid.unknown).mean(axis=0)[None, :])[0]


def as_transform(report: dict[str, float]) -> np.ndarray:
    return np.array([report["x"], report["y"], report["theta"]], dtype=np.float64)


@dataclass(frozen=True)
class PairFiles:
    folder: Path
    map1: Path
    map2: Path
    m1: GridMap
    m2: GridMap


@pytest.fixture(scope="module")
def pair_files(tmp_path_factory: pytest.TempPathFactory) -> PairFiles:
    folder = tmp_path_factory.mktemp("pair")
    m1, m2 = map_pair("warehouse", (6.0, 6.0), (11.0, 7.0), TRUTH)
    return PairFiles(
        folder, save_map(folder / "m1.yaml", m1), save_map(folder / "m2.yaml", m2), m1, m2
    )


@dataclass(frozen=True)
class JsonRun:
    status: int
    out: str
    err: str
    report: dict[str, object]
    merged_path: Path


@pytest.fixture(scope="module")
def json_run(pair_files: PairFiles) -> JsonRun:
    merged = pair_files.folder / "out" / "merged.yaml"
    merged.parent.mkdir()
    status, out, err = run_captured(
        "merge", pair_files.map1, pair_files.map2, "--json", "-o", merged
    )
    return JsonRun(status, out, err, json.loads(out), merged)


# -- a good pair ---------------------------------------------------------------------------


def test_merge_prints_the_transform_and_exits_0(capsys, pair_files: PairFiles) -> None:
    status, out, err = run_cli(capsys, "merge", pair_files.map1, pair_files.map2)
    assert status == 0, err
    match = re.search(
        r"map1_from_map2: x (-?\d+\.\d+) m, y (-?\d+\.\d+) m, theta (-?\d+\.\d+)°", out
    )
    assert match is not None, out
    x, y, degrees = (float(v) for v in match.groups())
    estimate = np.array([x, y, np.radians(degrees)])
    translation, rotation = relative_transform_error(estimate, TRUTH, known_centroid(pair_files.m2))
    assert translation <= TOLERANCE_M and rotation <= ONE_DEGREE
    assert "merged: acceptance index" in out
    assert err == ""


def test_json_report_has_the_design_keys(json_run: JsonRun) -> None:
    assert json_run.status == 0, json_run.err
    report = json_run.report
    assert set(report) >= DESIGN_KEYS
    assert set(report["transform"]) == {"x", "y", "theta"}
    assert all(isinstance(v, float) for v in report["transform"].values())
    assert isinstance(report["score"], float) and report["score"] > 0
    assert 0.9 <= report["acceptance_index"] <= 1.0
    assert isinstance(report["seconds"], float) and report["seconds"] > 0
    hypotheses = report["hypotheses"]
    assert isinstance(hypotheses, list) and hypotheses
    for hypothesis in hypotheses:
        assert {"transform", "acceptance_index", "score", "confident"} <= set(hypothesis)
        assert set(hypothesis["transform"]) == {"x", "y", "theta"}
    assert isinstance(report["reason"], str) and report["reason"].startswith("merged")
    # stdout is the JSON document and nothing else.
    assert json.loads(json_run.out) == report
    assert json_run.err == ""


def test_json_transform_is_correct(json_run: JsonRun, pair_files: PairFiles) -> None:
    estimate = as_transform(json_run.report["transform"])
    translation, rotation = relative_transform_error(estimate, TRUTH, known_centroid(pair_files.m2))
    assert translation <= TOLERANCE_M and rotation <= ONE_DEGREE


def test_output_is_a_loadable_merged_map(json_run: JsonRun, pair_files: PairFiles) -> None:
    merged = load_map(json_run.merged_path)
    m1, m2 = pair_files.m1, pair_files.m2
    assert merged.resolution == pytest.approx(m1.resolution)
    # In map 1's frame, on its lattice: m1's known cells sit inside it unchanged (the
    # merged map spans the two maps' known areas, not m1's whole grid).
    offset = (np.asarray(m1.origin) - np.asarray(merged.origin)) / merged.resolution
    col0, row0 = np.rint(offset).astype(int)
    np.testing.assert_allclose(offset, [col0, row0], atol=1e-6)
    for mask, check in (
        (~m1.unknown, lambda v: v != UNKNOWN),
        (m1.occupied, lambda v: v == OCCUPIED),
    ):
        cells = np.argwhere(mask) + np.array([row0, col0])
        assert merged.contains(cells).all()
        assert np.all(check(merged.cells[cells[:, 0], cells[:, 1]]))
    known = np.count_nonzero(~merged.unknown)
    assert np.count_nonzero(~m1.unknown) < known
    assert np.count_nonzero(~m2.unknown) < known


# -- no confident merge ----------------------------------------------------------------------


def test_no_overlap_exits_3_with_null_transform(capsys, tmp_path: Path) -> None:
    m1, m2 = map_pair("office", (4.0, 4.0), (23.0, 12.0), np.array([1.0, 2.0, 0.5]))
    map1, map2 = save_map(tmp_path / "a.yaml", m1), save_map(tmp_path / "b.yaml", m2)
    merged = tmp_path / "merged.yaml"
    status, out, err = run_cli(capsys, "merge", map1, map2, "--json", "-o", merged)
    assert status == 3, err
    report = json.loads(out)
    assert set(report) >= DESIGN_KEYS
    assert report["transform"] is None
    assert report["reason"].startswith("no confident merge")
    assert report["acceptance_index"] is None and report["score"] is None
    assert not merged.exists()  # nothing merged, nothing written


# -- the transform is in the maps' world frames -----------------------------------------------


def _with_origin_shift(source: Path, target: Path, shift: tuple[float, float]) -> Path:
    """A copy of a map YAML whose ``origin`` is moved by ``shift`` (same image)."""
    document = yaml.safe_load(source.read_text())
    document["origin"] = [document["origin"][0] + shift[0], document["origin"][1] + shift[1], 0.0]
    document["image"] = str((source.parent / document["image"]).resolve())
    target.write_text(yaml.safe_dump(document))
    return target


def test_transform_honours_each_yaml_origin(
    json_run: JsonRun, pair_files: PairFiles, tmp_path: Path
) -> None:
    shift1, shift2 = (3.3, -1.7), (-12.34, 5.67)
    map1 = _with_origin_shift(pair_files.map1, tmp_path / "m1.yaml", shift1)
    map2 = _with_origin_shift(pair_files.map2, tmp_path / "m2.yaml", shift2)
    status, out, err = run_captured("merge", map1, map2, "--json")
    assert status == 0, err
    shifted = as_transform(json.loads(out)["transform"])
    original = as_transform(json_run.report["transform"])

    def in_shifted_frames(map1_from_map2: np.ndarray) -> np.ndarray:
        # Map i's frame moved by shift_i: map1'_from_map2' = shift1 ∘ map1_from_map2 ∘ shift2⁻¹.
        moved = compose(np.array([*shift1, 0.0]), map1_from_map2)
        return compose(moved, np.array([-shift2[0], -shift2[1], 0.0]))

    pivot = known_centroid(load_map(map2))
    translation, rotation = relative_transform_error(shifted, in_shifted_frames(original), pivot)
    assert translation <= CELL and rotation <= ONE_DEGREE
    # ... and it is still the true relative pose, in the shifted frames.
    translation, rotation = relative_transform_error(shifted, in_shifted_frames(TRUTH), pivot)
    assert translation <= TOLERANCE_M and rotation <= ONE_DEGREE


# -- bad input ------------------------------------------------------------------------------


def _bad_inputs(folder: Path, pair: PairFiles) -> dict[str, tuple[list[str | Path], str]]:
    (folder / "malformed.yaml").write_text("image: [unclosed\n")
    (folder / "no_image.yaml").write_text(
        "image: nowhere.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    unknown = GridMap(cells=np.full((80, 80), UNKNOWN, dtype=np.int8), resolution=0.05)
    save_map(folder / "unknown.yaml", unknown)
    save_map(folder / "coarse.yaml", resample_map(pair.m2, 0.5))  # 10x coarser than m1
    good1, good2 = pair.map1, pair.map2
    return {
        "missing file": (["merge", folder / "missing.yaml", good2], "map YAML file not found"),
        "malformed yaml": (["merge", good1, folder / "malformed.yaml"], "invalid YAML syntax"),
        "missing image": (["merge", folder / "no_image.yaml", good2], "image file not found"),
        "all unknown": (["merge", good1, folder / "unknown.yaml"], "map 2 is all unknown"),
        "resolutions": (["merge", good1, folder / "coarse.yaml"], "differ by 10.0x"),
        "output folder": (
            ["merge", good1, good2, "-o", folder / "nowhere" / "m.yaml"],
            "does not exist",
        ),
    }


BAD_CASES = [
    "missing file",
    "malformed yaml",
    "missing image",
    "all unknown",
    "resolutions",
    "output folder",
]


@pytest.mark.parametrize("case", BAD_CASES)
def test_bad_input_is_one_line_and_exit_2(
    capsys, tmp_path: Path, pair_files: PairFiles, case: str
) -> None:
    argv, message = _bad_inputs(tmp_path, pair_files)[case]
    status, out, err = run_cli(capsys, *argv, "--json")
    assert status == 2
    assert out == ""
    assert err.startswith("mrslam: error: ") and err.count("\n") == 1, err
    assert message in err, err
    assert "Traceback" not in err


def test_bad_input_in_a_real_process_has_no_traceback(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "scenarios.cli", "merge", "a.yaml", "b.yaml"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert done.returncode == 2
    assert done.stderr.startswith("mrslam: error: ") and done.stderr.count("\n") == 1
    assert "a.yaml" in done.stderr and done.stdout == ""


def test_rrd_in_a_missing_folder_is_exit_2(capsys, pair_files: PairFiles, tmp_path: Path) -> None:
    rrd = tmp_path / "nowhere" / "merge.rrd"
    status, _, err = run_cli(capsys, "merge", pair_files.map1, pair_files.map2, "--rrd", rrd)
    assert status == 2
    assert err.startswith("mrslam: error: ") and err.count("\n") == 1, err
