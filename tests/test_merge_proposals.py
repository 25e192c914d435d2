"""The wall-correlation proposal source (``correlation_hypotheses``) and how ``merge_maps``
uses it.

- ``placement_scores`` (FFT) against a direct double sum over every shift.
- ``relative_rotations`` recovers a known turn of a wall-orientation histogram, and of a
  realistic map pair; ``wall_orientation_histogram`` of a map without walls is empty.
- On a realistic small overlap of the maze, the correlation ranks the true placement
  first; with a virtual robot too weak to find it, ``merge_maps`` merges it through the
  correlation (and refuses without it).
- A placement covering little of the smaller map is refused, whoever proposed it
  (``MergeConfig.min_overlap_fraction``): on this procedural pair it is a wrong fit.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np
import pytest
from merge_fixtures import map_pair
from scipy import fft as scipy_fft

from mrslam_env.evaluation import relative_transform_error
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.merge import hypotheses
from mrslam_env.merge.fuse import resample_map
from mrslam_env.merge.hypotheses import (
    CorrelationConfig,
    correlation_hypotheses,
    placement_scores,
    relative_rotations,
    wall_orientation_histogram,
)
from mrslam_env.merge.mcl import MclConfig
from mrslam_env.merge.pipeline import MergeConfig, merge_maps
from mrslam_env.merge.spectrum import hough_rotations
from mrslam_env.merge.virtual import VirtualRobotConfig

TRUTH = np.array([1.0, 2.0, 2.4])


def known_centroid(grid: GridMap) -> np.ndarray:
    return grid.cell_to_world(np.argwhere(~grid.unknown).mean(axis=0)[None, :])[0]


# -- placement_scores against a slow reference ------------------------------------------------


def _direct_scores(
    target1: np.ndarray, walls1: np.ndarray, walls2: np.ndarray, far2: np.ndarray, weight: float
) -> dict[tuple[int, int], float]:
    """score[s] = sum_p walls2[p] target1[p + s] - weight * sum_p far2[p] walls1[p + s]."""
    rows1, cols1 = target1.shape
    rows2, cols2 = walls2.shape
    scores = {}
    for sr in range(-(rows2 - 1), rows1):
        for sc in range(-(cols2 - 1), cols1):
            total = 0.0
            for r in range(rows2):
                for c in range(cols2):
                    if 0 <= r + sr < rows1 and 0 <= c + sc < cols1:
                        total += walls2[r, c] * target1[r + sr, c + sc]
                        total -= weight * far2[r, c] * walls1[r + sr, c + sc]
            scores[(sr, sc)] = total
    return scores


def test_placement_scores_match_a_direct_sum_over_every_shift() -> None:
    rng = np.random.default_rng(3)
    target1 = rng.normal(size=(7, 9))
    walls1 = rng.random((7, 9)) < 0.3
    walls2 = rng.random((5, 4)) < 0.4
    far2 = (rng.random((5, 4)) < 0.4) & ~walls2
    shape = (7 + 5, 9 + 4)
    fast = placement_scores(
        scipy_fft.rfft2(target1, shape),
        scipy_fft.rfft2(walls1.astype(float), shape),
        walls2,
        far2,
        2.0,
        shape,
    )
    for (sr, sc), expected in _direct_scores(target1, walls1, walls2, far2, 2.0).items():
        assert fast[sr % shape[0], sc % shape[1]] == pytest.approx(expected, abs=1e-9)


# -- rotations from wall orientations ---------------------------------------------------------


def test_relative_rotations_recover_a_shifted_histogram() -> None:
    bins = 180
    angles = np.arange(bins)
    h1 = np.exp(-0.5 * ((angles - 30) / 2.0) ** 2) + 0.6 * np.exp(
        -0.5 * ((angles - 120) / 2.0) ** 2
    )
    turn = 17  # degrees: map 2's walls are 17° behind map 1's
    h2 = np.roll(h1, -turn)
    rotations = relative_rotations(h1, h2, peaks=1, separation=math.radians(10.0))
    assert len(rotations) == 2
    errors = sorted(abs(math.degrees(r) - d) for r in rotations for d in (turn, turn - 180))
    assert errors[0] < 0.5 and errors[1] < 0.5


def test_wall_orientation_histogram_without_walls_is_empty() -> None:
    grid = GridMap(cells=np.full((40, 40), FREE, dtype=np.int8), resolution=0.1)
    assert not wall_orientation_histogram(grid).any()
    assert correlation_hypotheses(grid, grid) == []


def test_wall_orientation_histogram_of_an_axis_wall_peaks_at_its_normal() -> None:
    cells = np.full((40, 40), FREE, dtype=np.int8)
    cells[20, :] = OCCUPIED  # a wall along x: its normal points along y (90°)
    histogram = wall_orientation_histogram(GridMap(cells=cells, resolution=0.1))
    assert histogram.sum() == pytest.approx(1.0)
    assert int(np.argmax(histogram)) in (89, 90)


# -- a realistic small overlap ----------------------------------------------------------------


@pytest.fixture(scope="module")
def maze_small_overlap() -> tuple[GridMap, GridMap]:
    """Two maze maps 6 m apart: about 15 m² in common."""
    return map_pair("maze", (4, 4), (10, 5), TRUTH, seed=1, scans=8)


def test_relative_rotations_of_a_realistic_pair_contain_the_truth(
    maze_small_overlap: tuple[GridMap, GridMap],
) -> None:
    m1, m2 = (resample_map(m, 0.1) for m in maze_small_overlap)
    rotations = relative_rotations(
        wall_orientation_histogram(m1), wall_orientation_histogram(m2), 2, math.radians(10.0)
    )
    best = min(abs(math.remainder(r - TRUTH[2], math.tau)) for r in rotations)
    assert best < math.radians(2.0)


def test_correlation_ranks_the_true_placement_first(
    maze_small_overlap: tuple[GridMap, GridMap],
) -> None:
    m1, m2 = (resample_map(m, 0.1) for m in maze_small_overlap)
    placements = correlation_hypotheses(m1, m2)
    assert 1 <= len(placements) <= CorrelationConfig().max_hypotheses
    assert placements[0].weight == pytest.approx(1.0)
    moved, turned = relative_transform_error(
        placements[0].map1_from_map2, TRUTH, known_centroid(m2)
    )
    # Within the coarse grid (0.2 m) and the orientation estimate.
    assert moved < 0.4 and turned < math.radians(2.0)


def test_correlation_rejects_maps_of_different_resolutions(
    maze_small_overlap: tuple[GridMap, GridMap],
) -> None:
    m1, m2 = maze_small_overlap
    with pytest.raises(ValueError, match="same resolution"):
        correlation_hypotheses(m1, resample_map(m2, 0.1))


# Two runs and a starved particle filter: the virtual robot proposes nothing right.
WEAK_VIRTUAL_ROBOT = MergeConfig(
    virtual=VirtualRobotConfig(max_runs=2),
    mcl=MclConfig(n_particles=20, initial_particles=40),
    candidates=1,
)


def test_merge_finds_through_the_correlation_what_a_weak_virtual_robot_misses(
    maze_small_overlap: tuple[GridMap, GridMap],
) -> None:
    m1, m2 = maze_small_overlap
    result = merge_maps(m1, m2, WEAK_VIRTUAL_ROBOT, rng=0)
    assert result.chosen is not None, result.reason
    assert result.chosen.proposed_by == "correlation"
    assert result.chosen.votes == 0
    assert result.transform is not None
    moved, turned = relative_transform_error(result.transform, TRUTH, known_centroid(m2))
    assert moved < 0.1 and turned < math.radians(1.0)
    assert result.as_dict()["hypotheses"][0]["proposed_by"] == "correlation"
    # Without the correlation (its Hough rotations included).
    without = merge_maps(m1, m2, replace(WEAK_VIRTUAL_ROBOT, correlation_candidates=0), rng=0)
    assert without.transform is None


def test_hough_rotations_of_a_realistic_pair_contain_the_truth(
    maze_small_overlap: tuple[GridMap, GridMap],
) -> None:
    m1, m2 = (resample_map(m, 0.1) for m in maze_small_overlap)
    rotations = hough_rotations(m1, m2, peaks=2)
    assert len(rotations) == 4
    # theta and theta + pi for each peak
    assert abs(math.remainder(rotations[1] - rotations[0] - math.pi, math.tau)) < 1e-9
    best = min(abs(math.remainder(r - TRUTH[2], math.tau)) for r in rotations)
    assert best < math.radians(2.0)
    empty = GridMap(cells=np.full((20, 20), FREE, dtype=np.int8), resolution=0.1)
    assert hough_rotations(m1, empty, peaks=2) == []


def test_merge_finds_through_the_hough_source_what_the_others_miss(
    maze_small_overlap: tuple[GridMap, GridMap], monkeypatch: pytest.MonkeyPatch
) -> None:
    m1, m2 = maze_small_overlap
    # A starved virtual robot, and wall orientations that point the correlation 45° off:
    # only the Hough rotations lead to the truth, and the same decision step accepts it.
    monkeypatch.setattr(hypotheses, "relative_rotations", lambda *args: [TRUTH[2] + math.pi / 4])
    result = merge_maps(m1, m2, WEAK_VIRTUAL_ROBOT, rng=0)
    assert result.chosen is not None, result.reason
    assert result.chosen.proposed_by == "hough" and result.chosen.votes == 0
    assert result.transform is not None
    moved, turned = relative_transform_error(result.transform, TRUTH, known_centroid(m2))
    assert moved < 0.1 and turned < math.radians(1.0)
    assert "hypotheses.hough" in result.seconds
    without = merge_maps(m1, m2, replace(WEAK_VIRTUAL_ROBOT, hough_candidates=0), rng=0)
    assert without.transform is None
    # The live team's setting, the correlation off, turns the Hough placements off too.
    off = merge_maps(m1, m2, replace(WEAK_VIRTUAL_ROBOT, correlation_candidates=0), rng=0)
    assert off.transform is None and "hypotheses.hough" not in off.seconds


@functools.cache
def _procedural_pair() -> tuple[GridMap, GridMap]:
    return map_pair("procedural-1", (5, 5), (12, 6), TRUTH, seed=1, scans=8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_fit_covering_little_of_the_smaller_map_is_refused(seed: int) -> None:
    # 7 m apart in the procedural building: the best confident placement is a wrong fit
    # covering 8-15 % of the smaller map (the true one has too many conflicts). Which
    # source proposes it (the virtual robot, the wall correlation, Hough) changes with the
    # seed and the working grid: the rule judges the placement, not who proposed it. On
    # MCL seeds 0-5, cropped or not, the best covered at most 15 %, under the 20 % floor
    # by a margin. Whether the pair would be merged without the floor is not asked here:
    # that hangs on a rival a few conflicts from confident (issue 36, a knife edge); the
    # decision itself is tested on hand-made candidates in test_merge_decide.py.
    m1, m2 = _procedural_pair()
    for crop in (True, False):
        result = merge_maps(m1, m2, MergeConfig(crop_to_known=crop), rng=seed)
        assert result.transform is None
        assert "of the smaller map (< 20%)" in result.reason, result.reason
        best = result.hypotheses[0]
        assert best.confident  # refused for its coverage alone, not for doubt
        moved, _ = relative_transform_error(best.map1_from_map2, TRUTH, known_centroid(m2))
        assert moved > 1.0  # it was indeed wrong


# -- configuration ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("orientation_peaks", 0),
        ("cell_factor", 1.5),
        ("max_hypotheses", True),
        ("wall_sigma", 0.0),
        ("orientation_smoothing", math.nan),
        ("miss_distance", -0.3),
        ("min_peak_distance", math.inf),
        ("peak_separation", 0),
        ("contradiction_weight", -1.0),
    ],
)
def test_correlation_config_out_of_range_names_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=rf"CorrelationConfig\.{field} .*{value!r}"):
        CorrelationConfig(**{field: value})


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("correlation_candidates", -1),
        ("correlation_candidates", 2.0),
        ("min_overlap_fraction", 1.5),
        ("hough_candidates", -1),
        ("hough_peaks", 0),
        ("hough_sweep", -0.1),
        ("hough_sweep_step", 0.0),
        ("correlation", 3),
    ],
)
def test_merge_config_correlation_fields_are_validated(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=rf"MergeConfig\.{field}"):
        MergeConfig(**{field: value})
