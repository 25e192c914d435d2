"""Merge pairs cut from the real map files: the real maps' own texture, size and resolution.

The pairs of :func:`~scenarios.bench.merge.pairs.generate_pairs` are maps made by the
project's simulated SLAM in worlds built from the real maps: a few hundred cells a side,
clean walls. The pairs here are cut from the map files themselves (:mod:`scenarios.worlds.real`,
at their native resolution): ragged walls, clutter, up to the map's size (about 1,060 x 730
cells for ``aws_warehouse`` at 0.02 m), the maps outside users bring.

A pair
------
Map 1 is a window (a rectangle of cells) of a map's known box, in the map file's frame.
Map 2 is a second window of the same map, turned by a uniformly random angle (any, by
default: :attr:`CutConfig.max_turn_deg`) about a uniformly random point of the window and
re-rasterised into the turned frame ``F2`` (:func:`turned_grid`: nearest cell, UNKNOWN
outside, the centres of the window's occupied cells marked occupied where they land, and
the midpoints of 8-adjacent ones that would fall apart, so that no thin wall breaks). So
the truth is exact: ``map1_from_map2 = file_from_F2``. Window sides are uniform fractions
(:attr:`CutConfig.side_fraction`) of the known box's sides, at least
:attr:`CutConfig.large_side` (800) cells along a side longer than that and at most
:attr:`CutConfig.max_side` cells.

The overlap is computed on the map file's lattice before the turn, where it is exact:
known cells (FREE or OCCUPIED) in both windows over the smaller window's known cells (the
definition of :func:`~mrslam_env.evaluation.true_overlap`). Overlapping pairs fill the
overlap bins in turn, map after map (windows drawn until the overlap falls in the slot's
bin). Two kinds of pairs have no overlap:

``disjoint``        two windows on either side of a cut across the known box (overlap 0);
``other-building``  windows of two different buildings (``aws_warehouse`` and
                    ``aws_warehouse_lowres`` are the same building); the scenario label is
                    ``cut:<building1>+<building2>``, the stored truth is meaningless and
                    any transform returned is wrong.

Pairs are saved like the simulated ones (ROS map files and ``manifest.json``,
:func:`~scenarios.bench.merge.pairs.load_pairs`) in ``<cache>/<key>/`` with the key
``cuts-v<CUT_VERSION>-n<pairs>-seed<seed>-<digest of the config and the map files>``.
Scenario labels are ``cut:<building>`` (family ``real``,
:func:`~scenarios.bench.merge.pairs.world_family`).
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mrslam_env.geometry import inverse, transform_points
from mrslam_env.gridmap import OCCUPIED, UNKNOWN, GridMap, grid_in_frame
from mrslam_env.mapio import load_map
from mrslam_env.validation import check_fields, require
from scenarios.bench.merge.pairs import (
    DEFAULT_CACHE,
    MergePair,
    _file_digest,
    load_pairs,
    save_pair,
    write_manifest,
)
from scenarios.worlds.real import REAL_BUILDINGS

FloatArray = NDArray[np.float64]

__all__ = [
    "CUT_BUILDINGS",
    "CUT_PREFIX",
    "CUT_VERSION",
    "CutConfig",
    "generate_cut_pairs",
    "load_or_generate_cut_pairs",
    "turned_grid",
]

CUT_VERSION = 1
"""Bump when cutting changes, so cached cut pairs are rebuilt."""

CUT_PREFIX = "cut:"
"""Scenario label of a cut pair: ``cut:<building>`` (``cut:<b1>+<b2>`` for two buildings)."""

CUT_BUILDINGS = tuple(REAL_BUILDINGS)
"""The six real maps (:data:`scenarios.worlds.real.REAL_BUILDINGS`), the default sources."""

SAME_BUILDING = {"aws_warehouse_lowres": "aws_warehouse"}
"""Maps of one building under two names (never paired as ``other-building``)."""

Window = tuple[int, int, int, int]
"""Rows ``[r0, r1)`` and columns ``[c0, c1)`` of a map's cells."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CutConfig:
    """How cut pairs are made (module docstring)."""

    n_pairs: int = 24
    """Pairs in the set (overlapping and without overlap)."""
    seed: int = 0
    """Seeds every window, angle and pivot."""
    buildings: tuple[str, ...] = CUT_BUILDINGS
    """Real buildings (:mod:`scenarios.worlds.real`) to cut from; pairs go to them in turn."""
    overlap_bins: tuple[float, ...] = (0.2, 0.35, 0.5, 0.65, 0.85)
    """Edges of the overlap bins the overlapping pairs fill in turn (those of
    :class:`~scenarios.bench.merge.pairs.PairGenerationConfig`)."""
    disjoint_fraction: float = 0.125
    """Share of the pairs that are two disjoint windows of one map."""
    other_building_fraction: float = 0.125
    """Share of the pairs whose windows come from two different buildings."""
    side_fraction: tuple[float, float] = (0.5, 1.0)
    """A window side is a uniform fraction in this range of the known box's side."""
    max_side: int = 1250
    """Longest window side, cells."""
    large_side: int = 800
    """Along a known box side longer than this, window sides are at least this long, cells
    (the sizes the issue's speed target names, where a map is that large)."""
    max_turn_deg: float = 180.0
    """Map 2 is turned by a uniform angle in [-this, this), degrees (180: any angle)."""
    min_known_area: float = 4.0
    """Windows knowing less than this are drawn again, m²."""
    tries: int = 4000
    """Window pairs drawn for one slot before it is left empty (a shortfall)."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_fields(self, counts=("n_pairs", "max_side", "large_side", "tries"))
        check_fields(self, non_negative=("min_known_area",))
        turn = self.max_turn_deg
        require(name, "max_turn_deg", turn, 0.0 <= turn <= 180.0, "in [0, 180]")
        require(name, "buildings", self.buildings, len(self.buildings) > 0, "one name or more")
        unknown = [b for b in self.buildings if b not in REAL_BUILDINGS]
        require(name, "buildings", self.buildings, not unknown, f"in {', '.join(REAL_BUILDINGS)}")
        edges = self.overlap_bins
        ok = len(edges) >= 2 and list(edges) == sorted(set(edges)) and edges[0] > 0
        require(
            name, "overlap_bins", edges, ok and edges[-1] <= 1, ">= 2 increasing edges in (0, 1]"
        )
        share = self.disjoint_fraction + self.other_building_fraction
        for field_name in ("disjoint_fraction", "other_building_fraction"):
            value = getattr(self, field_name)
            require(name, field_name, value, 0.0 <= value <= 1.0, "in [0, 1]")
        require(name, "other_building_fraction", share, share <= 1.0, "<= 1 with disjoint_fraction")
        low, high = self.side_fraction
        require(
            name, "side_fraction", self.side_fraction, 0 < low <= high <= 1, "0 < low <= high <= 1"
        )

    def cache_key(self) -> str:
        """Folder name of this configuration's cached pairs (the map files' digests are part
        of it: another file under the same name is another set)."""
        from scenarios.worlds.real import map_file

        fields = asdict(self)
        fields["map_digests"] = [_file_digest(map_file(name)) for name in self.buildings]
        text = json.dumps({"version": CUT_VERSION, **fields}, sort_keys=True)
        digest = hashlib.sha1(text.encode()).hexdigest()[:10]
        return f"cuts-v{CUT_VERSION}-n{self.n_pairs}-seed{self.seed}-{digest}"


def turned_grid(grid: GridMap, frame_from_grid: FloatArray) -> GridMap:
    """``grid`` re-rasterised in another frame at its resolution: the nearest-cell picture
    (:func:`~mrslam_env.gridmap.grid_in_frame`; UNKNOWN outside the grid), with walls kept
    whole: the centre of every occupied cell of ``grid`` is marked OCCUPIED in the cell it
    lands in, and so is the midpoint of two 8-adjacent occupied cells whose centres land in
    cells that are not 8-adjacent.

    Nearest-cell resampling alone breaks a thin wall that runs diagonally (a staircase of
    cells touching at their corners) and can drop a lone occupied cell. Marked this way,
    every occupied cell moved by ``frame_from_grid`` lands on an occupied cell and walls
    8-connected in ``grid`` stay 8-connected (a midpoint is less than one cell from both
    centres). A lattice-exact transform (whole cells, quarter turns) adds nothing."""
    turned = grid_in_frame(grid, frame_from_grid)
    occupied = grid.cells == OCCUPIED
    cells = turned.cells.copy()

    def landing(at: FloatArray) -> NDArray[np.int64]:
        """Cells of ``turned`` under the (fractional) cell positions ``at`` of ``grid``."""
        return turned.world_to_cell(transform_points(frame_from_grid, grid.cell_to_world(at)))

    def mark(index: NDArray[np.int64]) -> None:
        inside = turned.contains(index)
        cells[index[inside, 0], index[inside, 1]] = OCCUPIED

    mark(landing(np.argwhere(occupied).astype(np.float64)))
    rows, cols = occupied.shape
    for d_row, d_col in ((0, 1), (1, 0), (1, 1), (1, -1)):
        low, high = max(-d_col, 0), max(d_col, 0)
        first = np.argwhere(
            occupied[: rows - d_row, low : cols - high] & occupied[d_row:, high : cols - low]
        )
        first[:, 1] += low
        start = first.astype(np.float64)
        step = np.array([d_row, d_col], dtype=np.float64)
        apart = np.abs(landing(start) - landing(start + step)).max(axis=1, initial=0) > 1
        mark(landing(start[apart] + step / 2))
    return GridMap(cells=cells, resolution=turned.resolution, origin=turned.origin)


def _window_grid(grid: GridMap, window: Window) -> GridMap:
    """The cells of ``window`` as a grid in ``grid``'s frame."""
    r0, r1, c0, c1 = window
    origin = (grid.origin[0] + c0 * grid.resolution, grid.origin[1] + r0 * grid.resolution)
    return GridMap(cells=grid.cells[r0:r1, c0:c1].copy(), resolution=grid.resolution, origin=origin)


