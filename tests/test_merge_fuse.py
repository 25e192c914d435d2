"""Resampling, warping and fusing maps (mrslam_env.merge.fuse).

Oracles: resampling and warping against per-cell loops written from the definitions.
Invariants: warping by the identity is exact; lattice-exact warps (quarter turns, any
translation) round-trip exactly; a realistic map cut into two overlapping halves, one half
moved into another frame and fused back, is the original map.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from merge_fixtures import map_pair

from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.merge.fuse import covering_grid, fuse_cells, fuse_maps, resample_map, warp_map

F, W, U = int(FREE), int(OCCUPIED), int(UNKNOWN)  # free, wall, unknown
QUARTER_TURNS = [
    np.array([0.0, 0.0, 0.0]),
    np.array([1.23, -0.57, np.pi / 2]),
    np.array([0.1, -0.35, np.pi]),
    np.array([-2.0, 0.4, -np.pi / 2]),
    np.array([0.25, 0.05, 0.0]),
]


def grid(cells, resolution: float = 1.0, origin=(0.0, 0.0)) -> GridMap:
    return GridMap(cells=np.asarray(cells, dtype=np.int8), resolution=resolution, origin=origin)


def random_grid(rng, shape, resolution=0.1, origin=(0.0, 0.0), p=(0.4, 0.2, 0.4)) -> GridMap:
    values = np.array([FREE, OCCUPIED, UNKNOWN], dtype=np.int8)
    return GridMap(cells=rng.choice(values, size=shape, p=p), resolution=resolution, origin=origin)


@pytest.fixture(scope="module")
def office_map() -> GridMap:
    m1, _ = map_pair("office", (5, 4), (9, 4), np.array([1.0, 2.0, 1.2]))
    return m1


# --- the fusion rule -----------------------------------------------------------------------


def test_fuse_cells_truth_table() -> None:
    a = np.array([U, U, U, F, F, F, W, W, W], dtype=np.int8)
    b = np.array([U, F, W, U, F, W, U, F, W], dtype=np.int8)
    expected = np.array([U, F, W, F, F, W, W, W, W], dtype=np.int8)
    np.testing.assert_array_equal(fuse_cells(a, b), expected)
    np.testing.assert_array_equal(fuse_cells(b, a), expected)


# --- resample_map ----------------------------------------------------------------------------


def reference_resample(source: GridMap, resolution: float) -> np.ndarray:
    rows, cols = source.shape
    ratio = source.resolution / resolution
    out_rows = math.ceil(rows * ratio - 1e-6)
    out_cols = math.ceil(cols * ratio - 1e-6)
    rank = {U: 0, F: 1, W: 2}
    out = np.full((out_rows, out_cols), U, dtype=np.int8)
    if resolution > source.resolution:
        for r in range(rows):
            for c in range(cols):
                rr = min(math.floor((r + 0.5) * ratio), out_rows - 1)
                cc = min(math.floor((c + 0.5) * ratio), out_cols - 1)
                if rank[int(source.cells[r, c])] > rank[int(out[rr, cc])]:
                    out[rr, cc] = source.cells[r, c]
    else:
        for rr in range(out_rows):
            for cc in range(out_cols):
                r = math.floor((rr + 0.5) / ratio)
                c = math.floor((cc + 0.5) / ratio)
                if r < rows and c < cols:
                    out[rr, cc] = source.cells[r, c]
    return out


def test_downsampling_by_two_keeps_the_most_conservative_class() -> None:
    source = grid(
        [
            [F, F, U, U, F],
            [F, W, U, F, U],
            [U, U, F, F, W],
        ],
        resolution=0.05,
        origin=(1.0, -2.0),
    )
    coarse = resample_map(source, 0.1)
    assert coarse.resolution == 0.1 and coarse.origin == (1.0, -2.0)
    np.testing.assert_array_equal(coarse.cells, [[W, F, F], [U, F, W]])


@pytest.mark.parametrize("resolution", [0.1, 0.15, 0.13, 0.4, 0.07, 0.05, 0.025, 0.031])
def test_resample_matches_the_reference(resolution: float) -> None:
    source = random_grid(np.random.default_rng(4), (23, 17), resolution=0.05, origin=(0.3, -1.1))
    result = resample_map(source, resolution)
    assert result.origin == source.origin and result.resolution == resolution
    np.testing.assert_array_equal(result.cells, reference_resample(source, resolution))
    # The output covers the input.
    assert result.extent[2] >= source.extent[2] - 1e-9
    assert result.extent[3] >= source.extent[3] - 1e-9


def test_resample_to_the_same_resolution_is_a_copy() -> None:
    source = random_grid(np.random.default_rng(1), (5, 6))
    copy = resample_map(source, source.resolution)
    np.testing.assert_array_equal(copy.cells, source.cells)
    assert copy.cells is not source.cells


def test_downsampled_walls_stay_connected(office_map) -> None:
    coarse = resample_map(office_map, 0.1)
    fine_walls = office_map.occupied.sum()
    # Every 2x2 block holding a wall cell is a wall cell: exactly the block count.
    blocks = office_map.occupied.reshape(128, 2, 192, 2).any(axis=(1, 3))
    np.testing.assert_array_equal(coarse.occupied, blocks)
    assert 0 < coarse.occupied.sum() <= fine_walls


# --- warp_map --------------------------------------------------------------------------------


def reference_warp(m2: GridMap, map1_from_map2: np.ndarray, like: GridMap) -> np.ndarray:
    out = np.full(like.shape, U, dtype=np.int8)
    map2_from_map1 = inverse(map1_from_map2)
    for r in range(like.shape[0]):
        for c in range(like.shape[1]):
            centre = like.cell_to_world(np.array([r, c]))
            point = transform_points(map2_from_map1, centre[None])[0]
            ix = math.floor((point[0] - m2.origin[0]) / m2.resolution)
            iy = math.floor((point[1] - m2.origin[1]) / m2.resolution)
            if 0 <= iy < m2.shape[0] and 0 <= ix < m2.shape[1]:
                out[r, c] = m2.cells[iy, ix]
    return out


def test_warp_by_identity_is_exact(office_map) -> None:
    for like in (None, office_map):
        warped = warp_map(office_map, np.zeros(3), like=like)
        np.testing.assert_array_equal(warped.cells, office_map.cells)
        assert warped.origin == pytest.approx(office_map.origin, abs=1e-9)
        assert warped.resolution == office_map.resolution


def test_warp_matches_the_reference_for_generic_transforms() -> None:
    rng = np.random.default_rng(9)
    m2 = random_grid(rng, (11, 8), origin=(-0.4, -0.5))
    like = random_grid(rng, (14, 15), origin=(-0.73, -0.61))
    for _ in range(5):
        transform = np.array([*rng.uniform(-0.3, 0.3, 2), rng.uniform(-np.pi, np.pi)])
        warped = warp_map(m2, transform, like=like)
        assert warped.shape == like.shape and warped.origin == like.origin
        np.testing.assert_array_equal(warped.cells, reference_warp(m2, transform, like))


def test_warp_without_like_covers_the_image_exactly_once() -> None:
    rng = np.random.default_rng(2)
    m2 = random_grid(rng, (7, 12), resolution=0.05, origin=(0.12, -0.31))
    for transform in QUARTER_TURNS:
        warped = warp_map(m2, transform)
        # A quarter turn keeps the cell count and every class count.
        assert warped.cells.size == m2.cells.size
        for value in (F, W, U):
            assert np.count_nonzero(warped.cells == value) == np.count_nonzero(m2.cells == value)


@pytest.mark.parametrize("index", range(len(QUARTER_TURNS)))
def test_lattice_exact_warps_round_trip(office_map, index: int) -> None:
    transform = QUARTER_TURNS[index]
    there = warp_map(office_map, transform)
    back = warp_map(there, inverse(transform), like=office_map)
    np.testing.assert_array_equal(back.cells, office_map.cells)


def test_warp_does_not_mutate_its_input(office_map) -> None:
    before = office_map.cells.copy()
    warp_map(office_map, np.array([0.3, 0.2, 0.4]))
    np.testing.assert_array_equal(office_map.cells, before)


# --- covering_grid and fuse_maps ---------------------------------------------------------------


def test_covering_grid_is_on_m1_lattice_and_covers_both() -> None:
    rng = np.random.default_rng(3)
    m1 = random_grid(rng, (10, 12), resolution=0.05, origin=(0.013, -0.021))
    m2 = random_grid(rng, (9, 7), resolution=0.05, origin=(-0.2, 0.1))
    transform = np.array([0.9, -0.4, 0.7])
    canvas = covering_grid(m1, m2, transform)
    offset = (np.asarray(canvas.origin) - m1.origin) / m1.resolution
    np.testing.assert_allclose(offset, np.rint(offset), atol=1e-6)
    assert np.all(canvas.unknown)
    x0, y0, x1, y1 = canvas.extent
    corners = np.array([[m2.extent[0], m2.extent[1]], [m2.extent[2], m2.extent[3]]])
    corners = np.vstack([corners, [[m2.extent[0], m2.extent[3]], [m2.extent[2], m2.extent[1]]]])
    image = transform_points(transform, corners)
    for x, y in (*image, m1.extent[:2], m1.extent[2:]):
        assert x0 - 1e-9 <= x <= x1 + 1e-9 and y0 - 1e-9 <= y <= y1 + 1e-9


def test_fuse_rule_known_beats_unknown_and_occupied_beats_free() -> None:
    m1 = grid([[F, F, U, W]])
    m2 = grid([[U, W, F, F]])
    fused = fuse_maps(m1, m2, np.zeros(3))
    np.testing.assert_array_equal(fused.cells, [[F, W, F, W]])
    assert fused.origin == (0.0, 0.0)


def test_fused_grid_grows_to_cover_both() -> None:
    m1 = grid([[F, W]], origin=(0.0, 0.0))
    m2 = grid([[W, F, F]], origin=(0.0, 0.0))
    fused = fuse_maps(m1, m2, np.array([3.0, 1.0, 0.0]))  # m2 lands one row up, three right
    assert fused.origin == (0.0, 0.0) and fused.shape == (2, 6)
    np.testing.assert_array_equal(fused.cells, [[F, W, U, U, U, U], [U, U, U, W, F, F]])


@pytest.mark.parametrize("index", range(len(QUARTER_TURNS)))
def test_two_overlapping_halves_fuse_back_to_the_original(office_map, index: int) -> None:
    original = office_map
    res = original.resolution
    cols = original.shape[1]
    left_end, right_start = cols * 6 // 10, cols * 4 // 10
    left = grid(original.cells[:, :left_end], res, original.origin)
    right_origin = (original.origin[0] + right_start * res, original.origin[1])
    right = grid(original.cells[:, right_start:], res, right_origin)
    # Map 2 is the right half seen from a frame at `map1_from_map2` in map 1.
    map1_from_map2 = QUARTER_TURNS[index]
    right_in_map2 = warp_map(right, inverse(map1_from_map2))
    fused = fuse_maps(left, right_in_map2, map1_from_map2)
    assert fused.shape == original.shape
    assert fused.origin == pytest.approx(original.origin, abs=1e-9)
    np.testing.assert_array_equal(fused.cells, original.cells)


def test_fusing_a_map_with_itself_changes_nothing(office_map) -> None:
    fused = fuse_maps(office_map, office_map, np.zeros(3))
    np.testing.assert_array_equal(fused.cells, office_map.cells)


def test_fuse_is_consistent_with_compose_for_a_moved_frame(office_map) -> None:
    # Moving map 2's grid origin and compensating in the transform fuses identically.
    m2 = warp_map(office_map, np.array([0.4, -0.3, np.pi / 2]))
    transform = inverse(np.array([0.4, -0.3, np.pi / 2]))
    shift = np.array([1.5, -0.25])
    moved = grid(m2.cells, m2.resolution, tuple(np.asarray(m2.origin) + shift))
    a = fuse_maps(office_map, m2, transform)
    b = fuse_maps(office_map, moved, compose(transform, [-shift[0], -shift[1], 0.0]))
    np.testing.assert_array_equal(a.cells, b.cells)
    np.testing.assert_array_equal(a.cells, office_map.cells)


# --- bad input -------------------------------------------------------------------------------


def test_bad_input_raises_one_line_value_errors() -> None:
    rng = np.random.default_rng(0)
    good = random_grid(rng, (5, 5))
    coarse = random_grid(rng, (5, 5), resolution=0.2)
    unknown = grid(np.full((3, 3), U), resolution=0.1)
    empty = grid(np.zeros((0, 4)), resolution=0.1)
    cases = [
        (lambda: fuse_maps(good, coarse, np.zeros(3)), "different resolutions"),
        (lambda: fuse_maps(good, unknown, np.zeros(3)), "no known"),
        (lambda: fuse_maps(empty, good, np.zeros(3)), "empty"),
        (lambda: fuse_maps(good, good, [np.inf, 0.0, 0.0]), "finite"),
        (lambda: warp_map(unknown, np.zeros(3)), "no known"),
        (lambda: warp_map(empty, np.zeros(3)), "empty"),
        (lambda: warp_map(good, [0.0, 0.0, np.nan]), "finite"),
        (lambda: warp_map(good, np.zeros(3), like=coarse), "different resolutions"),
        (lambda: resample_map(empty, 0.1), "empty"),
        (lambda: resample_map(good, 0.0), "resolution"),
        (lambda: resample_map(good, math.nan), "resolution"),
    ]
    for call, words in cases:
        with pytest.raises(ValueError, match=words) as error:
            call()
        assert "\n" not in str(error.value)
