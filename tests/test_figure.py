"""The run's summary figure (scenarios/figure.py) reads at a glance: every panel in robot
0's frame at one scale and size, the ground truth lined up with the robots' maps, and a
reason in every panel without a merge."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from PIL import Image

from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import GridMap, grid_in_frame
from mrslam_env.registry import build_world
from mrslam_env.sim.world import ground_truth_map
from scenarios.figure import no_merge_reason, panel_boxes, summary_figure

WORLD_FROM_MAP0 = np.array([3.0, 2.0, math.pi / 2])  # robot 0 starts turned a quarter turn
WORLD_FROM_MAP1 = np.array([14.0, 6.0, -0.4])


@pytest.fixture(scope="module")
def truth() -> GridMap:
    return ground_truth_map(build_world("office"), 0.05)


def in_start_frame(truth: GridMap, world_from_map: NDArray[np.float64]) -> GridMap:
    """A perfect robot map: the ground truth in the robot's start frame."""
    return grid_in_frame(truth, inverse(world_from_map))


def panels(path: Path, n_top: int = 3) -> list[NDArray[np.uint8]]:
    image = Image.open(path).convert("L")
    return [np.asarray(image.crop(box)) for box in panel_boxes(image.size, n_top)]


def test_the_truth_and_the_robots_maps_line_up(truth: GridMap, tmp_path: Path) -> None:
    map0 = in_start_frame(truth, WORLD_FROM_MAP0)
    map1 = in_start_frame(truth, WORLD_FROM_MAP1)
    true_1 = compose(inverse(WORLD_FROM_MAP0), WORLD_FROM_MAP1)
    path = summary_figure(
        tmp_path / "figure.png",
        truth,
        map0,
        map1,
        None,
        None,
        world_from_maps=[WORLD_FROM_MAP0, WORLD_FROM_MAP1],
        transforms=[true_1],
    )
    ground, m1, m2, *_ = panels(path)
    assert ground.shape == m1.shape == m2.shape
    walls = ground < 60
    assert walls.sum() > 1000
    # Every wall pixel of the truth panel is a wall in m1's and m2's within two pixels,
    # and the other way round (the scale bar's corner left out).
    body = np.ones_like(walls)
    body[-40:, :140] = False
    for other in (m1, m2):
        theirs = other < 60
        for a, b in ((walls, theirs), (theirs, walls)):
            near = _dilate(b, 2)
            missed = a & body & ~near
            assert missed.sum() <= 0.01 * (a & body).sum(), missed.sum()


def _dilate(mask: NDArray[np.bool_], radius: int) -> NDArray[np.bool_]:
    from scipy import ndimage

    return ndimage.binary_dilation(mask, iterations=radius)


def test_panels_have_one_size_and_a_scale_bar(truth: GridMap, tmp_path: Path) -> None:
    map0 = in_start_frame(truth, WORLD_FROM_MAP0)
    small = GridMap(
        cells=map0.cells[::2, ::2].copy(), origin=map0.origin, resolution=0.1
    )  # a coarser map
    path = summary_figure(
        tmp_path / "f.png",
        truth,
        map0,
        small,
        map0,
        map0,
        world_from_maps=[WORLD_FROM_MAP0, WORLD_FROM_MAP0],
    )
    shown = panels(path)
    assert len({p.shape for p in shown}) == 1
    # The two merge panels are the same map: the same picture.
    assert np.array_equal(shown[3], shown[4])
    # A scale bar: a long black run of pixels in the bottom left of every map panel.
    for panel in shown[:5]:
        corner = panel[-30:, :200] < 30
        assert corner.sum(axis=1).max() >= 20


def test_a_panel_without_a_merge_says_why(truth: GridMap, tmp_path: Path) -> None:
    map0 = in_start_frame(truth, WORLD_FROM_MAP0)
    path = summary_figure(
        tmp_path / "f.png",
        truth,
        map0,
        map0,
        None,
        None,
        world_from_maps=[WORLD_FROM_MAP0, WORLD_FROM_MAP0],
        no_merge="no merge: stopped at coverage while verifying (3 hypotheses tested)",
    )
    blank = summary_figure(
        tmp_path / "g.png",
        truth,
        map0,
        map0,
        None,
        None,
        world_from_maps=[WORLD_FROM_MAP0, WORLD_FROM_MAP0],
        no_merge="",
    )
    said, silent = panels(path), panels(blank)
    for k in (3, 4, 5):
        dark = said[k] < 128
        assert dark.sum() > 200  # text
        # ... more than the blank panel: the text is the reason
        assert dark.sum() > (silent[k] < 128).sum() + 200


def test_the_reasons_for_no_merge() -> None:
    verifying = {"hypotheses_tested": 2, "first_hypothesis_step": 40}
    assert "while verifying" in no_merge_reason(verifying, "hypothesis_verification")
    assert "no hypothesis yet" in no_merge_reason(
        {"hypotheses_tested": 0, "first_hypothesis_step": None},
        "hypothesis_generation",
        ["12 no hypotheses: the maps share too little"],
    )
    refused = no_merge_reason(
        verifying, "no_interaction", ["90 hypothesis #1 rejected by the radio", "91 x"]
    )
    assert "refused" in refused and "rejected by the radio" in refused
