"""Issue 36: the examples and the README's snippets write under ``runs/``, never in the
repository root, and example 03 never overwrites an earlier output without ``--overwrite``."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
FILE_SUFFIXES = (".zip", ".yaml", ".pgm", ".rrd", ".json", ".csv", ".png")


def written_names(source: str) -> list[str]:
    """String constants that name files (by suffix) in ``source``'s code."""
    return [
        node.value
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and node.value.endswith(FILE_SUFFIXES)
        and not node.value.startswith(".")  # a suffix, not a file
        and "/" not in node.value.removeprefix("runs/")
    ]


def test_readme_snippets_write_under_runs() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```python\n(.*?)^```", text, re.M | re.S)
    saved = [name for block in blocks for name in written_names(block) if "save" in block]
    assert saved, "no file the snippets write was found"
    for name in saved:
        assert name.startswith("runs/"), f"a README snippet writes {name} in the working folder"
    assert "MRSLAM_SB3_MODEL=runs/ppo_mrslam.zip" in text


def out_defaults(source: str) -> list[str]:
    """The defaults of ``--out`` options and ``DEFAULT_MODEL`` in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument":
            names = [a.value for a in node.args if isinstance(a, ast.Constant)]
            if "--out" in names:
                found += [ast.literal_eval(k.value) for k in node.keywords if k.arg == "default"]
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "DEFAULT_MODEL":
            found.append(ast.literal_eval(node.value))
    return found


def test_example_defaults_write_under_runs() -> None:
    names = ("02_slam_map.py", "03_merge_two_maps.py", "train_sb3_ppo.py", "train_rllib_ppo.py")
    for name in (*names, "sb3_policy.py"):
        defaults = out_defaults((EXAMPLES / name).read_text(encoding="utf-8"))
        assert len(defaults) == 1, name
        assert defaults[0].startswith("runs/"), f"{name} writes {defaults[0]} in the working folder"


def run_example(name: str, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, TMPDIR=str(cwd), PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_merge_example_writes_under_runs_and_never_overwrites(tmp_path: Path) -> None:
    first = run_example("03_merge_two_maps.py", cwd=tmp_path)
    assert first.returncode == 0, first.stderr[-2000:]
    merged = tmp_path / "runs" / "merged.yaml"
    assert merged.is_file() and (tmp_path / "runs" / "merged.pgm").is_file()
    assert not list(tmp_path.glob("merged*"))
    before = merged.read_bytes()
    merged.write_text("mine\n")
    second = run_example("03_merge_two_maps.py", cwd=tmp_path)
    assert second.returncode == 2 and "--overwrite" in second.stderr, second.stderr[-2000:]
    assert merged.read_text() == "mine\n"
    third = run_example("03_merge_two_maps.py", "--overwrite", cwd=tmp_path)
    assert third.returncode == 0, third.stderr[-2000:]
    assert merged.read_bytes() == before
