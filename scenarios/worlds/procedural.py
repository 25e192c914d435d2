"""Seeded generator of office-like floor plans.

The layout is drawn in six steps, one function each:

1. :func:`carve_floor_plan` — a rectangular floor with a main corridor along its long axis,
   an optional open hall at one end, optional parallel and perpendicular side corridors,
   the rest cut into rooms by recursive binary space partitioning (BSP).
2. :func:`shared_walls` — the room adjacency graph: which rooms share a stretch of wall
   long enough for a door.
3. :func:`choose_openings` — a random spanning tree of that graph (Kruskal's algorithm
   with random weights that favour doors onto corridors), so every room is reachable,
   plus a few extra doors that close loops. Corridor junctions and the corridor's mouth
   into the hall are left fully open.
4. :func:`wall_quads` — every room edge becomes part of a wall line; collinear pieces are
   merged and the openings cut out, then each solid piece becomes a 0.1 m thick quad.
5. :func:`furnish` — desk clusters in halls and a desk in a corner of some rooms.
6. :func:`choose_starts` — two start poses in the centres of two rooms far apart.

All coordinates are metres on a 0.1 m lattice, with the origin at the floor's south-west
corner. The same seed always gives the same world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np

from mrslam_env.sim.world import (
    DEFAULT_WALL_THICKNESS,
    FloatArray,
    WorldSpec,
    box,
    thick_segment,
)
from mrslam_env.validation import check_fields, require

__all__ = [
    "HUGE_CONFIG",
    "LARGE_CONFIG",
    "FloorPlan",
    "Opening",
    "ProceduralConfig",
    "Room",
    "RoomKind",
    "SharedWall",
    "build_procedural",
    "build_procedural_huge",
    "build_procedural_large",
    "carve_floor_plan",
    "choose_openings",
    "choose_starts",
    "furnish",
    "generate_floor_plan",
    "shared_walls",
    "wall_quads",
]

LATTICE = 0.1  # m, every coordinate of a generated plan is a multiple of this
_EPS = 1e-6  # m, tolerance when comparing lattice coordinates


@dataclass(frozen=True, slots=True, kw_only=True)
class ProceduralConfig:
    """Parameters of the floor-plan generator (all lengths in metres)."""

    long_side: tuple[float, float] = (18.0, 28.0)
    """Range of the floor's long side."""
    short_side: tuple[float, float] = (12.0, 19.0)
    """Range of the floor's short side (clipped to the long side)."""
    corridor_width: tuple[float, float] = (1.8, 2.4)
    """Range of corridor widths."""
    min_room_side: float = 3.0
    """No room is narrower than this."""
    max_room_area: float = 32.0
    """Rooms larger than this (m^2) are always subdivided further."""
    stop_probability: float = 0.35
    """Chance that a region small enough to be a room is not subdivided further."""
    hall_probability: float = 0.5
    """Chance of an open hall at one end of the main corridor."""
    side_corridor_probability: float = 0.35
    """Chance, per strip of rooms along a corridor, of a perpendicular side corridor."""
    deep_side: float = 9.0
    """Sides of the main corridor at least this deep may get a parallel corridor."""
    parallel_corridor_probability: float = 0.8
    """Chance that a deep side gets a parallel corridor."""
    door_width: float = 1.0
    """Clear width of a door."""
    door_margin: float = 0.4
    """Minimum solid wall between a door and the end of the shared wall."""
    extra_doors: tuple[int, int] = (1, 3)
    """Inclusive range of doors added beyond the spanning tree (to make loops)."""
    wall_thickness: float = DEFAULT_WALL_THICKNESS
    """Thickness of every wall."""
    desk_size: tuple[float, float] = (1.6, 0.8)
    """Long and short side of a desk (furniture box)."""
    furniture_clearance: float = 1.2
    """Free space kept between furniture and walls (halls) or openings (rooms)."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_fields(
            self,
            positive=(
                "min_room_side",
                "max_room_area",
                "deep_side",
                "door_width",
                "wall_thickness",
            ),
            non_negative=("furniture_clearance", "door_margin"),
        )
        for attr in ("long_side", "short_side", "corridor_width"):
            low, high = getattr(self, attr)
            require(name, attr, (low, high), 0.0 < low <= high, "(low, high) with 0 < low <= high")
        for attr in (
            "stop_probability",
            "hall_probability",
            "side_corridor_probability",
            "parallel_corridor_probability",
        ):
            value = getattr(self, attr)
            require(name, attr, value, 0.0 <= value <= 1.0, "in [0, 1]")
        require(name, "desk_size", self.desk_size, min(self.desk_size) > 0.0, "positive")
        low, high = self.extra_doors
        require(
            name, "extra_doors", (low, high), 0 <= low <= high, "(low, high) with 0 <= low <= high"
        )
        require(
            name,
            "short_side",
            self.short_side,
            self.short_side[0] >= 2.0 * self.min_room_side + self.corridor_width[1],
            "at least two rooms of min_room_side and the widest corridor across",
        )

    @property
    def min_door_wall(self) -> float:
        """Shortest shared wall (centre line, m) that can hold a door."""
        return self.door_width + self.wall_thickness + 2.0 * self.door_margin


class RoomKind(Enum):
    """What a rectangle of the floor plan is used for."""

    ROOM = "room"
    CORRIDOR = "corridor"
    HALL = "hall"

    @property
    def circulation(self) -> bool:
        """Corridors and halls: spaces that join each other without doors."""
        return self is not RoomKind.ROOM


@dataclass(frozen=True, slots=True)
class Room:
    """An axis-aligned rectangle of the floor plan (wall centre lines), metres."""

    x0: float
    y0: float
    x1: float
    y1: float
    kind: RoomKind = RoomKind.ROOM

    @property
    def centre(self) -> tuple[float, float]:
        return ((self.x0 + self.x1) / 2.0, (self.y0 + self.y1) / 2.0)

    def transposed(self) -> Room:
        """The same room mirrored about the diagonal x = y."""
        return Room(self.y0, self.x0, self.y1, self.x1, self.kind)


@dataclass(frozen=True, slots=True)
class SharedWall:
    """A stretch of wall between two rooms.

    ``vertical`` walls lie on ``x = line`` and run from y = ``low`` to ``high``; horizontal
    ones lie on ``y = line`` and run in x. Metres.
    """

    first: int
    second: int
    vertical: bool
    line: float
    low: float
    high: float

    @property
    def length(self) -> float:
        return self.high - self.low


@dataclass(frozen=True, slots=True)
class Opening:
    """A gap cut into a wall line (centre-line coordinates, m): ``[low, high]`` on ``line``."""

    vertical: bool
    line: float
    low: float
    high: float


def _snap(value: float) -> float:
    return round(round(value / LATTICE) * LATTICE, 6)


# ----------------------------------------------------------------------- 1. floor plan


def _subdivide(
    x0: float, y0: float, x1: float, y1: float, rng: np.random.Generator, config: ProceduralConfig
) -> list[Room]:
    """Recursive BSP of a rectangle into rooms no narrower than ``config.min_room_side``."""
    width, height = x1 - x0, y1 - y0
    least = config.min_room_side
    can_cut_x, can_cut_y = width >= 2.0 * least, height >= 2.0 * least
    small = width * height <= config.max_room_area
    if not (can_cut_x or can_cut_y) or (small and rng.random() < config.stop_probability):
        return [Room(x0, y0, x1, y1)]
    # Halve the longer dimension most of the time, so rooms stay roughly square.
    cut_x = can_cut_x
    if can_cut_x and can_cut_y:
        cut_x = (width >= height) == (rng.random() < 0.8)
    if cut_x:
        x = _snap(rng.uniform(x0 + least, x1 - least))
        return _subdivide(x0, y0, x, y1, rng, config) + _subdivide(x, y0, x1, y1, rng, config)
    y = _snap(rng.uniform(y0 + least, y1 - least))
    return _subdivide(x0, y0, x1, y, rng, config) + _subdivide(x0, y, x1, y1, rng, config)


def _with_side_corridor(
    x0: float, y0: float, x1: float, y1: float, rng: np.random.Generator, config: ProceduralConfig
) -> list[Room]:
    """BSP rooms in a strip off a horizontal corridor, maybe split by a perpendicular
    corridor that runs across the strip."""
    width = _snap(rng.uniform(*config.corridor_width))
    least = config.min_room_side
    if x1 - x0 >= 2.0 * least + width and rng.random() < config.side_corridor_probability:
        x = _snap(rng.uniform(x0 + least, x1 - least - width))
        return [
            *_subdivide(x0, y0, x, y1, rng, config),
            Room(x, y0, _snap(x + width), y1, RoomKind.CORRIDOR),
            *_subdivide(_snap(x + width), y0, x1, y1, rng, config),
        ]
    return _subdivide(x0, y0, x1, y1, rng, config)


def _side_of_corridor(
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    main_is_north: bool,
    rng: np.random.Generator,
    config: ProceduralConfig,
) -> list[Room]:
    """Rooms on one side of the horizontal main corridor.

    A side deeper than ``config.deep_side`` gets, with ``config.parallel_corridor_probability``,
    a second corridor parallel to the main one, joined to it by a perpendicular corridor,
    so that no room lies deep inside a warren of rooms (a double-loaded corridor grid).
    """
    width = _snap(rng.uniform(*config.corridor_width))
    least = config.min_room_side
    depth = y1 - y0
    if depth >= config.deep_side and rng.random() < config.parallel_corridor_probability:
        near = _snap(rng.uniform(least, depth - least - width))  # rooms between the corridors
        if main_is_north:
            south, north = _snap(y1 - near - width), _snap(y1 - near)
            between, beyond = (north, y1), (y0, south)
        else:
            south, north = _snap(y0 + near), _snap(y0 + near + width)
            between, beyond = (y0, south), (north, y1)
        corridor = Room(x0, south, x1, north, RoomKind.CORRIDOR)
        # The strip between the corridors always has a connector; the far strip may have one.
        config_between = replace(config, side_corridor_probability=1.0)
        return [
            corridor,
            *_with_side_corridor(x0, between[0], x1, between[1], rng, config_between),
            *_with_side_corridor(x0, beyond[0], x1, beyond[1], rng, config),
        ]
    return _with_side_corridor(x0, y0, x1, y1, rng, config)


def carve_floor_plan(
    rng: np.random.Generator, config: ProceduralConfig
) -> tuple[float, float, list[Room]]:
    """Cut a rectangular floor into corridors, maybe a hall, and rooms.

    The plan is drawn with the main corridor running along x, then transposed with
    probability 1/2 so that portrait and landscape floors both occur.

    Returns
    -------
    width, depth : float
        Floor size along x and y, metres.
    rooms : list of Room
        Rectangles tiling ``[0, width] x [0, depth]``.
    """
    length = _snap(rng.uniform(*config.long_side))
    depth = _snap(rng.uniform(config.short_side[0], min(config.short_side[1], length)))
    corridor = _snap(rng.uniform(*config.corridor_width))
    least = config.min_room_side
    # An open hall at one end of the corridor, spanning the floor's full depth.
    west, east = 0.0, length
    rooms: list[Room] = []
    if rng.random() < config.hall_probability:
        hall_length = _snap(rng.uniform(least + 1.0, length / 3.0))
        if rng.random() < 0.5:
            rooms.append(Room(0.0, 0.0, hall_length, depth, RoomKind.HALL))
            west = hall_length
        else:
            east = _snap(length - hall_length)
            rooms.append(Room(east, 0.0, length, depth, RoomKind.HALL))
    y = _snap(rng.uniform(least, depth - least - corridor))
    north = _snap(y + corridor)
    rooms.append(Room(west, y, east, north, RoomKind.CORRIDOR))
    rooms += _side_of_corridor(west, 0.0, east, y, True, rng, config)
    rooms += _side_of_corridor(west, north, east, depth, False, rng, config)
    if rng.random() < 0.5:
        return depth, length, [room.transposed() for room in rooms]
    return length, depth, rooms


# ----------------------------------------------------------------------- 2. adjacency


def shared_walls(rooms: list[Room]) -> list[SharedWall]:
    """Every stretch of wall that two rooms share (positive length), in a fixed order."""
    walls = []
    for i, a in enumerate(rooms):
        for j in range(i + 1, len(rooms)):
            b = rooms[j]
            for vertical, a_lo, a_hi, b_lo, b_hi, along_a, along_b in (
                (True, a.x0, a.x1, b.x0, b.x1, (a.y0, a.y1), (b.y0, b.y1)),
                (False, a.y0, a.y1, b.y0, b.y1, (a.x0, a.x1), (b.x0, b.x1)),
            ):
                if abs(a_hi - b_lo) < _EPS:
                    line = a_hi
                elif abs(b_hi - a_lo) < _EPS:
                    line = a_lo
                else:
                    continue
                low, high = max(along_a[0], along_b[0]), min(along_a[1], along_b[1])
                if high - low > _EPS:
                    walls.append(SharedWall(i, j, vertical, line, low, high))
    return walls


# ----------------------------------------------------------------------- 3. openings


class _DisjointSets:
    """Union–find over ``n`` items, for Kruskal's algorithm."""

    def __init__(self, n: int) -> None:
        self.parent = list(range(n))

    def find(self, i: int) -> int:
        while self.parent[i] != i:
            self.parent[i] = self.parent[self.parent[i]]
            i = self.parent[i]
        return i

    def union(self, i: int, j: int) -> bool:
        """Join the sets of i and j; False when they were already one set."""
        ri, rj = self.find(i), self.find(j)
        if ri == rj:
            return False
        self.parent[ri] = rj
        return True