class _Source:
    """One map file: its grid, known box and a summed-area table of its known cells."""

    def __init__(self, name: str) -> None:
        from scenarios.worlds.real import map_file

        self.name = name
        self.grid = load_map(map_file(name))
        known = self.grid.cells != UNKNOWN
        self.table = np.zeros((known.shape[0] + 1, known.shape[1] + 1), dtype=np.int64)
        self.table[1:, 1:] = known.cumsum(0).cumsum(1)
        rows, cols = np.flatnonzero(known.any(1)), np.flatnonzero(known.any(0))
        if len(rows) == 0:
            raise ValueError(f"map {name!r} has no known cell")
        self.box: Window = (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)
        self.min_known = 0  # set by the generator (cells)

    def known(self, window: Window) -> int:
        r0, r1, c0, c1 = window
        if r1 <= r0 or c1 <= c0:
            return 0
        t = self.table
        return int(t[r1, c1] - t[r0, c1] - t[r1, c0] + t[r0, c0])

    def overlap(self, a: Window, b: Window) -> float:
        both = (max(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), min(a[3], b[3]))
        smaller = min(self.known(a), self.known(b))
        return 0.0 if smaller == 0 else self.known(both) / smaller

    def window(
        self, rng: np.random.Generator, config: CutConfig, span: Window | None = None
    ) -> Window:
        """A random window inside ``span`` (default: the known box), sides drawn as
        :attr:`CutConfig.side_fraction` of ``span``'s, at least
        :attr:`CutConfig.large_side` along a side longer than that."""
        r0, r1, c0, c1 = span if span is not None else self.box
        low, high = config.side_fraction
        sides = []
        for length in (r1 - r0, c1 - c0):
            shortest = low * length
            if length > config.large_side:
                shortest = max(shortest, config.large_side)
            side = round(rng.uniform(shortest, max(shortest, high * length)))
            sides.append(int(min(max(side, 1), config.max_side, length)))
        top = r0 + int(rng.integers(0, r1 - r0 - sides[0] + 1))
        left = c0 + int(rng.integers(0, c1 - c0 - sides[1] + 1))
        return (top, top + sides[0], left, left + sides[1])

    def big_enough(self, window: Window) -> bool:
        return self.known(window) >= self.min_known


