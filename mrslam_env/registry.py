"""Scenario lookup by name through the ``mrslam.scenarios`` entry-point group.

The library never imports the ``scenarios`` package (docs/design.md §1): worlds are plugins. Any
installed distribution can add worlds by declaring, in its ``pyproject.toml``::

    [project.entry-points."mrslam.scenarios"]
    mine = "my_package.worlds:SCENARIOS"   # a Mapping[str, ScenarioLike]

mrslam itself registers its built-in catalogue that way.

Names: a scenario's own name (``"office"``), or for parametric families such as
``"procedural"`` the name with a layout seed (``"procedural-7"``; plain ``"procedural"``
is seed 0).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import cache
from importlib.metadata import entry_points
from typing import Protocol

from mrslam_env.sim.world import WorldSpec

__all__ = ["ScenarioLike", "UnknownScenarioError", "available_scenarios", "build_world"]

ENTRY_POINT_GROUP = "mrslam.scenarios"


class ScenarioLike(Protocol):
    """What a scenario entry must provide."""

    @property
    def name(self) -> str: ...
    @property
    def description(self) -> str: ...
    @property
    def build(self) -> Callable[[int], WorldSpec]: ...
    @property
    def parametric(self) -> bool: ...


class UnknownScenarioError(ValueError):
    """Raised for a scenario name that no installed catalogue provides."""


@cache
def available_scenarios() -> Mapping[str, ScenarioLike]:
    """All scenarios of every installed catalogue, by name (loaded once)."""
    found: dict[str, ScenarioLike] = {}
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        found.update(entry.load())
    return found


def build_world(name: str) -> WorldSpec:
    """Build the world a scenario name stands for.

    Raises
    ------
    UnknownScenarioError
        Naming the valid scenarios.
    """
    catalogue = available_scenarios()
    scenario = catalogue.get(name)
    variant = 0
    if scenario is None:
        family, _, suffix = name.rpartition("-")
        candidate = catalogue.get(family)
        if candidate is not None and candidate.parametric and suffix.isdigit():
            scenario, variant = candidate, int(suffix)
    if scenario is None:
        valid = ", ".join(
            f"{key}[-SEED]" if s.parametric else key for key, s in sorted(catalogue.items())
        )
        raise UnknownScenarioError(f"unknown scenario {name!r}; valid scenarios: {valid}")
    return scenario.build(variant)