def _door(wall: SharedWall, rng: np.random.Generator, config: ProceduralConfig) -> Opening:
    """A door at a random place along a shared wall, ``door_margin`` clear of its ends."""
    gap = config.door_width + config.wall_thickness
    low = wall.low + config.door_margin + gap / 2.0
    high = max(wall.high - config.door_margin - gap / 2.0, low)  # equal on a shortest wall
    centre = float(np.clip(round(rng.uniform(low, high) / 0.05) * 0.05, low, high))
    return Opening(wall.vertical, wall.line, centre - gap / 2.0, centre + gap / 2.0)


def choose_openings(
    rooms: list[Room],
    walls: list[SharedWall],
    rng: np.random.Generator,
    config: ProceduralConfig,
) -> list[Opening] | None:
    """Doors along a random spanning tree of the rooms, plus a few that close loops.

    Walls between two circulation spaces (corridor or hall) are opened over their whole
    length; other walls get a door of ``config.door_width`` if they are at least
    ``config.min_door_wall`` long. Kruskal's algorithm on random weights picks the tree;
    walls onto circulation spaces weigh less, so rooms open onto corridors where they can.

    Returns
    -------
    list of Opening, or None
        None when the walls long enough for doors do not connect every room.
    """
    candidates = []
    for wall in walls:
        circulation = rooms[wall.first].kind.circulation + rooms[wall.second].kind.circulation
        if circulation == 2:
            candidates.append((-1.0, wall))
        elif wall.length >= config.min_door_wall - _EPS:
            candidates.append((float(rng.random()) + (0.0 if circulation else 1.0), wall))
    candidates.sort(key=lambda item: item[0])
    sets = _DisjointSets(len(rooms))
    openings, spare = [], []
    for weight, wall in candidates:
        joined = sets.union(wall.first, wall.second)
        if weight < 0.0:  # circulation spaces always open onto each other, loops or not
            openings.append(Opening(wall.vertical, wall.line, wall.low, wall.high))
        elif joined:
            openings.append(_door(wall, rng, config))
        else:
            spare.append(wall)
    if len({sets.find(i) for i in range(len(rooms))}) > 1:
        return None
    low, high = config.extra_doors
    count = min(int(rng.integers(low, high + 1)), len(spare))
    for index in sorted(rng.choice(len(spare), size=count, replace=False)):
        openings.append(_door(spare[int(index)], rng, config))
    return openings