def _slot_plan(config: CutConfig) -> list[tuple[int, str, int]]:
    """(building index, kind, bin) per pair: buildings in turn; the disjoint and
    other-building slots evenly spaced; each building cycling through the overlap bins."""
    n, n_sources = config.n_pairs, len(config.buildings)
    kinds = ["overlap"] * n
    for kind, share, phase in (
        ("disjoint", config.disjoint_fraction, 0.25),
        ("other-building", config.other_building_fraction, 0.75),
    ):
        count = round(n * share)
        for k in range(count):
            slot = math.floor((k + phase) * n / count) % n
            while kinds[slot] != "overlap":
                slot = (slot + 1) % n
            kinds[slot] = kind
    next_bin = list(range(n_sources))
    n_bins = len(config.overlap_bins) - 1
    plan = []
    for slot, kind in enumerate(kinds):
        source = slot % n_sources
        plan.append((source, kind, next_bin[source] % n_bins))
        if kind == "overlap":
            next_bin[source] += 1
    return plan


def _overlap_windows(
    source: _Source, config: CutConfig, rng: np.random.Generator, low: float, high: float
) -> tuple[Window, Window, float] | None:
    for _ in range(config.tries):
        a, b = source.window(rng, config), source.window(rng, config)
        if not (source.big_enough(a) and source.big_enough(b)):
            continue
        overlap = source.overlap(a, b)
        if low <= overlap < high:
            return a, b, overlap
    return None


