"""The merge benchmark's pairs cut from the real map files (scenarios.bench.merge.cuts)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import ndimage

from mrslam_env.evaluation import true_overlap
from mrslam_env.geometry import transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, GridMap, grid_in_frame
from scenarios.bench.merge.cuts import (
    CutConfig,
    generate_cut_pairs,
    load_or_generate_cut_pairs,
    turned_grid,
)
from scenarios.bench.merge.pairs import MergePair, world_family
from scenarios.cli import main

SMALL = ("bookstore", "aws_warehouse_lowres", "tb3_sandbox", "small_house")
"""The smaller maps (0.05 m): quick to cut."""


def small_config(**changes: object) -> CutConfig:
    fields: dict[str, object] = {
        "n_pairs": 8,
        "buildings": SMALL,
        "disjoint_fraction": 0.25,
        "other_building_fraction": 0.25,
    }
    fields.update(changes)
    return CutConfig(**fields)  # type: ignore[arg-type]


def landing(pair: MergePair) -> tuple[np.ndarray, np.ndarray]:
    """Map 1's cell under the centre of every occupied cell of map 2 moved by the truth
    (those landing inside map 1), and whether map 1 has a wall within one cell of it."""
    cells = np.argwhere(pair.m2.cells == OCCUPIED)
    points = transform_points(pair.map1_from_map2, pair.m2.cell_to_world(cells))
    index = pair.m1.world_to_cell(points)
    rows, cols = pair.m1.shape
    inside = (index[:, 0] >= 1) & (index[:, 0] < rows - 1)
    inside &= (index[:, 1] >= 1) & (index[:, 1] < cols - 1)
    index = index[inside]
    near_wall = ndimage.binary_dilation(pair.m1.cells == OCCUPIED, np.ones((3, 3), bool))
    return index, near_wall[index[:, 0], index[:, 1]]


def test_cutting_is_deterministic_per_seed(tmp_path) -> None:
    config = small_config()
    first = generate_cut_pairs(config, tmp_path / "a")
    again, _ = load_or_generate_cut_pairs(config, tmp_path / "cache")
    other = generate_cut_pairs(small_config(seed=1), tmp_path / "b")
    assert len(first) == len(again) == config.n_pairs
    for a, b in zip(first, again, strict=True):
        assert a.pair_id == b.pair_id and a.overlap == b.overlap
        np.testing.assert_array_equal(a.m1.cells, b.m1.cells)
        np.testing.assert_array_equal(a.m2.cells, b.m2.cells)
        assert a.m2.origin == b.m2.origin  # the saved maps read back exactly
        np.testing.assert_array_equal(a.map1_from_map2, b.map1_from_map2)
    assert any(
        not np.array_equal(a.map1_from_map2, b.map1_from_map2)
        for a, b in zip(first, other, strict=True)
    )
    assert small_config().cache_key() != small_config(seed=1).cache_key()


def test_the_set_holds_every_kind_of_pair(tmp_path) -> None:
    pairs = generate_cut_pairs(small_config(), tmp_path)
    kinds = [pair.info["kind"] for pair in pairs]
    assert kinds.count("disjoint") == 2 and kinds.count("other-building") == 2
    edges = CutConfig().overlap_bins
    for pair in pairs:
        assert world_family(pair.scenario) == "real"
        if pair.info["kind"] == "overlap":
            assert edges[0] <= pair.overlap < edges[-1]
            # the overlap on the file's lattice agrees with the one measured after the turn
            assert true_overlap(pair.m1, pair.m2, pair.map1_from_map2) == pytest.approx(
                pair.overlap, abs=0.03
            )
        else:
            assert pair.overlap == 0.0 and not pair.overlapping()
        if pair.info["kind"] == "other-building":
            assert pair.info["source1"] != pair.info["source2"]
            assert {pair.info["source1"], pair.info["source2"]} != {
                "aws_warehouse",
                "aws_warehouse_lowres",
            }
        else:
            assert pair.info["source1"] == pair.info["source2"]


def test_unturned_cut_maps_cells_onto_cells(tmp_path) -> None:
    pairs = generate_cut_pairs(small_config(max_turn_deg=0.0), tmp_path)
    compared = 0
    for pair in (p for p in pairs if p.info["kind"] == "overlap"):
        m1, m2 = pair.m1, pair.m2
        assert pair.map1_from_map2[2] == 0.0
        cells = np.indices(m2.shape).reshape(2, -1).T
        points = transform_points(pair.map1_from_map2, m2.cell_to_world(cells))
        index = m1.world_to_cell(points)
        # every centre lands on a centre of map 1's lattice ...
        np.testing.assert_allclose(m1.cell_to_world(index), points, atol=1e-9)
        inside = m1.contains(index)
        assert inside.sum() > 0.2 * min(m1.cells.size, m2.cells.size)
        # ... with the same state: the two windows are cut from one lattice
        np.testing.assert_array_equal(
            m2.cells[cells[inside, 0], cells[inside, 1]],
            m1.cells[index[inside, 0], index[inside, 1]],
        )
        compared += int(inside.sum())
    assert compared > 10_000


def test_turned_cut_puts_walls_on_walls(tmp_path) -> None:
    pairs = generate_cut_pairs(small_config(n_pairs=12), tmp_path)
    overlapping = [p for p in pairs if p.info["kind"] == "overlap"]
    assert all(abs(p.info["turn_deg"]) > 1.0 for p in overlapping)  # really turned
    total = 0
    for pair in overlapping:
        index, on_wall = landing(pair)
        assert len(index) > 20, pair.pair_id
        assert on_wall.mean() >= 0.95, (pair.pair_id, on_wall.mean())
        total += len(index)
        # a transform 3 cells off the truth does not put the walls on walls
        shifted = MergePair(
            pair_id=pair.pair_id,
            scenario=pair.scenario,
            m1=pair.m1,
            m2=pair.m2,
            map1_from_map2=pair.map1_from_map2 + np.array([3 * pair.m1.resolution, 0.0, 0.0]),
            overlap=pair.overlap,
        )
        assert landing(shifted)[1].mean() < 0.9
    assert total > 1000


def staircase() -> GridMap:
    """A free room with a one-cell diagonal wall: cells touching at their corners only."""
    cells = np.full((60, 60), FREE, dtype=np.int8)
    for k in range(5, 55):
        cells[k, k] = OCCUPIED
    return GridMap(cells=cells, resolution=0.05, origin=(0.3, -0.7))


def test_turned_grid_keeps_a_thin_diagonal_wall() -> None:
    grid = staircase()
    occupied = np.argwhere(grid.cells == OCCUPIED)
    one_wall = np.ones((3, 3), bool)
    for degrees in (10.0, 30.0, 45.0, 67.0, 100.0, -135.0):
        transform = np.array([0.4, 1.1, math.radians(degrees)])
        turned = turned_grid(grid, transform)
        nearest = grid_in_frame(grid, transform)
        np.testing.assert_array_equal(turned.cells.shape, nearest.cells.shape)
        # nothing but added wall cells differs from the nearest-cell picture
        changed = turned.cells != nearest.cells
        assert np.all(turned.cells[changed] == OCCUPIED)
        index = turned.world_to_cell(transform_points(transform, grid.cell_to_world(occupied)))
        assert np.all(turned.cells[index[:, 0], index[:, 1]] == OCCUPIED)
        assert ndimage.label(turned.cells == OCCUPIED, one_wall)[1] == 1, degrees
    # the nearest-cell picture alone breaks this wall at 45 degrees
    broken = grid_in_frame(grid, np.array([0.4, 1.1, math.radians(45.0)]))
    assert ndimage.label(broken.cells == OCCUPIED, one_wall)[1] > 1


def test_cut_config_rejects_bad_values() -> None:
    with pytest.raises(ValueError, match="buildings"):
        CutConfig(buildings=("nowhere",))
    with pytest.raises(ValueError, match="max_turn_deg"):
        CutConfig(max_turn_deg=200.0)
    with pytest.raises(ValueError, match="other_building_fraction"):
        CutConfig(disjoint_fraction=0.6, other_building_fraction=0.6)
    with pytest.raises(ValueError, match="side_fraction"):
        CutConfig(side_fraction=(0.0, 1.0))


def test_cli_rejects_bad_cut_arguments_in_one_line(capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:  # refused by argparse, before any work
        main(["bench", "merge", "--set", "cuts", "--cut-pairs", "0"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    expected = "argument --cut-pairs: must be an integer >= 1, got 0"
    assert err == f"mrslam bench merge: error: {expected}\n"
    with pytest.raises(SystemExit) as exit_info:
        main(["bench", "merge", "--set", "slices"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "invalid choice: 'slices'" in err and "cuts" in err


def test_windows_of_a_large_map_are_large() -> None:
    from scenarios.bench.merge.cuts import _Source

    source = _Source("bookstore")  # known box 297 x 311 cells
    rng = np.random.default_rng(0)
    rows, cols = source.box[1] - source.box[0], source.box[3] - source.box[2]
    config = CutConfig(large_side=300)  # longer than the rows, shorter than the columns
    sides = np.array(
        [(w[1] - w[0], w[3] - w[2]) for w in (source.window(rng, config) for _ in range(200))]
    )
    assert sides[:, 1].min() >= 300 and sides[:, 1].max() <= cols
    assert sides[:, 0].min() < 0.6 * rows  # the fraction rule on the shorter side
    capped = CutConfig(large_side=300, max_side=305)
    for window in (source.window(rng, capped) for _ in range(20)):
        assert 300 <= window[3] - window[2] <= 305


def test_cli_runs_the_methods_on_the_cut_set(tmp_path, monkeypatch, capsys) -> None:
    from scenarios.bench.merge import methods as merge_methods

    def identity(m1: GridMap, m2: GridMap, rng: np.random.Generator) -> np.ndarray:
        return np.zeros(3)

    monkeypatch.setattr(merge_methods, "_METHODS", {"identity": (identity, ())})
    argv = ["bench", "merge", "--set", "cuts", "--cut-pairs", "4", "--seed", "2"]
    argv += ["--methods", "identity", "--variants", "none", "--no-aliasing"]
    out = tmp_path / "rows.json"
    assert main([*argv, "--cache", str(tmp_path), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "4 pairs (4 overlapping)" in printed and "| | identity |" in printed
    rows = json.loads(out.read_text())["rows"]
    assert [row["scenario"].startswith("cut:") for row in rows] == [True] * 4
    assert {row["family"] for row in rows} == {"real"}
    # a turned map 2 is never at the identity: a wrong answer on every pair
    assert all(row["outcome"] == "wrong" for row in rows)
    assert len(list(tmp_path.glob("cuts-v*-n4-seed2-*/manifest.json"))) == 1
