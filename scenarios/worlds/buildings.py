"""Hand-made worlds: an office, a warehouse, a maze and a building with twin wings.

Every world is a closed building drawn with 0.1 m thick walls
(:func:`mrslam_env.sim.world.thick_segment`) and solid furniture boxes
(:func:`mrslam_env.sim.world.box`), in metres, with the origin at the building's south-west
corner. Doorways and passages are at least :data:`DOOR_WIDTH` wide *clear* (between wall
faces), so a 0.2 m radius robot passes with margin. Each world has two default start poses
``(x, y, theta)`` in different rooms or areas, more than 6 m apart and facing different
directions, with at least 0.5 m of clearance.

The builders take a seed so that they share the signature of the procedural generator; the
hand-made worlds ignore it (the maze is drawn from its own fixed seed, so it is the same
every time).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from mrslam_env.sim.world import (
    DEFAULT_WALL_THICKNESS,
    FloatArray,
    WorldSpec,
    box,
    polyline_walls,
    thick_segment,
)

__all__ = [
    "DOOR_WIDTH",
    "MAZE_DESCRIPTION",
    "OFFICE_DESCRIPTION",
    "TWIN_HALL_LENGTH",
    "TWIN_WINGS_DESCRIPTION",
    "TWIN_WING_DEPTH",
    "TWIN_WING_WIDTH",
    "WAREHOUSE_DESCRIPTION",
    "Doorway",
    "build_maze",
    "build_office",
    "build_twin_wings",
    "build_warehouse",
    "horizontal_wall",
    "outline",
    "vertical_wall",
    "wall_with_openings",
]

DOOR_WIDTH = 1.0  # m, clear width of a standard doorway
TWIN_WING_WIDTH = 12.0  # m, x-extent of one wing of ``twin_wings``
TWIN_WING_DEPTH = 14.0  # m, y-extent of the ``twin_wings`` building
TWIN_HALL_LENGTH = 8.0  # m, x-extent of the hall joining the two wings

OFFICE_DESCRIPTION = "office floor: corridor, 9 rooms, open-plan area (28 x 16 m)"
WAREHOUSE_DESCRIPTION = "warehouse: 5 rows of shelving, cross aisles, loading area (32 x 20 m)"
MAZE_DESCRIPTION = "maze: 12 x 9 cells of 1.8 m with a few loops (21.6 x 16.2 m)"
TWIN_WINGS_DESCRIPTION = (
    "two identical wings joined by a hall, asymmetric only in details (32 x 14 m)"
)

Doorway = float | tuple[float, float]
"""A doorway in a wall: its centre along the wall's axis (m), or ``(centre, clear width)``."""


# --------------------------------------------------------------------------- wall kit


def wall_with_openings(
    p: Sequence[float],
    q: Sequence[float],
    openings: Sequence[tuple[float, float]] = (),
    thickness: float = DEFAULT_WALL_THICKNESS,
) -> list[FloatArray]:
    """A straight wall from ``p`` to ``q`` with gaps cut into it.

    Parameters
    ----------
    p, q : sequence of float, shape (2,)
        End points of the wall's centre line, metres.
    openings : sequence of (float, float)
        ``(distance from p to the opening's centre, clear width)``, metres. The clear
        width is measured between the faces of the wall pieces on either side (the pieces
        are :func:`thick_segment` quads, which overhang their end points by half the
        thickness).
    thickness : float
        Wall thickness, metres.

    Returns
    -------
    list of ndarray, shape (4, 2)
        One quad per solid piece; pieces shorter than a millimetre are dropped.
    """
    start = np.asarray(p, dtype=np.float64)
    end = np.asarray(q, dtype=np.float64)
    length = float(np.hypot(*(end - start)))
    if length == 0.0:
        raise ValueError(f"wall has zero length at {start.tolist()}")
    direction = (end - start) / length
    half = thickness / 2.0
    cuts = sorted((c - w / 2.0 - half, c + w / 2.0 + half) for c, w in openings)
    for (_, a_end), (b_start, _) in itertools.pairwise(cuts):
        if b_start < a_end:
            raise ValueError(f"openings overlap in the wall from {p} to {q}: {openings}")
    for lo, hi in cuts:
        if lo < -1e-9 or hi > length + 1e-9:
            raise ValueError(
                f"opening [{lo:.3f}, {hi:.3f}] m runs past the wall from {p} to {q} "
                f"(length {length:.3f} m)"
            )
    pieces = []
    position = 0.0
    for lo, hi in [*cuts, (length, length)]:
        if lo - position > 1e-3:
            pieces.append(
                thick_segment(start + direction * position, start + direction * lo, thickness)
            )
        position = hi
    return pieces


