"""The merge benchmark on real maps: pairs from real buildings and map files, the variants
users meet, the proposal recall, the per-family table (plumbing only, tiny configs)."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from mrslam_env.evaluation import relative_transform_error
from mrslam_env.geometry import transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.mapio import map_images
from scenarios.bench.merge import methods as merge_methods
from scenarios.bench.merge import pairs as merge_pairs
from scenarios.bench.merge.pairs import (
    MergePair,
    PairGenerationConfig,
    generate_pairs,
    map_label,
    world_family,
)
from scenarios.bench.merge.report import format_family_breakdown, format_merge_table, summarize
from scenarios.bench.merge.run import (
    PAD_CELLS,
    VARIANT_YAW,
    make_variant,
    pad_grid,
    run_merge_benchmark,
    yaw_variant,
)
from scenarios.cli import main
from scenarios.worlds.real import map_file

TRUTH = np.array([0.4, -0.3, 0.2])


def room() -> GridMap:
    cells = np.full((40, 60), FREE, dtype=np.int8)
    cells[[0, -1], :] = OCCUPIED
    cells[:, [0, -1]] = OCCUPIED
    cells[:20, 25] = OCCUPIED
    cells[35:, 50:] = UNKNOWN
    return GridMap(cells=cells, resolution=0.05, origin=(-1.0, 0.5))


def pair(pair_id: str = "000-bookstore", scenario: str = "bookstore", overlap=0.6) -> MergePair:
    return MergePair(
        pair_id=pair_id,
        scenario=scenario,
        m1=room(),
        m2=room(),
        map1_from_map2=TRUTH.copy(),
        overlap=overlap,
    )


class StubPipeline:
    """Answers the truth plus an offset; its candidates: the truth and a far one."""

    def __call__(self, m1, m2, rng):
        return self.answer(m1, m2, rng)[0]

    def answer(self, m1, m2, rng):
        return None, [np.array([9.0, 9.0, 0.0]), TRUTH.copy()]


# --- pairs -----------------------------------------------------------------------------------


def test_default_cache_key_is_unchanged() -> None:
    # the built-in set's figures are compared across releases: its key must not move by
    # accident (it moves with the SLAM defaults: 0211c70fe7 before the map's weaker miss in
    # cells that hold hits, issue 20; docs/benchmarks.md "Onboard SLAM" compares the two;
    # abda62f3e8 before SlamConfig.match_lag, issue 20)
    assert PairGenerationConfig().cache_key() == "v1-n40-seed0-5b8e42e60a"


def test_the_cache_key_follows_the_map_files_contents(tmp_path) -> None:
    source = map_file("tb3_sandbox")
    copy = tmp_path / "sandbox_copy.yaml"
    copy.write_text(source.read_text())
    for image in map_images(source):
        shutil.copy(image, tmp_path / image.name)
    config = PairGenerationConfig(maps=(str(copy),))
    before = config.cache_key()
    copy.write_text(source.read_text().replace("resolution: 0.05", "resolution: 0.06"))
    assert config.cache_key() != before  # an edited map is another world: no stale pairs


def test_pairs_from_a_real_building_and_a_map_file(tmp_path) -> None:
    source = map_file("tb3_sandbox")
    copy = tmp_path / "sandbox_copy.yaml"
    copy.write_text(source.read_text())
    for image in map_images(source):
        shutil.copy(image, tmp_path / image.name)
    config = PairGenerationConfig(
        n_pairs=3,
        worlds=("tb3_sandbox",),
        maps=(str(copy),),
        runs_per_world=2,
        checkpoints=(60, 120),
        no_overlap_fraction=0.0,
        min_known_area=1.0,
        native_resolution=True,
    )
    assert config.labels() == ["tb3_sandbox", "map:sandbox_copy"]
    assert config.cache_key() != PairGenerationConfig(n_pairs=3).cache_key()
    assert config.slam_config("map:sandbox_copy").grid.resolution == pytest.approx(0.05)
    pairs = generate_pairs(config, tmp_path / "pairs")
    assert {p.scenario for p in pairs} <= {"tb3_sandbox", "map:sandbox_copy"}
    assert len(pairs) == 3 and all(p.overlap > 0 for p in pairs)
    assert all((tmp_path / "pairs" / f"{p.pair_id}-m1.yaml").exists() for p in pairs)
    assert all(":" not in p.pair_id for p in pairs)


def test_world_families_and_labels() -> None:
    assert world_family("bookstore") == "real"
    assert world_family(map_label("/some/plant.yaml")) == "real"
    assert world_family("office") == "built-in"
    assert world_family("procedural-1") == "built-in"
    with pytest.raises(ValueError, match="distinct"):
        PairGenerationConfig(worlds=(), maps=("a/x.yaml", "b/x.yaml"))


# --- variants --------------------------------------------------------------------------------


def test_padding_keeps_every_cell_in_place() -> None:
    grid = room()
    padded = pad_grid(grid, 300)
    assert padded.shape == (300, 300)
    assert (padded.cells != UNKNOWN).sum() == (grid.cells != UNKNOWN).sum()
    centres = grid.cell_to_world(np.argwhere(grid.occupied))
    assert (padded.cells[tuple(padded.world_to_cell(centres).T)] == OCCUPIED).all()
    assert pad_grid(grid).shape == (PAD_CELLS, PAD_CELLS)


def test_yaw_variant_turns_map_2_and_moves_the_truth_by_the_yaw() -> None:
    changed = yaw_variant(pair())
    assert changed.map1_from_map2[2] == pytest.approx(TRUTH[2] - VARIANT_YAW)
    # the file rotates the grid about its origin corner: the two truths agree there
    corner = np.array(room().origin)
    translation, rotation = relative_transform_error(changed.map1_from_map2, TRUTH, corner)
    assert translation == pytest.approx(0.0, abs=1e-9)
    assert math.degrees(rotation) == pytest.approx(math.degrees(VARIANT_YAW))
    # the grid read is the room in the file's frame: under the new truth its walls land
    # where the old truth puts the room's walls
    old_walls = transform_points(TRUTH, room().cell_to_world(np.argwhere(room().occupied)))
    new_walls = transform_points(
        changed.map1_from_map2, changed.m2.cell_to_world(np.argwhere(changed.m2.occupied))
    )
    nearest = np.linalg.norm(new_walls[:, None, :] - old_walls[None, :, :], axis=2).min(axis=1)
    assert nearest.max() <= room().resolution


def test_resolution_variant() -> None:
    changed, notes = make_variant(pair(), "res")
    assert changed.m2.resolution == pytest.approx(0.1) and notes["variant_resolution"] == 0.1
    with pytest.raises(ValueError, match="unknown variant"):
        make_variant(pair(), "bogus")


def test_variant_rows_and_proposal_recall() -> None:
    pairs = [pair(), pair("001-office", "office", overlap=0.0)]
    rows = run_merge_benchmark(
        pairs, {"ours": StubPipeline()}, warm_up=False, variants=("yaw", "res")
    )
    methods = [r["method"] for r in rows]
    assert methods == ["ours", "ours+yaw", "ours+res"] * 2
    first = rows[0]
    assert first["family"] == "real" and first["variant"] is None and first["candidates"] == 2
    assert first["proposal_hit"] is True
    assert rows[1]["variant"] == "yaw" and rows[1]["variant_yaw"] == VARIANT_YAW
    assert rows[1]["proposal_hit"] is False  # the truth moved by the yaw
    assert rows[3]["proposal_hit"] is None  # no overlap
    summary = summarize(rows, ["ours", "ours+yaw", "ours+res"])
    assert summary["ours"]["proposal_recall_overlapping"] == 1.0
    assert summary["ours+yaw"]["proposal_recall_overlapping"] == 0.0
    table = format_merge_table(summary)
    assert "| proposal recall, overlapping pairs" in table and "| 100% | 0% |" in table
    family = format_family_breakdown(rows, ["ours"])
    assert "| ours | real | 1 |" in family and "| ours | built-in | 1 |" in family


# --- the CLI ---------------------------------------------------------------------------------


def test_cli_custom_set_from_names_and_maps(tmp_path, monkeypatch, capsys) -> None:
    seen = []

    def load(config, cache, *, regenerate=False, progress=None, jobs=1, ray=None):
        seen.append(config)
        pairs = [pair(), pair("001-map-plant", "map:plant", overlap=0.5)]
        return pairs, {"generation_seconds": 1.0, "shortfall": 0}

    monkeypatch.setattr(merge_pairs, "load_or_generate_pairs", load)
    monkeypatch.setattr(merge_methods, "_METHODS", {"ours": (StubPipeline(), ())})
    out = tmp_path / "rows.json"
    argv = ["bench", "merge", "--worlds", "bookstore", "--maps", "x/plant.yaml", "--pairs", "2"]
    argv += ["--methods", "ours", "--variants", "pad4000", "--no-aliasing", "--out", str(out)]
    assert main([*argv, "--cache", str(tmp_path)]) == 0
    (config,) = seen
    assert config.worlds == ("bookstore",) and config.maps == ("x/plant.yaml",)
    printed = capsys.readouterr().out
    assert "## custom: bookstore, map:plant" in printed
    assert "| | ours | ours+pad4000 |" in printed
    saved = json.loads(out.read_text())
    assert [r["method"] for r in saved["rows"]] == ["ours", "ours+pad4000"] * 2


def test_cli_default_reports_both_sets_side_by_side(tmp_path, monkeypatch, capsys) -> None:
    seen = []

    def load(config, cache, *, regenerate=False, progress=None, jobs=1, ray=None):
        seen.append(config)
        if config.worlds == merge_pairs.DEFAULT_WORLDS:
            return [pair("000-office", "office")], {"generation_seconds": 1.0, "shortfall": 0}
        return [pair()], {"generation_seconds": 2.0, "shortfall": 0}

    monkeypatch.setattr(merge_pairs, "load_or_generate_pairs", load)
    monkeypatch.setattr(merge_methods, "_METHODS", {"ours": (StubPipeline(), ())})
    argv = ["bench", "merge", "--methods", "ours", "--variants", "none", "--no-aliasing"]
    assert main([*argv, "--cache", str(tmp_path)]) == 0
    assert seen[0].cache_key() == PairGenerationConfig().cache_key()
    assert seen[1].worlds == merge_pairs.REAL_WORLDS and seen[1].native_resolution
    printed = capsys.readouterr().out
    assert "## built-in worlds" in printed and "## real buildings" in printed
    assert "| ours | built-in | 1 |" in printed and "| ours | real | 1 |" in printed
    assert main([*argv, "--cache", str(tmp_path), "--variants", "bogus"]) == 2
