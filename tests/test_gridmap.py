"""Resampling a grid onto a raster in another frame (mrslam_env.gridmap.resample_cells), the
one warping implementation behind mrslam_env.merge.fuse.warp_map and the evaluation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrslam_env.geometry import inverse
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap, resample_cells
from mrslam_env.merge.fuse import covering_grid, warp_map


def room_map(rows: int = 60, cols: int = 80, resolution: float = 0.05) -> GridMap:
    """A fully known walled rectangle with an inner wall stub, origin at (0, 0)."""
    cells = np.full((rows, cols), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[: rows // 2, cols // 3] = OCCUPIED
    return GridMap(cells=cells, resolution=resolution, origin=(0.0, 0.0))


def random_grid(rng: np.random.Generator, shape, resolution=0.1, origin=(0.0, 0.0)) -> GridMap:
    cells = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], dtype=np.int8), size=shape)
    return GridMap(cells=cells, resolution=resolution, origin=origin)


def reference_resample(source, target_from_source, origin, shape, resolution) -> np.ndarray:
    """Vectorised numpy reference: each target centre into the source frame, nearest cell."""
    rows, cols = shape
    xs = origin[0] + (np.arange(cols) + 0.5) * resolution
    ys = origin[1] + (np.arange(rows) + 0.5) * resolution
    back = inverse(target_from_source)
    c, s = math.cos(back[2]), math.sin(back[2])
    px = c * xs[None, :] - s * ys[:, None] + back[0]
    py = s * xs[None, :] + c * ys[:, None] + back[1]
    ix = np.floor((px - source.origin[0]) / source.resolution).astype(np.int64)
    iy = np.floor((py - source.origin[1]) / source.resolution).astype(np.int64)
    inside = (ix >= 0) & (ix < source.shape[1]) & (iy >= 0) & (iy < source.shape[0])
    out = np.full(shape, UNKNOWN, dtype=np.int8)
    out[inside] = source.cells[iy[inside], ix[inside]]
    return out


def test_resample_cells_identity_and_outside() -> None:
    grid = room_map()
    same = resample_cells(grid, np.zeros(3), grid.origin, grid.shape, grid.resolution)
    np.testing.assert_array_equal(same, grid.cells)
    far = resample_cells(grid, np.array([100.0, 0.0, 0.0]), grid.origin, grid.shape, 0.05)
    assert (far == UNKNOWN).all()


@pytest.mark.parametrize("resolution", [0.1, 0.05, 0.033, 0.25])
def test_resample_cells_matches_the_reference_at_any_resolution(resolution: float) -> None:
    rng = np.random.default_rng(4)
    source = random_grid(rng, (23, 31), origin=(-0.37, 0.52))
    for _ in range(5):
        transform = np.array([*rng.uniform(-1.0, 1.0, 2), rng.uniform(-math.pi, math.pi)])
        args = ((-2.0, -1.5), (70, 90), resolution)
        np.testing.assert_array_equal(
            resample_cells(source, transform, *args),
            reference_resample(source, transform, *args),
        )


def test_resample_cells_accepts_sequences_and_leaves_the_source_alone() -> None:
    grid = room_map()
    before = grid.cells.copy()
    a = resample_cells(grid, [0.3, -0.2, 0.4], (-1.0, -1.0), (50, 60), 0.07)
    b = resample_cells(grid, np.array([0.3, -0.2, 0.4]), (-1.0, -1.0), (50, 60), 0.07)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(grid.cells, before)
    assert a.dtype == np.int8 and a.shape == (50, 60)


def test_warp_map_is_resample_cells_onto_its_lattice() -> None:
    rng = np.random.default_rng(8)
    m1 = random_grid(rng, (20, 25), origin=(0.13, -0.4))
    m2 = random_grid(rng, (18, 30), origin=(-0.6, 0.2))
    for _ in range(4):
        transform = np.array([*rng.uniform(-1.0, 1.0, 2), rng.uniform(-math.pi, math.pi)])
        for like in (None, covering_grid(m1, m2, transform)):
            warped = warp_map(m2, transform, like=like)
            cells = resample_cells(m2, transform, warped.origin, warped.shape, m2.resolution)
            np.testing.assert_array_equal(warped.cells, cells)


def test_known_window_is_the_grown_box_of_the_known_cells_and_of_also() -> None:
    from mrslam_env.gridmap import known_window

    cells = np.full((20, 30), UNKNOWN, dtype=np.int8)
    assert known_window(GridMap(cells=cells, resolution=0.1), 3) == (slice(0, 20), slice(0, 30))
    cells[5, 7] = FREE
    cells[9, 12] = OCCUPIED
    grid = GridMap(cells=cells, resolution=0.1)
    assert known_window(grid, 0) == (slice(5, 10), slice(7, 13))
    assert known_window(grid, 2) == (slice(3, 12), slice(5, 15))
    assert known_window(grid, 8) == (slice(0, 18), slice(0, 21))  # clipped to the grid
    also = np.zeros(cells.shape, dtype=bool)
    also[15, 25] = True
    assert known_window(grid, 1, also=also) == (slice(4, 17), slice(6, 27))
    empty = GridMap(cells=np.full((4, 4), UNKNOWN, dtype=np.int8), resolution=0.1)
    only = np.zeros((4, 4), dtype=bool)
    only[2, 1] = True
    assert known_window(empty, 0, also=only) == (slice(2, 3), slice(1, 2))
