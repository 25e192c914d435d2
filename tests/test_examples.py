"""Smoke tests of the usage examples in ``examples/``: each runs as a user would run it
(a subprocess, small size knobs, files written to a temporary working folder)."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from mrslam_env.mapio import load_map

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MAX_LINES = 45


def run_example(
    name: str,
    *args: str,
    cwd: Path,
    timeout: float = 120.0,
    environment: dict[str, str] | None = None,
) -> str:
    """Run ``examples/<name>`` with ``args`` in ``cwd`` (``environment`` added to this
    process's variables); its stdout (exit code 0 asserted)."""
    env = dict(os.environ, TMPDIR=str(cwd))  # the examples' temporary folders go in cwd
    env.update(environment or {})
    env["PYTHONPATH"] = os.pathsep.join(
        [str(EXAMPLES.parent), *filter(None, [os.environ.get("PYTHONPATH")])]
    )
    completed = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    assert completed.returncode == 0, completed.stderr[-3000:]
    return completed.stdout


def numbers(pattern: str, text: str) -> list[float]:
    """The groups of the first match of ``pattern`` in ``text``, as floats."""
    found = re.search(pattern, text)
    assert found is not None, f"{pattern!r} not in the output:\n{text}"
    return [float(group) for group in found.groups()]


def test_every_example_is_short_and_says_how_to_run_it() -> None:
    examples = sorted(EXAMPLES.glob("[0-9][0-9]_*.py"))
    assert [path.name[:3] for path in examples] == ["01_", "02_", "03_", "04_"]
    for path in examples:
        text = path.read_text(encoding="utf-8")
        assert len(text.splitlines()) < MAX_LINES, f"{path.name} is too long"
        assert text.startswith('"""'), f"{path.name} has no module docstring"
        assert f"Run: python examples/{path.name}" in text


def test_random_actions(tmp_path: Path) -> None:
    out = run_example("01_random_actions.py", "--steps", "15", "--seed", "3", cwd=tmp_path)
    assert "15 steps = 1.5 s simulated" in out
    rows = re.findall(r"(robot_\d): reward (-?[\d.]+), map ([\d.]+) m², collision steps (\d+)", out)
    assert [row[0] for row in rows] == ["robot_0", "robot_1"]
    assert all(float(area) > 0 and int(hits) <= 15 for _, _, area, hits in rows)


def test_slam_map_is_saved_as_a_loadable_ros_map(tmp_path: Path) -> None:
    out = run_example("02_slam_map.py", "--steps", "60", "--out", "mine.yaml", cwd=tmp_path)
    grid = load_map(tmp_path / "mine.yaml")
    assert (tmp_path / "mine.pgm").is_file()
    assert grid.free.sum() > 1000 and grid.occupied.sum() > 50
    known_area = (~grid.unknown).sum() * grid.resolution**2
    assert numbers(r"known area ([\d.]+) m²", out) == pytest.approx([known_area], abs=0.1)
    (slam_error,) = numbers(r"pose position error after 60 steps: ([\d.]+) m", out)
    assert slam_error < 0.2


def test_merge_example_recovers_the_known_transform(tmp_path: Path) -> None:
    out = run_example("03_merge_two_maps.py", "-o", "both.yaml", cwd=tmp_path)
    demo = re.search(r"demo pair in (\S+);", out)
    assert demo is not None and Path(demo.group(1)).parent == tmp_path
    assert (Path(demo.group(1)) / "m1.yaml").is_file()
    x, y, theta = numbers(r"map1_from_map2: x (-?[\d.]+) m, y (-?[\d.]+) m, theta (-?[\d.]+)°", out)
    assert math.hypot(x - 12.0, y - 3.0) < 0.1
    assert abs(theta - 30.0) < 1.0
    merged = load_map(tmp_path / "both.yaml")
    m1 = load_map(Path(demo.group(1)) / "m1.yaml")
    assert (~merged.unknown).sum() > (~m1.unknown).sum()  # map 2 added what m1 lacks


def test_full_experiment_writes_its_report(tmp_path: Path) -> None:
    out = run_example("04_full_experiment.py", str(tmp_path / "out"), "--steps", "30", cwd=tmp_path)
    run_dir = tmp_path / "out" / "run"
    report = json.loads((run_dir / "report.json").read_text())
    assert report["steps"] == 30
    assert f"30 steps ({report['sim_time_s']} s simulated)" in out
    assert "no verified merge" in out  # far too early to meet
    for name in ("robot_0.yaml", "robot_1.yaml", "figure.png", "recording.rrd"):
        assert (run_dir / name).is_file()
    assert (~load_map(run_dir / "robot_0.yaml").unknown).any()
