"""The Hough-spectrum baseline (:mod:`scenarios.bench.merge.hough`)."""

from __future__ import annotations

import math

import numpy as np

from mrslam_env.evaluation import relative_transform_error
from mrslam_env.geometry import inverse
from mrslam_env.gridmap import UNKNOWN, GridMap, grid_footprint, resample_cells
from mrslam_env.registry import build_world
from mrslam_env.sim.world import ground_truth_map
from scenarios.bench.merge.hough import HoughConfig, estimate_transform_hough, hough_spectrum


def rotated_pair(truth: np.ndarray) -> tuple[GridMap, GridMap]:
    """Two overlapping ground-truth crops of the office: m1 its left three quarters,
    m2 its right three quarters expressed in a frame with ``map1_from_map2 = truth``."""
    full = ground_truth_map(build_world("office"), 0.05, margin=0.5)
    cols = full.shape[1]
    left = full.cells.copy()
    left[:, int(0.75 * cols) :] = UNKNOWN
    right = full.cells.copy()
    right[:, : int(0.25 * cols)] = UNKNOWN
    m1 = GridMap(cells=left, resolution=0.05, origin=full.origin)
    source = GridMap(cells=right, resolution=0.05, origin=full.origin)
    frame2_from_map1 = inverse(truth)
    corners = grid_footprint(source, frame2_from_map1)
    lower = corners.min(axis=0) - 0.2
    cols, rows = (int(v) for v in np.ceil((corners.max(axis=0) + 0.2 - lower) / 0.05))
    shape = (rows, cols)
    cells = resample_cells(source, frame2_from_map1, (lower[0], lower[1]), shape, 0.05)
    return m1, GridMap(cells=cells, resolution=0.05, origin=(lower[0], lower[1]))


def test_recovers_a_rotation_and_translation() -> None:
    truth = np.array([1.5, -0.8, math.radians(30.0)])
    m1, m2 = rotated_pair(truth)
    result = estimate_transform_hough(m1, m2, HoughConfig(polish=False))
    assert result.transform is not None
    pivot = m2.cell_to_world(np.argwhere(m2.cells != UNKNOWN)).mean(axis=0)
    translation, rotation = relative_transform_error(result.transform, truth, pivot)
    assert translation <= 0.2 and math.degrees(rotation) <= 2.0


def test_spectrum_shifts_with_rotation() -> None:
    rng = np.random.default_rng(0)
    wall = np.column_stack([rng.uniform(0, 5, 300), np.zeros(300)])
    angle = math.radians(45.0)
    c, s = math.cos(angle), math.sin(angle)
    turned = wall @ np.array([[c, s], [-s, c]])
    s1 = hough_spectrum(wall, 180, 0.05)
    s2 = hough_spectrum(turned, 180, 0.05)
    assert abs(int(np.argmax(s1)) - 90) <= 1  # a wall along x: its normal points along y
    assert abs(int(np.argmax(s2)) - 135) <= 1


def test_no_occupied_cell_gives_no_transform() -> None:
    empty = GridMap(cells=np.zeros((10, 10), dtype=np.int8), resolution=0.05)
    assert estimate_transform_hough(empty, empty).transform is None