# ----------------------------------------------------------------------- 4. walls


def _merge_intervals(intervals: list[tuple[float, float]]) -> list[tuple[float, float]]:
    merged: list[tuple[float, float]] = []
    for low, high in sorted(intervals):
        if merged and low <= merged[-1][1] + _EPS:
            merged[-1] = (merged[-1][0], max(merged[-1][1], high))
        else:
            merged.append((low, high))
    return merged


def _subtract(
    intervals: list[tuple[float, float]], cuts: list[tuple[float, float]]
) -> list[tuple[float, float]]:
    pieces = []
    for low, high in intervals:
        position = low
        for cut_low, cut_high in sorted(cuts):
            if cut_high <= position or cut_low >= high:
                continue
            if cut_low > position:
                pieces.append((position, cut_low))
            position = max(position, cut_high)
        if high > position:
            pieces.append((position, high))
    return [(low, high) for low, high in pieces if high - low > 1e-3]


def wall_quads(
    rooms: list[Room], openings: list[Opening], thickness: float = DEFAULT_WALL_THICKNESS
) -> list[FloatArray]:
    """Wall quads along every room edge, collinear pieces merged, openings cut out.

    Each solid piece becomes one :func:`thick_segment`, which overhangs its end points by
    half the thickness, so corners and T-junctions close and an opening of centre-line
    length g leaves ``g - thickness`` clear.
    """
    lines: dict[tuple[bool, float], list[tuple[float, float]]] = {}
    for room in rooms:
        for vertical, line, low, high in (
            (False, room.y0, room.x0, room.x1),
            (False, room.y1, room.x0, room.x1),
            (True, room.x0, room.y0, room.y1),
            (True, room.x1, room.y0, room.y1),
        ):
            lines.setdefault((vertical, round(line, 6)), []).append((low, high))
    cuts: dict[tuple[bool, float], list[tuple[float, float]]] = {}
    for opening in openings:
        key = (opening.vertical, round(opening.line, 6))
        cuts.setdefault(key, []).append((opening.low, opening.high))
    quads = []
    for (vertical, line), intervals in sorted(lines.items()):
        for low, high in _subtract(_merge_intervals(intervals), cuts.get((vertical, line), [])):
            if vertical:
                quads.append(thick_segment((line, low), (line, high), thickness))
            else:
                quads.append(thick_segment((low, line), (high, line), thickness))
    return quads


