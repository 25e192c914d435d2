"""The dependency rules of docs/design.md §1: which room may import which, and light imports."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def modules_loaded_by(statement: str) -> set[str]:
    code = f"import sys; {statement}; print('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return {name.split(".")[0] for name in out.stdout.split()}


@pytest.mark.parametrize(
    "statement",
    [
        "import mrslam_env",
        "import mrslam_env.merge",
        "import mrslam_env.geometry, mrslam_env.gridmap, mrslam_env.mapio",
        "import mrslam_env.slam.raycast",
        "import mrslam_env.sim.world",
    ],
)
def test_light_imports(statement: str) -> None:
    loaded = modules_loaded_by(statement)
    for heavy in ("pymunk", "pettingzoo", "rerun", "agents", "scenarios"):
        assert heavy not in loaded, f"`{statement}` imports {heavy}"


@pytest.mark.parametrize("name", ["parallel_env", "env", "MultiRobotSlamEnv"])
def test_the_package_resolves_the_env_lazily(name: str) -> None:
    # The README's first line of Python; it must work in a fresh interpreter.
    loaded = modules_loaded_by(f"from mrslam_env import {name}")
    assert "pettingzoo" in loaded and "pymunk" in loaded


def imported_modules(package: str) -> dict[str, set[str]]:
    """Full dotted module names each file of a package imports (statically, anywhere in
    the file: imports inside functions count too)."""
    found = {}
    for path in (ROOT / package).rglob("*.py"):
        names: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module)
                names |= {f"{node.module}.{alias.name}" for alias in node.names}
        found[str(path.relative_to(ROOT))] = names
    return found


def imports_of(package: str) -> dict[str, set[str]]:
    """Top-level module names each file of a package imports (statically)."""
    return {
        path: {name.split(".")[0] for name in names}
        for path, names in imported_modules(package).items()
    }


def test_library_never_imports_agents_or_scenarios() -> None:
    for path, names in imports_of("mrslam_env").items():
        forbidden = names & {"agents", "scenarios"}
        assert not forbidden, f"{path} imports {forbidden}"


def test_agents_never_import_scenarios() -> None:
    for path, names in imports_of("agents").items():
        assert "scenarios" not in names, f"{path} imports scenarios"


def test_benchmarks_are_imported_by_the_cli_only() -> None:
    # A benchmark is an application, never a library: whatever two of them share, or
    # share with the experiment, lives in mrslam_env.
    for package in ("mrslam_env", "agents", "scenarios"):
        for path, names in imported_modules(package).items():
            if path.startswith("scenarios/bench/") or path == "scenarios/cli.py":
                continue
            bench = {name for name in names if name.startswith("scenarios.bench")}
            assert not bench, f"{path} imports the benchmarks {sorted(bench)}"


def test_worlds_hold_only_worlds() -> None:
    for path, names in imports_of("scenarios").items():
        if path.startswith("scenarios/worlds/"):
            assert "agents" not in names, f"{path} imports agents"
            assert not any(
                n.startswith(("scenarios.bench", "scenarios.experiment", "scenarios.cli"))
                for n in imported_modules("scenarios")[path]
            ), f"{path} imports beyond the worlds"


def test_heavy_libraries_stay_in_their_modules() -> None:
    homes = {
        "pymunk": {"mrslam_env/sim/physics.py"},
        "rerun": {"mrslam_env/recording.py"},
        "pettingzoo": {"mrslam_env/env.py"},
    }
    for package in ("mrslam_env", "agents"):
        for path, names in imports_of(package).items():
            for library, allowed in homes.items():
                if library in names:
                    assert path in allowed, f"{path} imports {library}"