def _openings(doors: Sequence[Doorway], origin: float) -> list[tuple[float, float]]:
    result = []
    for door in doors:
        centre, width = (door, DOOR_WIDTH) if isinstance(door, int | float) else door
        result.append((float(centre) - origin, float(width)))
    return result


def horizontal_wall(
    y: float, x0: float, x1: float, doors: Sequence[Doorway] = ()
) -> list[FloatArray]:
    """Wall along ``y`` from ``x0`` to ``x1`` (m), with doorways centred at the given x."""
    return wall_with_openings((x0, y), (x1, y), _openings(doors, x0))


def vertical_wall(
    x: float, y0: float, y1: float, doors: Sequence[Doorway] = ()
) -> list[FloatArray]:
    """Wall along ``x`` from ``y0`` to ``y1`` (m), with doorways centred at the given y."""
    return wall_with_openings((x, y0), (x, y1), _openings(doors, y0))


def outline(x0: float, y0: float, x1: float, y1: float) -> list[FloatArray]:
    """Closed rectangular outer wall, metres."""
    return polyline_walls([(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)])


# --------------------------------------------------------------------------- office


def build_office(seed: int = 0) -> WorldSpec:
    """A 28 m x 16 m office floor.

    A 2 m corridor runs west to east between five offices to the north and four rooms to
    the south (a large meeting room with two doors, two offices and a corner room that
    also opens east); it ends in an open-plan area with desk clusters, a pillar and a
    glazed-in quiet room. Two of the northern offices are joined by an inner door, so
    there are loops. Robot 0 starts in the north-west office facing its door, robot 1 in
    a southern office facing north.

    Parameters
    ----------
    seed : int
        Ignored (the layout is fixed).
    """
    del seed
    width, depth = 28.0, 16.0
    corridor_south, corridor_north = 7.0, 9.0
    open_plan_west = 20.0
    walls = outline(0.0, 0.0, width, depth)
    # Corridor walls, with the doors of the rooms on either side.
    walls += horizontal_wall(
        corridor_north, 0.0, open_plan_west, doors=[3.0, 5.2, 10.0, 15.0, 17.2]
    )
    walls += horizontal_wall(corridor_south, 0.0, open_plan_west, doors=[1.5, 5.8, 8.5, 12.8, 15.4])
    # North offices: partitions at x = 4, 8.5, 11.5, 16 (4 and 8.5 joined by an inner door).
    walls += vertical_wall(4.0, corridor_north, depth, doors=[14.0])
    for x in (8.5, 11.5, 16.0):
        walls += vertical_wall(x, corridor_north, depth)
    # South rooms: partitions at x = 7, 10, 14; the corner room opens east too.
    for x in (7.0, 10.0, 14.0):
        walls += vertical_wall(x, 0.0, corridor_south)
    walls += vertical_wall(open_plan_west, 0.0, corridor_south, doors=[3.5])
    walls += vertical_wall(open_plan_west, corridor_north, depth)
    # Meeting room: a long table.
    walls.append(box(2.0, 2.6, 5.0, 3.8))
    # Open plan: two columns of desk clusters, a pillar, a quiet room in the north-east.
    for x0 in (21.6, 25.0):
        for y0 in (1.6, 4.8):
            walls.append(box(x0, y0, x0 + 1.6, y0 + 1.2))
    for x0, y0 in ((21.6, 11.0), (21.6, 14.0), (25.0, 9.6)):
        walls.append(box(x0, y0, x0 + 1.6, y0 + 1.2))
    walls.append(box(23.8, 7.8, 24.2, 8.2))
    walls += vertical_wall(24.5, 12.5, depth)
    walls += horizontal_wall(12.5, 24.5, width, doors=[26.3])
    # North offices: desks against the back wall.
    walls.append(box(0.6, 15.15, 2.4, 15.95))
    walls.append(box(12.2, 15.15, 14.0, 15.95))
    starts = [(2.0, 12.0, -math.pi / 2.0), (12.0, 3.5, math.pi / 2.0)]
    return WorldSpec.from_walls("office", walls, starts, description=OFFICE_DESCRIPTION)


# --------------------------------------------------------------------------- warehouse


