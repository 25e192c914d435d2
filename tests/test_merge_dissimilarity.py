"""Dissimilarity psi, distance maps and acceptance index (mrslam_env.merge.dissimilarity).

Oracles: the L1 distance maps against a brute-force minimum over all cells; psi (both
variants, every map placement, free-cell subsampling) against a brute-force evaluation of
the paper's eq. 12 that knows nothing of distance maps or clamping. Invariants: psi is 0
for a map against itself, symmetric under swapping the maps, unchanged when a grid's
origin moves and the transform compensates; on a realistic pair of partial maps the
overlap-restricted psi has its minimum at the true transform and grows with the offset,
where the paper's psi over all cells does not.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from merge_fixtures import map_pair

from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.merge.dissimilarity import (
    SIDE_BINS,
    SIDE_DISTANCE_CAP,
    Agreement,
    DissimilarityConfig,
    acceptance_index,
    dissimilarity,
    distance_maps,
)

TRUTH = np.array([1.0, 2.0, 1.2])
EXACT = DissimilarityConfig(max_free_cells=10**9)
EXACT_ALL = DissimilarityConfig(restrict_to_overlap=False, max_free_cells=10**9)


def random_grid(
    rng: np.random.Generator,
    shape: tuple[int, int],
    *,
    p: tuple[float, float, float] = (0.4, 0.2, 0.4),
    resolution: float = 0.1,
    origin: tuple[float, float] = (0.0, 0.0),
) -> GridMap:
    """Random trinary cells with probabilities (free, occupied, unknown)."""
    cells = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], dtype=np.int8), size=shape, p=p)
    return GridMap(cells=cells, resolution=resolution, origin=origin)


def brute_force_l1(mask: np.ndarray, sentinel: int) -> np.ndarray:
    sources = np.argwhere(mask)
    if len(sources) == 0:
        return np.full(mask.shape, sentinel)
    cells = np.argwhere(np.ones_like(mask))
    distance = np.abs(cells[:, None, :] - sources[None, :, :]).sum(axis=-1).min(axis=1)
    return distance.reshape(mask.shape)


def wall_side(grid: GridMap, iy: int, ix: int) -> float | None:
    """Direction (rad) of the sum of the offsets from an occupied cell to its free
    8-neighbours, None if there is none (or they cancel)."""
    sx = sy = 0
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            y, x = iy + dy, ix + dx
            inside = 0 <= y < grid.shape[0] and 0 <= x < grid.shape[1]
            if (dx or dy) and inside and grid.cells[y, x] == FREE:
                sx, sy = sx + dx, sy + dy
    return math.atan2(sy, sx) if (sx or sy) else None


def side_bin(angle: float) -> int:
    return math.floor(angle / (2 * math.pi / SIDE_BINS) + 0.5) % SIDE_BINS


def brute_force_psi(
    m1: GridMap,
    m2: GridMap,
    map1_from_map2: np.ndarray,
    *,
    restrict: bool,
    stride=(1, 1),
    sides: bool = False,
) -> float:
    """Eq. 11–12 straight from the definition: for each class-c cell of one map, the L1
    distance (in cells, between integer cell indices, possibly outside the grid) from the
    cell under its image to every class-c cell of the other map. With ``sides``, an
    occupied cell with a side only to the occupied cells whose side bin (in the other
    map's frame) is within one of its own, or which have no side, and at most
    SIDE_DISTANCE_CAP."""

    def directed(a: GridMap, b: GridMap, b_from_a: np.ndarray, free_stride: int):
        means, count = [], 0
        for value, step in ((FREE, free_stride), (OCCUPIED, 1)):
            cells = np.argwhere(a.cells == value)[::step]
            if len(cells) == 0:
                continue
            targets = b.world_to_cell(transform_points(b_from_a, a.cell_to_world(cells)))
            sources = np.argwhere(b.cells == value)
            if restrict:
                keep = b.contains(targets)
                keep[keep] = b.cells[targets[keep, 0], targets[keep, 1]] != UNKNOWN
                cells, targets = cells[keep], targets[keep]
            count += len(targets)
            if len(targets) == 0:
                continue
            if len(sources) == 0:
                means.append(float(sum(b.shape)))
                continue
            d = np.abs(targets[:, None, :] - sources[None, :, :]).sum(axis=-1)
            nearest = d.min(axis=1)
            if sides and value == OCCUPIED:
                source_sides = [wall_side(b, *cell) for cell in sources]
                for k, cell in enumerate(cells):
                    side = wall_side(a, *cell)
                    if side is None:
                        continue
                    want = side_bin(side + b_from_a[2])
                    near = [
                        other is None or (side_bin(other) - want) % SIDE_BINS in (0, 1, 7)
                        for other in source_sides
                    ]
                    nearest[k] = min(d[k, near].min(initial=sum(b.shape)), SIDE_DISTANCE_CAP)
            means.append(float(nearest.mean()))
        return sum(means), count

    forward, count1 = directed(m1, m2, inverse(map1_from_map2), stride[0])
    backward, count2 = directed(m2, m1, map1_from_map2, stride[1])
    if restrict and min(count1, count2) == 0:
        return math.inf
    return forward + backward


@pytest.fixture(scope="module")
def office_pair() -> tuple[GridMap, GridMap]:
    return map_pair("office", (5, 4), (9, 4), TRUTH)


# --- distance maps -----------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (6, 1), (9, 13), (17, 11)])
def test_distance_maps_match_brute_force_l1(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(sum(shape))
    for p in ((0.4, 0.2, 0.4), (0.05, 0.05, 0.9), (0.9, 0.05, 0.05)):
        grid = random_grid(rng, shape, p=p)
        if not (grid.free.any() or grid.occupied.any()):
            continue
        maps = distance_maps(grid)
        sentinel = shape[0] + shape[1]
        assert maps.sentinel == sentinel
        np.testing.assert_array_equal(maps.free, brute_force_l1(grid.free, sentinel))
        np.testing.assert_array_equal(maps.occupied, brute_force_l1(grid.occupied, sentinel))
        np.testing.assert_array_equal(maps.known, grid.free | grid.occupied)
        np.testing.assert_array_equal(maps.free_cells, np.argwhere(grid.free))
        np.testing.assert_array_equal(maps.occupied_cells, np.argwhere(grid.occupied))


def test_distance_map_of_a_single_cell_is_the_l1_diamond() -> None:
    cells = np.full((7, 9), UNKNOWN, dtype=np.int8)
    cells[3, 4] = OCCUPIED
    maps = distance_maps(GridMap(cells=cells, resolution=0.05))
    rows, cols = np.mgrid[0:7, 0:9]
    np.testing.assert_array_equal(maps.occupied, np.abs(rows - 3) + np.abs(cols - 4))
    assert np.all(maps.free == 7 + 9)  # no free cell: the sentinel everywhere


def test_distance_maps_do_not_mutate_the_grid() -> None:
    grid = random_grid(np.random.default_rng(0), (8, 8))
    before = grid.cells.copy()
    distance_maps(grid)
    np.testing.assert_array_equal(grid.cells, before)


# --- psi against the definition ---------------------------------------------------------


@pytest.mark.parametrize("restrict", [True, False])
def test_psi_matches_the_definition_for_random_placements(restrict: bool) -> None:
    rng = np.random.default_rng(7)
    config = EXACT if restrict else EXACT_ALL
    for trial in range(12):
        # Grids roughly centred on their frame origins, so every rotation overlaps them.
        m1 = random_grid(rng, (14, 19), origin=tuple(rng.uniform(-0.3, 0.3, 2) - [0.95, 0.7]))
        m2 = random_grid(rng, (17, 12), origin=tuple(rng.uniform(-0.3, 0.3, 2) - [0.6, 0.85]))
        transform = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(-np.pi, np.pi)])
        if trial == 0:
            transform[:] = 0.0
        expected = brute_force_psi(m1, m2, transform, restrict=restrict)
        got = dissimilarity(m1, m2, transform, config=replace_min_overlap(config))
        assert math.isfinite(expected)
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-12)


def replace_min_overlap(config: DissimilarityConfig) -> DissimilarityConfig:
    return DissimilarityConfig(
        restrict_to_overlap=config.restrict_to_overlap,
        max_free_cells=config.max_free_cells,
        min_overlap_cells=1,
        wall_sides=config.wall_sides,
    )


@pytest.mark.parametrize("restrict", [True, False])
def test_psi_with_wall_sides_matches_the_definition(restrict: bool) -> None:
    rng = np.random.default_rng(17)
    config = DissimilarityConfig(
        restrict_to_overlap=restrict, max_free_cells=10**9, min_overlap_cells=1, wall_sides=True
    )
    for _ in range(8):
        m1 = random_grid(rng, (14, 19), p=(0.5, 0.3, 0.2), origin=(-0.95, -0.7))
        m2 = random_grid(rng, (17, 12), p=(0.5, 0.3, 0.2), origin=(-0.6, -0.85))
        transform = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(-np.pi, np.pi)])
        expected = brute_force_psi(m1, m2, transform, restrict=restrict, sides=True)
        plain = brute_force_psi(m1, m2, transform, restrict=restrict)
        assert expected != pytest.approx(plain)  # the side test matters on these grids
        got = dissimilarity(m1, m2, transform, config=config)
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_psi_with_wall_sides_charges_the_sentinel_against_a_map_without_walls() -> None:
    """With no wall in the other map there is no side to match: the sentinel, as in plain
    psi, not the side cap."""
    rng = np.random.default_rng(5)
    walls = random_grid(rng, (12, 12), p=(0.5, 0.3, 0.2))
    open_floor = random_grid(rng, (12, 12), p=(0.8, 0.0, 0.2))
    transform = np.array([0.1, -0.05, 0.2])
    for restrict in (True, False):
        plain, sides = (
            DissimilarityConfig(
                restrict_to_overlap=restrict,
                wall_sides=s,
                max_free_cells=10**9,
                min_overlap_cells=1,
            )
            for s in (False, True)
        )
        with_sides = dissimilarity(walls, open_floor, transform, config=sides)
        assert with_sides == dissimilarity(walls, open_floor, transform, config=plain)
        if restrict:
            expected = brute_force_psi(walls, open_floor, transform, restrict=True, sides=True)
            assert with_sides == pytest.approx(expected, rel=1e-12)


def thick_wall_pair(seen_from: str) -> GridMap:
    """A wall 3 cells thick (0.05 m cells) below a corridor with a box in it. The map
    knows the corridor and the side of the wall ``seen_from``, and of the wall only that
    face. The right map saw half of the corridor's top wall a cell higher (the noise that
    keeps psi above 0 at the truth)."""
    cells = np.full((120, 120), UNKNOWN, dtype=np.int8)
    cells[5:116, 10:111] = FREE
    cells[116, 10:111] = OCCUPIED
    cells[104:107, 30:33] = OCCUPIED
    cells[5:100, 58:61] = OCCUPIED
    if seen_from == "left":
        cells[:100, 59:] = UNKNOWN
    else:
        cells[:100, :60] = UNKNOWN
        cells[116, 60:111] = FREE
        cells[117, 60:111] = OCCUPIED
    return GridMap(cells=cells, resolution=0.05)


def test_wall_sides_keep_a_wall_seen_from_its_two_sides_where_it_is() -> None:
    """One map saw a thick wall's left face, the other its right face: plain psi is
    least with the faces laid over each other (a wall's thickness off), psi with wall
    sides at the truth."""
    left, right = thick_wall_pair("left"), thick_wall_pair("right")
    shifts = range(-4, 5)

    def best_shift(config: DissimilarityConfig) -> int:
        d1 = distance_maps(left, sides=config.wall_sides)
        d2 = distance_maps(right, sides=config.wall_sides)
        costs = [
            dissimilarity(
                left, right, [0.05 * k, 0.0, 0.0], distances1=d1, distances2=d2, config=config
            )
            for k in shifts
        ]
        return list(shifts)[int(np.argmin(costs))]

    assert best_shift(DissimilarityConfig()) == -2
    assert best_shift(DissimilarityConfig(wall_sides=True)) == 0


def test_psi_faithful_charges_cells_far_outside_the_other_grid_their_exact_distance() -> None:
    rng = np.random.default_rng(3)
    m1 = random_grid(rng, (9, 9))
    m2 = random_grid(rng, (9, 9))
    far = np.array([5.0, -3.0, 0.4])  # the maps do not overlap at all
    expected = brute_force_psi(m1, m2, far, restrict=False)
    assert dissimilarity(m1, m2, far, config=EXACT_ALL) == pytest.approx(expected, rel=1e-12)
    assert math.isinf(dissimilarity(m1, m2, far))  # restricted: nothing overlaps


def test_free_cell_subsampling_is_a_regular_stride() -> None:
    rng = np.random.default_rng(11)
    m1 = random_grid(rng, (30, 30), p=(0.7, 0.1, 0.2))
    m2 = random_grid(rng, (30, 30), p=(0.7, 0.1, 0.2))
    transform = np.array([0.2, -0.1, 0.3])
    config = DissimilarityConfig(max_free_cells=100, min_overlap_cells=1)
    stride1 = -(-np.count_nonzero(m1.free) // 100)
    stride2 = -(-np.count_nonzero(m2.free) // 100)
    assert stride1 > 1 and stride2 > 1
    expected = brute_force_psi(m1, m2, transform, restrict=True, stride=(stride1, stride2))
    assert dissimilarity(m1, m2, transform, config=config) == pytest.approx(expected, rel=1e-12)


# --- psi invariants ------------------------------------------------------------------------


def test_psi_of_a_map_with_itself_is_zero(office_pair) -> None:
    m1, _ = office_pair
    assert dissimilarity(m1, m1, np.zeros(3)) == 0.0
    assert dissimilarity(m1, m1, np.zeros(3), config=EXACT_ALL) == 0.0


def test_psi_is_symmetric_under_swapping_the_maps(office_pair) -> None:
    m1, m2 = office_pair
    for offset in ([0.0, 0.0, 0.0], [0.2, -0.1, 0.05]):
        transform = TRUTH + offset
        forward = dissimilarity(m1, m2, transform)
        backward = dissimilarity(m2, m1, inverse(transform))
        assert forward == pytest.approx(backward, rel=1e-9)


def test_psi_honours_grid_origins(office_pair) -> None:
    m1, m2 = office_pair
    shift = np.array([0.731, -1.29])
    moved = GridMap(cells=m2.cells, resolution=m2.resolution, origin=tuple(m2.origin + shift))
    # A point p of moved grid's frame is p - shift in m2's frame.
    compensated = compose(TRUTH, [-shift[0], -shift[1], 0.0])
    for config in (EXACT, EXACT_ALL):
        assert dissimilarity(m1, moved, compensated, config=config) == pytest.approx(
            dissimilarity(m1, m2, TRUTH, config=config), rel=1e-9
        )


def test_precomputed_distance_maps_give_the_same_psi(office_pair) -> None:
    m1, m2 = office_pair
    d1, d2 = distance_maps(m1), distance_maps(m2)
    transform = TRUTH + np.array([0.1, 0.05, -0.02])
    assert dissimilarity(m1, m2, transform, distances1=d1, distances2=d2) == dissimilarity(
        m1, m2, transform
    )


def test_psi_is_least_at_the_true_transform_and_grows_with_offset(office_pair) -> None:
    m1, m2 = office_pair
    d1, d2 = distance_maps(m1), distance_maps(m2)

    def psi(offset) -> float:
        return dissimilarity(m1, m2, TRUTH + offset, distances1=d1, distances2=d2)

    at_truth = psi([0.0, 0.0, 0.0])
    assert at_truth < 1.0  # under one cell on average per term sum
    # A local minimum over a grid of offsets (one cell and half a degree apart).
    for dx in np.arange(-0.25, 0.26, 0.05):
        for dy in np.arange(-0.25, 0.26, 0.05):
            for dtheta in np.radians([-3.0, -1.0, -0.5, 0.0, 0.5, 1.0, 3.0]):
                if abs(dx) + abs(dy) + abs(dtheta) > 1e-9:
                    assert psi([dx, dy, dtheta]) > at_truth
    # Growing along rays in x, y and theta.
    for direction in ([1, 0, 0], [0, -1, 0], [0.7, 0.7, 0], [0, 0, 0.1], [0, 0, -0.1]):
        values = [psi(np.multiply(direction, step)) for step in (0.0, 0.1, 0.2, 0.4)]
        assert np.all(np.diff(values) > 0), values


def test_faithful_psi_is_biased_on_partial_maps(office_pair) -> None:
    """Why the overlap-restricted psi is the default: over all cells, the parts of each
    map the other never saw dominate psi, and the truth is not even a local minimum."""
    m1, m2 = office_pair
    faithful = DissimilarityConfig(restrict_to_overlap=False)
    at_truth = dissimilarity(m1, m2, TRUTH, config=faithful)
    shifted = dissimilarity(m1, m2, TRUTH + np.array([-0.15, 0.0, 0.0]), config=faithful)
    assert shifted < at_truth
    assert dissimilarity(m1, m2, TRUTH) < dissimilarity(m1, m2, TRUTH + np.array([-0.15, 0.0, 0.0]))


def test_psi_is_inf_without_enough_overlap(office_pair) -> None:
    m1, m2 = office_pair
    assert math.isinf(dissimilarity(m1, m2, TRUTH + np.array([100.0, 0.0, 0.0])))
    assert math.isfinite(
        dissimilarity(
            m1,
            m2,
            TRUTH + np.array([100.0, 0.0, 0.0]),
            config=DissimilarityConfig(restrict_to_overlap=False),
        )
    )


# --- acceptance index ----------------------------------------------------------------------


def test_acceptance_index_of_a_map_with_itself_is_one(office_pair) -> None:
    m1, _ = office_pair
    agreement = acceptance_index(m1, m1, np.zeros(3))
    known = int(np.count_nonzero(m1.free | m1.occupied))
    assert agreement == Agreement(
        agree=known,
        disagree=0,
        conflicts=0,
        overlap=known,
        known1=known,
        known2=known,
        index=1.0,
        overlap_fraction=1.0,
        conflict_fraction=0.0,
    )


def test_acceptance_index_without_overlap_is_zero(office_pair) -> None:
    m1, m2 = office_pair
    agreement = acceptance_index(m1, m2, TRUTH + np.array([100.0, 0.0, 0.0]))
    assert agreement.overlap == agreement.agree == agreement.disagree == 0
    assert agreement.index == 0.0 and agreement.overlap_fraction == 0.0
    assert agreement.conflict_fraction == 0.0


def test_acceptance_index_counts_by_hand() -> None:
    # m1: F F O F U ; m2 (same frame, shifted origin by whole cells): . F O O F F
    m1 = GridMap(cells=np.array([[0, 0, 100, 0, -1]], dtype=np.int8), resolution=1.0)
    m2 = GridMap(
        cells=np.array([[0, 100, 100, 0, 0]], dtype=np.int8), resolution=1.0, origin=(1.0, 0.0)
    )
    # m1 cells 1..3 overlap m2 cells 0..2: F/F agree, O/O agree, F/O disagree.
    agreement = acceptance_index(m1, m2, np.zeros(3), tolerance_cells=0)
    assert (agreement.agree, agreement.disagree, agreement.overlap) == (2, 1, 3)
    assert (agreement.known1, agreement.known2) == (4, 5)
    assert agreement.index == pytest.approx(2 / 3)
    assert agreement.overlap_fraction == pytest.approx(3 / 4)
    # The disagreeing cell: m2's wall on m1's floor, one cell from m1's wall.
    assert agreement.conflicts == 1
    assert acceptance_index(m1, m2, np.zeros(3), tolerance_cells=1).conflicts == 0


def test_conflicts_tell_a_misaligned_wall_from_a_wall_across_open_floor() -> None:
    rows, cols = 40, 40
    floor = np.full((rows, cols), FREE, dtype=np.int8)
    wall = floor.copy()
    wall[:, 20] = OCCUPIED
    m1 = GridMap(cells=wall, resolution=0.05)
    one_cell_off = GridMap(cells=wall, resolution=0.05, origin=(0.05, 0.0))
    across = GridMap(cells=floor, resolution=0.05)
    small = acceptance_index(m1, one_cell_off, np.zeros(3))
    assert small.disagree > 0 and small.conflicts == 0
    big = acceptance_index(m1, across, np.zeros(3))
    assert big.conflicts == rows  # every cell of m1's wall lies on m2's open floor


def test_conflicts_are_rare_at_the_truth_and_common_when_wrong(office_pair) -> None:
    m1, m2 = office_pair
    truth = acceptance_index(m1, m2, TRUTH)
    assert truth.index > 0.98 and truth.overlap_fraction > 0.5
    assert truth.conflict_fraction < 0.002
    for offset in ([0.3, 0.0, 0.05], [2.0, 0.0, 0.0], [0.0, 0.0, np.pi]):
        wrong = acceptance_index(m1, m2, TRUTH + offset)
        assert wrong.conflict_fraction > 0.01, offset


# --- bad input -----------------------------------------------------------------------------


def test_bad_input_raises_one_line_value_errors() -> None:
    rng = np.random.default_rng(0)
    good = random_grid(rng, (5, 5))
    coarse = random_grid(rng, (5, 5), resolution=0.2)
    unknown = GridMap(cells=np.full((4, 4), UNKNOWN, dtype=np.int8), resolution=0.1)
    empty = GridMap(cells=np.zeros((0, 3), dtype=np.int8), resolution=0.1)
    bigger = random_grid(rng, (6, 5))
    cases = [
        (lambda: dissimilarity(good, coarse, np.zeros(3)), "different resolutions"),
        (lambda: acceptance_index(good, coarse, np.zeros(3)), "different resolutions"),
        (lambda: dissimilarity(good, unknown, np.zeros(3)), "no known"),
        (lambda: distance_maps(unknown), "no known"),
        (lambda: distance_maps(empty), "empty"),
        (lambda: dissimilarity(good, good, [0.0, np.nan, 0.0]), "finite"),
        (lambda: acceptance_index(good, good, [0.0, 0.0, np.inf]), "finite"),
        (lambda: dissimilarity(good, good, [0.0, 0.0]), "shape"),
        (
            lambda: dissimilarity(good, good, np.zeros(3), distances1=distance_maps(bigger)),
            "distances1",
        ),
        (lambda: acceptance_index(good, good, np.zeros(3), tolerance_cells=-1), "tolerance"),
        (
            lambda: dissimilarity(
                good,
                good,
                np.zeros(3),
                distances1=distance_maps(good),
                distances2=distance_maps(good),
                config=DissimilarityConfig(wall_sides=True),
            ),
            "sides=True",
        ),
    ]
    for call, words in cases:
        with pytest.raises(ValueError) as error:
            call()
        message = str(error.value)
        assert "\n" not in message
        assert words in message


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("max_free_cells", 0),
        ("min_overlap_cells", 1.5),
        ("restrict_to_overlap", 1),
        ("wall_sides", "yes"),
    ],
)
def test_config_errors_name_field_and_value(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=rf"DissimilarityConfig\.{field} .*{value!r}"):
        DissimilarityConfig(**{field: value})  # type: ignore[arg-type]


def test_overlap_psi_tables_give_the_generic_kernels_psi_exactly():
    """psi's kernel from the precomputed tables (cell centres, distances on known cells)
    equals, bit for bit, its generic per-term path (forced by dropping the tables), over
    random maps, origins, resolutions, strides, wall sides and placements, including
    placements with no overlap."""
    from dataclasses import replace

    from mrslam_env.merge.dissimilarity import _has_overlap_tables, _psi, _psi_tables

    rng = np.random.default_rng(21)
    for trial in range(6):
        resolution = (0.05, 0.1)[trial % 2]
        m1 = random_grid(rng, (37 + trial, 41), resolution=resolution, origin=(-1.3 * trial, 0.7))
        m2 = random_grid(rng, (29, 45 - trial), resolution=resolution, origin=(0.4, -2.1))
        d1, d2 = distance_maps(m1, sides=True), distance_maps(m2, sides=True)
        assert _has_overlap_tables(d1, m1, resolution) and _has_overlap_tables(d2, m2, resolution)
        plain1 = replace(d1, origin=None, free_in_known=None, occupied_in_known=None)
        plain2 = replace(d2, origin=None, free_centres=None, occupied_centres=None)
        for config in (
            EXACT,
            DissimilarityConfig(max_free_cells=97, min_overlap_cells=3),
            DissimilarityConfig(wall_sides=True, max_free_cells=97),
        ):
            for _ in range(40):
                transform = np.array(
                    [rng.uniform(-4, 4), rng.uniform(-4, 4), rng.uniform(-math.pi, math.pi)]
                )
                fast_tables = _psi_tables(m1, m2, d1, d2, config)
                slow_tables = _psi_tables(m1, m2, plain1, plain2, config)
                assert fast_tables.fast and not slow_tables.fast
                fast = _psi(*transform, fast_tables)
                slow = _psi(*transform, slow_tables)
                assert fast == slow or (math.isinf(fast) and math.isinf(slow))


def test_distance_tables_mark_unknown_cells_and_hold_cell_centres():
    rng = np.random.default_rng(5)
    grid = random_grid(rng, (9, 13), resolution=0.05, origin=(1.5, -0.25))
    maps = distance_maps(grid)
    assert maps.free_in_known is not None and maps.occupied_in_known is not None
    known = grid.free | grid.occupied
    assert np.array_equal(maps.free_in_known[known], maps.free[known])
    assert np.all(maps.free_in_known[~known] == -1)
    assert np.array_equal(maps.occupied_in_known[known], maps.occupied[known])
    assert np.all(maps.occupied_in_known[~known] == -1)
    assert maps.free_centres is not None
    np.testing.assert_allclose(maps.free_centres.T, grid.cell_to_world(maps.free_cells))
