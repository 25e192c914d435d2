"""Real buildings: worlds made from the ROS maps in ``scenarios/worlds/maps/``.

Each map is a SLAM map of a real place (ragged walls, clutter, round objects, unknown
padding; see ``maps/README.md`` for sources and licences). Building a world loads it,
removes speckle, ray streaks and free space no robot can reach
(:func:`~mrslam_env.sim.cleaning.clean_for_simulation`), and turns the occupied and unknown
cells into walls (:func:`~mrslam_env.sim.mapworld.world_from_map`). The two start poses are
chosen automatically and far apart (seed 0), at the map's native resolution.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np

from mrslam_env.mapio import load_map
from mrslam_env.sim.cleaning import clean_for_simulation
from mrslam_env.sim.mapworld import world_from_map
from mrslam_env.sim.world import WorldSpec

__all__ = ["MAPS_DIR", "REAL_BUILDINGS", "build_real", "map_file"]

MAPS_DIR = Path(__file__).with_name("maps")

REAL_BUILDINGS: dict[str, str] = {
    "aws_warehouse": "AWS small warehouse, 0.02 m SLAM map: shelving rows, bays (21 x 15 m)",
    "aws_warehouse_lowres": "the AWS warehouse from another SLAM run, 0.05 m (21 x 15 m)",
    "bookstore": "AWS bookstore, SLAM map: shelves, tables, a round corner (16 x 15 m)",
    "small_house": "AWS small house, SLAM map: furnished rooms, round objects (19 x 11 m)",
    "tb3_sandbox": "TurtleBot3 sandbox: a small hexagonal arena with pillars (6 x 5 m)",
    "planner_test": "nav2 planner test map: corridors, diagonal walls, blobs (20 x 20 m)",
}
"""Name -> what the map shows and the size of its known area (checked by a test)."""


def map_file(name: str) -> Path:
    """The YAML file of a real building's map."""
    if name not in REAL_BUILDINGS:
        raise ValueError(f"no real building {name!r}; known: {', '.join(REAL_BUILDINGS)}")
    return MAPS_DIR / f"{name}.yaml"


@cache
def build_real(name: str) -> WorldSpec:
    """The cleaned world of a real building (cached: worlds are immutable)."""
    grid = clean_for_simulation(load_map(map_file(name)))
    return world_from_map(
        grid, name=name, rng=np.random.default_rng(0), description=REAL_BUILDINGS[name]
    )