# ----------------------------------------------------------------------- 5. furniture


def _blocks_opening(quad: FloatArray, openings: list[Opening], clearance: float) -> bool:
    """Whether a box comes within ``clearance`` (m) of any opening's centre line."""
    (x0, y0), (x1, y1) = quad.min(axis=0) - clearance, quad.max(axis=0) + clearance
    for opening in openings:
        if opening.vertical:
            hit = x0 < opening.line < x1 and opening.low < y1 and opening.high > y0
        else:
            hit = y0 < opening.line < y1 and opening.low < x1 and opening.high > x0
        if hit:
            return True
    return False


def furnish(
    rooms: list[Room],
    openings: list[Opening],
    rng: np.random.Generator,
    config: ProceduralConfig,
) -> list[FloatArray]:
    """Solid furniture boxes, so that rooms are not bare rectangles to the lidar.

    Halls get a grid of desk clusters at least ``config.furniture_clearance`` from their
    walls; about half of the rooms get one desk in a corner that is at least that far from
    every opening. Room centres (where robots start) keep more than 0.5 m of clearance.
    """
    half = config.wall_thickness / 2.0
    desk_long, desk_short = config.desk_size
    gap = config.furniture_clearance
    quads = []
    for room in rooms:
        if room.kind is RoomKind.HALL:
            x0, y0 = room.x0 + half + gap, room.y0 + half + gap
            x1, y1 = room.x1 - half - gap, room.y1 - half - gap
            columns = int((x1 - x0 + gap) // (desk_long + gap))
            rows = int((y1 - y0 + gap) // (desk_short + gap))
            left = x0 + (x1 - x0 - columns * (desk_long + gap) + gap) / 2.0
            bottom = y0 + (y1 - y0 - rows * (desk_short + gap) + gap) / 2.0
            for i in range(columns):
                for j in range(rows):
                    if rng.random() < 0.25:
                        continue
                    dx, dy = left + i * (desk_long + gap), bottom + j * (desk_short + gap)
                    quads.append(box(dx, dy, dx + desk_long, dy + desk_short))
        elif room.kind is RoomKind.ROOM and rng.random() < 0.6:
            along_x = rng.random() < 0.5
            width, height = (desk_long, desk_short) if along_x else (desk_short, desk_long)
            corners = rng.permutation(4)
            for corner in corners:
                x = room.x0 + half if corner % 2 == 0 else room.x1 - half - width
                y = room.y0 + half if corner < 2 else room.y1 - half - height
                desk = box(x, y, x + width, y + height)
                if not _blocks_opening(desk, openings, gap):
                    quads.append(desk)
                    break
    return quads


# ----------------------------------------------------------------------- 6. starts


def choose_starts(rooms: list[Room], rng: np.random.Generator) -> FloatArray:
    """Two start poses at the centres of two far-apart rooms, facing different ways.

    The pair is drawn among room pairs whose centres are at least 80 % of the largest
    such distance apart; the headings differ by at least 60 degrees.

    Returns
    -------
    ndarray, shape (2, 3)
        ``(x, y, theta)`` in metres and radians.
    """
    centres = np.array([room.centre for room in rooms if room.kind is RoomKind.ROOM])
    distance = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=-1)
    first, second = np.nonzero(np.triu(distance >= 0.8 * distance.max(), k=1))
    pick = int(rng.integers(len(first)))
    heading = float(rng.uniform(-math.pi, math.pi))
    other = math.remainder(
        heading + float(rng.uniform(math.pi / 3.0, 5.0 * math.pi / 3.0)), 2 * math.pi
    )
    return np.array(
        [[*centres[first[pick]], heading], [*centres[second[pick]], other]], dtype=np.float64
    )


# ----------------------------------------------------------------------- the generator


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class FloorPlan:
    """A generated floor plan, before it is turned into a :class:`WorldSpec`.

    Attributes
    ----------
    width, depth : float
        Floor size along x and y, metres.
    rooms : tuple of Room
        Rectangles (rooms, corridors, halls) tiling ``[0, width] x [0, depth]``.
    openings : tuple of Opening
        Doors and open junctions cut into the walls.
    furniture : tuple of ndarray, shape (4, 2)
        Solid boxes, metres.
    starts : ndarray, shape (2, 3)
        Start poses ``(x, y, theta)``, metres and radians.
    """

    width: float
    depth: float
    rooms: tuple[Room, ...]
    openings: tuple[Opening, ...]
    furniture: tuple[FloatArray, ...]
    starts: FloatArray

    @property
    def room_count(self) -> int:
        """Number of rooms proper (corridors and halls not counted)."""
        return sum(room.kind is RoomKind.ROOM for room in self.rooms)


def generate_floor_plan(seed: int, config: ProceduralConfig | None = None) -> FloorPlan:
    """Draw a floor plan from ``seed`` (same seed and config, same plan).

    Parameters
    ----------
    seed : int
        Non-negative layout seed.
    config : ProceduralConfig, optional
        Generator parameters; the defaults give floors with 18–28 m long sides.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"procedural seed must be a non-negative int, got {seed!r}")
    config = config or ProceduralConfig()
    rng = np.random.default_rng(int(seed))
    # A plan whose door-sized walls leave a room unreachable is redrawn (rare).
    for _ in range(100):
        width, depth, rooms = carve_floor_plan(rng, config)
        openings = choose_openings(rooms, shared_walls(rooms), rng, config)
        if openings is not None:
            break
    else:
        raise RuntimeError(f"no connected floor plan found for seed {seed}")
    furniture = furnish(rooms, openings, rng, config)
    return FloorPlan(
        width=width,
        depth=depth,
        rooms=tuple(rooms),
        openings=tuple(openings),
        furniture=tuple(furniture),
        starts=choose_starts(rooms, rng),
    )


def build_procedural(seed: int = 0, config: ProceduralConfig | None = None) -> WorldSpec:
    """An office-like world drawn from ``seed`` (same seed, same world).

    Parameters
    ----------
    seed : int
        Non-negative layout seed.
    config : ProceduralConfig, optional
        Generator parameters.

    Returns
    -------
    WorldSpec
        Named ``procedural-<seed>``.
    """
    config = config or ProceduralConfig()
    plan = generate_floor_plan(seed, config)
    walls = wall_quads(list(plan.rooms), list(plan.openings), config.wall_thickness)
    return WorldSpec.from_walls(
        f"procedural-{seed}",
        walls + list(plan.furniture),
        plan.starts,
        description=(
            f"procedural office, seed {seed}: {plan.room_count} rooms "
            f"({plan.width:g} x {plan.depth:g} m)"
        ),
    )


LARGE_CONFIG = ProceduralConfig(long_side=(36.0, 44.0), short_side=(24.0, 30.0))
"""The generator's parameters for floors larger than the radio's range: the default
office-like plans at about twice the side (36-44 m by 24-30 m), the two starts in far-apart
rooms 25-40 m apart, two to three times the default comm range (12 m)."""


def build_procedural_large(seed: int = 0) -> WorldSpec:
    """A large office-like world drawn from ``seed`` (:data:`LARGE_CONFIG`).

    Returns
    -------
    WorldSpec
        Named ``procedural_large-<seed>``.
    """
    world = build_procedural(seed, LARGE_CONFIG)
    return replace(
        world,
        name=f"procedural_large-{seed}",
        description=world.description.replace("procedural office", "large procedural office"),
    )


HUGE_CONFIG = ProceduralConfig(long_side=(60.0, 80.0), short_side=(45.0, 60.0), extra_doors=(4, 8))
"""The generator's parameters for buildings where SLAM must close loops: the office-like
plans at 60-80 m by 45-60 m, like the large real floor plans of public SLAM data sets,
with 4 to 8 doors beyond the spanning tree, so that the corridors and rooms form loops of
tens to hundreds of metres."""


def build_procedural_huge(seed: int = 0) -> WorldSpec:
    """A huge office-like world drawn from ``seed`` (:data:`HUGE_CONFIG`).

    Returns
    -------
    WorldSpec
        Named ``procedural_huge-<seed>``.
    """
    world = build_procedural(seed, HUGE_CONFIG)
    return replace(
        world,
        name=f"procedural_huge-{seed}",
        description=world.description.replace("procedural office", "huge procedural office"),
    )