def build_warehouse(seed: int = 0) -> WorldSpec:
    """A 32 m x 20 m warehouse.

    Five rows of shelving (1.2 m deep, back-to-back racks drawn as solid boxes) run east
    to west, separated by 2 m aisles and cut by two 2.1 m cross aisles, so most of the
    hall looks alike. The west end is a loading area with three dock recesses in the
    outer wall, pallets and a site office. Robot 0 starts in the loading area facing
    east, robot 1 at the far end of an aisle facing west.

    Parameters
    ----------
    seed : int
        Ignored (the layout is fixed).
    """
    del seed
    width, depth = 32.0, 20.0
    dock_depth = 1.2
    docks = [(5.0, 8.0), (10.5, 13.5), (16.0, 19.0)]  # y ranges of the dock recesses
    # Outer wall, walked counter-clockwise; the docks are recesses in the west wall.
    points: list[tuple[float, float]] = [(0.0, 0.0), (width, 0.0), (width, depth), (0.0, depth)]
    for y_low, y_high in reversed(docks):
        points += [(0.0, y_high), (-dock_depth, y_high), (-dock_depth, y_low), (0.0, y_low)]
    points.append((0.0, 0.0))
    walls = polyline_walls(points)
    # Shelving: rows of racks, cut by cross aisles.
    rack_depth, aisle_width = 1.2, 2.0
    segments_x = [(9.0, 14.6), (16.7, 22.3), (24.4, 30.0)]
    for row in range(5):
        y0 = 2.0 + row * (rack_depth + aisle_width)
        for x0, x1 in segments_x:
            walls.append(box(x0, y0, x1, y0 + rack_depth))
    # Building columns along the main aisle in the north.
    for x in (11.8, 19.5, 27.2):
        walls.append(box(x - 0.2, 17.8, x + 0.2, 18.2))
    # Site office in the south-west corner, door facing the loading area.
    walls += horizontal_wall(3.5, 0.0, 4.0)
    walls += vertical_wall(4.0, 0.0, 3.5, doors=[1.75])
    # Pallets waiting in the loading area.
    for x0, y0 in ((2.0, 6.2), (5.8, 13.0), (3.0, 13.6), (6.0, 3.0)):
        walls.append(box(x0, y0, x0 + 1.2, y0 + 1.0))
    starts = [(2.5, 10.0, 0.0), (27.0, 4.2, math.pi)]
    return WorldSpec.from_walls("warehouse", walls, starts, description=WAREHOUSE_DESCRIPTION)


# --------------------------------------------------------------------------- maze


def _carve_maze(
    rows: int, cols: int, extra_openings: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Randomised depth-first search on a cell grid, then a few extra openings for loops.

    Returns
    -------
    horizontal : ndarray of bool, shape (rows + 1, cols)
        ``horizontal[r, c]``: a wall below cell (r, c) (row r = rows is the north edge).
    vertical : ndarray of bool, shape (rows, cols + 1)
        ``vertical[r, c]``: a wall west of cell (r, c) (column c = cols is the east edge).
    """
    horizontal = np.ones((rows + 1, cols), dtype=bool)
    vertical = np.ones((rows, cols + 1), dtype=bool)
    visited = np.zeros((rows, cols), dtype=bool)
    stack = [(0, 0)]
    visited[0, 0] = True
    while stack:
        r, c = stack[-1]
        neighbours = [
            (r + dr, c + dc)
            for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if 0 <= r + dr < rows and 0 <= c + dc < cols and not visited[r + dr, c + dc]
        ]
        if not neighbours:
            stack.pop()
            continue
        nr, nc = neighbours[int(rng.integers(len(neighbours)))]
        if nr != r:
            horizontal[max(r, nr), c] = False
        else:
            vertical[r, max(c, nc)] = False
        visited[nr, nc] = True
        stack.append((nr, nc))
    # Knock out a few interior walls so that the maze has loops (as real buildings do).
    interior = [("h", r, c) for r in range(1, rows) for c in range(cols) if horizontal[r, c]]
    interior += [("v", r, c) for r in range(rows) for c in range(1, cols) if vertical[r, c]]
    for index in rng.choice(len(interior), size=extra_openings, replace=False):
        kind, r, c = interior[int(index)]
        (horizontal if kind == "h" else vertical)[r, c] = False
    return horizontal, vertical


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs ``[start, stop)`` of True in a 1-D boolean array."""
    padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
    change = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b)) for a, b in zip(change[::2], change[1::2], strict=True)]


