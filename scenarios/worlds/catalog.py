"""The scenario catalogue: every built-in world, by name.

The environment finds worlds through the ``mrslam.scenarios`` entry point, which loads
:data:`SCENARIOS` from here; other packages can register their own mappings of
:class:`Scenario` under the same entry-point group.

====================  =============  ===================================================
name                  size (m)       character
====================  =============  ===================================================
``office``            28 x 16        corridor, nine rooms, open-plan area (the default)
``warehouse``         33 x 20        long parallel shelving aisles: repetitive
``maze``              21.6 x 16.2    grid maze of 1.8 m cells with a few loops
``twin_wings``        32 x 14        two identical wings: a trap for map merging
``procedural``        18-28 sides    seeded office-like floor plans (``build(seed)``)
``procedural_large``  36-44 x 24-30  the same plans larger than the radio's range (12 m)
``procedural_huge``   60-80 x 45-60  the same plans with loops of tens to hundreds of metres
====================  =============  ===================================================

Real buildings (:mod:`scenarios.worlds.real`, SLAM maps of real places):
``aws_warehouse``, ``aws_warehouse_lowres``, ``bookstore``, ``small_house``,
``tb3_sandbox``, ``planner_test``; ``mrslam scenarios`` lists their sizes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from mrslam_env.sim.world import WorldSpec
from scenarios.worlds import buildings
from scenarios.worlds.procedural import (
    build_procedural,
    build_procedural_huge,
    build_procedural_large,
)
from scenarios.worlds.real import REAL_BUILDINGS, build_real

__all__ = ["DEFAULT_SCENARIO", "SCENARIOS", "Scenario"]


@dataclass(frozen=True, slots=True, kw_only=True)
class Scenario:
    """A named world.

    Attributes
    ----------
    name : str
        Key in :data:`SCENARIOS`.
    description : str
        One line for ``mrslam scenarios``.
    build : callable (int) -> WorldSpec
        Builds the world from a variant/layout seed; hand-made worlds ignore the seed.
    parametric : bool
        True when different seeds give different worlds (the procedural family).
    """

    name: str
    description: str
    build: Callable[[int], WorldSpec]
    parametric: bool = False

    def __post_init__(self) -> None:
        if not self.name or not self.name.isidentifier():
            raise ValueError(f"Scenario.name must be an identifier, got {self.name!r}")
        if not self.description or "\n" in self.description:
            raise ValueError(f"Scenario.description must be one line, got {self.description!r}")
        if not callable(self.build):
            raise TypeError(f"Scenario.build must be callable, got {self.build!r}")


DEFAULT_SCENARIO = "office"


def _real_builder(name: str) -> Callable[[int], WorldSpec]:
    """A real building's build function: one world, whatever the variant."""

    def build(variant: int) -> WorldSpec:
        return build_real(name)

    return build


SCENARIOS: Mapping[str, Scenario] = MappingProxyType(
    {
        scenario.name: scenario
        for scenario in (
            Scenario(
                name="office",
                description=buildings.OFFICE_DESCRIPTION,
                build=buildings.build_office,
            ),
            Scenario(
                name="warehouse",
                description=buildings.WAREHOUSE_DESCRIPTION,
                build=buildings.build_warehouse,
            ),
            Scenario(
                name="maze",
                description=buildings.MAZE_DESCRIPTION,
                build=buildings.build_maze,
            ),
            Scenario(
                name="twin_wings",
                description=buildings.TWIN_WINGS_DESCRIPTION,
                build=buildings.build_twin_wings,
            ),
            Scenario(
                name="procedural",
                description="seeded office-like floor plans: BSP rooms, corridors, doors "
                "(18-28 m; build(seed))",
                build=build_procedural,
                parametric=True,
            ),
            Scenario(
                name="procedural_large",
                description="seeded office-like floor plans larger than the comm range "
                "(36-44 x 24-30 m, starts 25-40 m apart; build(seed))",
                build=build_procedural_large,
                parametric=True,
            ),
            Scenario(
                name="procedural_huge",
                description="seeded office-like floor plans with long loops, for loop "
                "closure (60-80 x 45-60 m; build(seed))",
                build=build_procedural_huge,
                parametric=True,
            ),
            *(
                Scenario(
                    name=name,
                    description=f"real building: {what}",
                    build=_real_builder(name),
                )
                for name, what in REAL_BUILDINGS.items()
            ),
        )
    }
)
"""Built-in scenarios by name (read-only)."""