def _disjoint_windows(
    source: _Source, config: CutConfig, rng: np.random.Generator
) -> tuple[Window, Window] | None:
    """Two windows on either side of a cut across the known box (across its longer side)."""
    r0, r1, c0, c1 = source.box
    for _ in range(config.tries):
        if r1 - r0 > c1 - c0:
            cut = r0 + round((r1 - r0) * rng.uniform(0.4, 0.6))
            spans = [(r0, cut, c0, c1), (cut, r1, c0, c1)]
        else:
            cut = c0 + round((c1 - c0) * rng.uniform(0.4, 0.6))
            spans = [(r0, r1, c0, cut), (r0, r1, cut, c1)]
        a, b = (source.window(rng, config, span) for span in spans)
        if source.big_enough(a) and source.big_enough(b):
            return (a, b) if rng.random() < 0.5 else (b, a)
    return None


def _building(name: str) -> str:
    return SAME_BUILDING.get(name, name)


def generate_cut_pairs(
    config: CutConfig, out_dir: Path, *, progress: Callable[[str], None] | None = None
) -> list[MergePair]:
    """Cut the pairs (module docstring) and save them (maps + ``manifest.json``)."""
    started = time.perf_counter()
    sources = [_Source(name) for name in config.buildings]
    for source in sources:
        source.min_known = math.ceil(config.min_known_area / source.grid.resolution**2)
    rng = np.random.default_rng([config.seed, 0xC075])
    edges = config.overlap_bins
    out_dir.mkdir(parents=True, exist_ok=True)
    pairs: list[MergePair] = []
    entries: list[dict[str, Any]] = []
    shortfall = 0
    for slot, (index, kind, wanted) in enumerate(_slot_plan(config)):
        first = second = sources[index]
        overlap = 0.0
        if kind == "overlap":
            found = _overlap_windows(first, config, rng, edges[wanted], edges[wanted + 1])
            if found is None:
                shortfall += 1
                continue
            window1, window2, overlap = found
        elif kind == "disjoint":
            split = _disjoint_windows(first, config, rng)
            if split is None:
                shortfall += 1
                continue
            window1, window2 = split
        else:
            others = [s for s in sources if _building(s.name) != _building(first.name)]
            if not others:
                shortfall += 1
                continue
            second = others[int(rng.integers(len(others)))]
            window1 = window2 = (0, 0, 0, 0)
            for _ in range(config.tries):
                window1, window2 = first.window(rng, config), second.window(rng, config)
                if first.big_enough(window1) and second.big_enough(window2):
                    break
            else:
                shortfall += 1
                continue
        m1 = _window_grid(first.grid, window1)
        cut2 = _window_grid(second.grid, window2)
        turn = math.radians(config.max_turn_deg)
        angle = float(rng.uniform(-turn, turn))
        xmin, ymin, xmax, ymax = cut2.extent
        pivot = np.array([rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)])
        c, s = math.cos(angle), math.sin(angle)
        turned_from_file = np.array(
            [
                pivot[0] - (c * pivot[0] - s * pivot[1]),
                pivot[1] - (s * pivot[0] + c * pivot[1]),
                angle,
            ]
        )
        m2 = turned_grid(cut2, turned_from_file)
        truth = inverse(turned_from_file)
        label = first.name if second is first else f"{first.name}+{second.name}"
        scenario = CUT_PREFIX + label
        pair_id = f"{slot:03d}-cut-{label}"
        info = {
            "kind": kind,
            "source1": first.name,
            "source2": second.name,
            "window1": list(window1),
            "window2": list(window2),
            "turn_deg": math.degrees(angle),
            "pivot": pivot.tolist(),
        }
        pair = MergePair(
            pair_id=pair_id,
            scenario=scenario,
            m1=m1,
            m2=m2,
            map1_from_map2=truth,
            overlap=overlap,
            info=info,
        )
        pairs.append(pair)
        entries.append(save_pair(out_dir, pair))
        if progress is not None:
            progress(f"cut {pair_id}: {kind}, overlap {overlap:.2f}, {m2.shape[1]}x{m2.shape[0]}")
    write_manifest(out_dir, CUT_VERSION, asdict(config), started, shortfall, entries)
    return pairs


def load_or_generate_cut_pairs(
    config: CutConfig,
    cache: Path = DEFAULT_CACHE,
    *,
    regenerate: bool = False,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[MergePair], dict[str, Any]]:
    """The cached cut pairs of this configuration, cut first when missing (or when
    ``regenerate``)."""
    folder = Path(cache) / config.cache_key()
    if regenerate or not (folder / "manifest.json").exists():
        if progress is not None:
            progress(f"cutting {config.n_pairs} pairs into {folder}")
        generate_cut_pairs(config, folder, progress=progress)
    return load_pairs(folder)