def build_maze(seed: int = 0) -> WorldSpec:
    """A 21.6 m x 16.2 m grid maze of 1.8 m cells (1.7 m clear corridors).

    Carved by a randomised depth-first search from a fixed seed, with ten extra openings
    so that there are loops; collinear wall pieces are merged into long walls. Robot 0
    starts in the south-west cell, robot 1 in the north-east cell, each facing an open
    side of its cell.

    Parameters
    ----------
    seed : int
        Ignored (the maze is always drawn from the same internal seed).
    """
    del seed
    rows, cols, cell = 9, 12, 1.8
    horizontal, vertical = _carve_maze(rows, cols, 10, np.random.default_rng(20240611))
    walls = []
    for r in range(rows + 1):
        for a, b in _runs(horizontal[r]):
            walls.append(thick_segment((a * cell, r * cell), (b * cell, r * cell)))
    for c in range(cols + 1):
        for a, b in _runs(vertical[:, c]):
            walls.append(thick_segment((c * cell, a * cell), (c * cell, b * cell)))

    def open_headings(r: int, c: int) -> list[float]:
        headings = []
        if not vertical[r, c + 1]:
            headings.append(0.0)
        if not horizontal[r + 1, c]:
            headings.append(math.pi / 2.0)
        if not vertical[r, c]:
            headings.append(math.pi)
        if not horizontal[r, c]:
            headings.append(-math.pi / 2.0)
        return headings

    heading_0 = open_headings(0, 0)[0]
    # The opposite corner: prefer an open side that differs from robot 0's heading.
    candidates = open_headings(rows - 1, cols - 1)
    heading_1 = next((h for h in candidates if h != heading_0), heading_0 + math.pi / 2.0)
    starts = [
        (0.5 * cell, 0.5 * cell, heading_0),
        ((cols - 0.5) * cell, (rows - 0.5) * cell, heading_1),
    ]
    return WorldSpec.from_walls("maze", walls, starts, description=MAZE_DESCRIPTION)


# --------------------------------------------------------------------------- twin wings


def _wing_walls() -> list[FloatArray]:
    """One wing of ``twin_wings`` (x in [0, 12], y in [0, 14] m), open to the hall at x = 12.

    A north-south corridor (x 5-7) with three rooms to the west, two to the east and a
    lobby between them that leads to the hall through a 2 m doorway.
    """
    w, d = TWIN_WING_WIDTH, TWIN_WING_DEPTH
    walls = horizontal_wall(0.0, 0.0, w) + horizontal_wall(d, 0.0, w)
    walls += vertical_wall(0.0, 0.0, d)
    walls += vertical_wall(w, 0.0, d, doors=[(d / 2.0, 2.0)])
    # West rooms off the corridor.
    walls += vertical_wall(5.0, 0.0, d, doors=[3.0, 6.0, 12.0])
    walls += horizontal_wall(4.5, 0.0, 5.0)
    walls += horizontal_wall(9.0, 0.0, 5.0)
    # East rooms and the lobby between them (3 m wide opening onto the corridor).
    walls += vertical_wall(7.0, 0.0, 4.0, doors=[2.5])
    walls += vertical_wall(7.0, 4.0, 10.0, doors=[(7.0, 3.0)])
    walls += vertical_wall(7.0, 10.0, d, doors=[11.5])
    walls += horizontal_wall(4.0, 7.0, w)
    walls += horizontal_wall(10.0, 7.0, w, doors=[10.6])
    # Furniture that both wings share: a table in the north-west room, a sofa in the lobby.
    walls.append(box(1.5, 11.0, 3.5, 12.0))
    walls.append(box(9.5, 4.05, 11.5, 4.8))
    return walls


def build_twin_wings(seed: int = 0) -> WorldSpec:
    """Two identical wings joined by a hall: a 32 m x 14 m trap for map merging.

    The east wing is the west wing rotated by 180 degrees about the building's centre, so a
    robot in either wing sees the same rooms (a rigid motion maps one wing onto the
    other). The true alignment is only unique because of two small asymmetric details: a
    pillar in the hall (off the centre of symmetry) and a cabinet in the south-west room
    of the west wing. The robots start at symmetric poses, one in each wing, so their
    first maps are identical in their own frames.

    Parameters
    ----------
    seed : int
        Ignored (the layout is fixed).
    """
    del seed
    wing, hall, depth = TWIN_WING_WIDTH, TWIN_HALL_LENGTH, TWIN_WING_DEPTH
    width = 2.0 * wing + hall
    centre = np.array([width / 2.0, depth / 2.0])
    west = _wing_walls()
    east = [2.0 * centre - quad for quad in west]  # a half turn keeps quads counter-clockwise
    hall_south, hall_north = depth / 2.0 - 2.0, depth / 2.0 + 2.0
    walls = west + east
    walls += horizontal_wall(hall_south, wing, wing + hall)
    walls += horizontal_wall(hall_north, wing, wing + hall)
    # The asymmetric details.
    walls.append(box(wing + 2.0, hall_north - 1.2, wing + 2.4, hall_north - 0.8))
    walls.append(box(0.05, 0.6, 0.55, 1.5))
    start_west = np.array([2.5, 6.75, 0.0])
    start_east = np.array([*(2.0 * centre - start_west[:2]), math.pi])
    return WorldSpec.from_walls(
        "twin_wings", walls, [start_west, start_east], description=TWIN_WINGS_DESCRIPTION
    )
