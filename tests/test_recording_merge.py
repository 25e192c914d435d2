"""``Recorder.log_merge``: the merge stages under ``merge/*`` (docs/design.md §7), read back.

A merge made with ``trace=True`` is logged into a temporary ``.rrd`` file and read back with
Rerun's own reader (the ``Recording`` helper of ``test_recording``): the entity paths, that
everything drawn in the ``merge`` view lines up in map 1's frame (the inputs, the fused
map, skeletons, virtual runs and scans, MCL particles, hypotheses, the random walk), the
scalars, and a refusal's recording. ``mrslam merge --rrd`` writes the same entities.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from merge_fixtures import map_pair
from scipy import ndimage
from test_recording import Recording

from mrslam_env.geometry import inverse, transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.mapio import load_map, save_map
from mrslam_env.merge.pipeline import MergeConfig, MergeResult, merge_maps
from mrslam_env.merge.skeleton import SkeletonConfig, clean_free_space
from mrslam_env.recording import Recorder, scan_hits_world
from scenarios.cli import main

STEP, SIM_TIME = 5, 0.5
TRUTH = np.array([1.1, -0.4, -1.9])  # maze windows overlapping by about 60 %
MERGE_ENTITIES = {
    "/merge/map1",
    "/merge/map2",
    "/merge/skeleton/map1",
    "/merge/skeleton/map2",
    "/merge/virtual_robot/path",
    "/merge/virtual_robot/scan",
    "/merge/mcl/particles",
    "/merge/hypotheses",
    "/merge/refine/candidate",
    "/merge/refine/best",
    "/merge/result",
    "/metrics/merge/psi",
    "/metrics/merge/acceptance_index",
}
PIXEL = {UNKNOWN: 0, FREE: 1, OCCUPIED: 2}  # recording.occupancy_classes, style "map"


@dataclass(frozen=True)
class Logged:
    m1: GridMap
    m2: GridMap
    result: MergeResult
    recording: Recording


def _log(path: Path, result: MergeResult, m1: GridMap, m2: GridMap) -> Recording:
    with Recorder(path, n_robots=2) as recorder:
        recorder.set_time(STEP, SIM_TIME)
        recorder.log_merge(result, m1, m2)
        recorder.log_event("after the merge")
    return Recording(path)


@pytest.fixture(scope="module")
def merged(tmp_path_factory: pytest.TempPathFactory) -> Logged:
    m1, m2 = map_pair("maze", (5.0, 5.0), (9.0, 7.0), TRUTH)
    result = merge_maps(m1, m2, rng=0, trace=True)
    assert result.merged and result.trace is not None, result.reason
    path = tmp_path_factory.mktemp("merge") / "merge.rrd"
    return Logged(m1, m2, result, _log(path, result, m1, m2))


@pytest.fixture(scope="module")
def refused(tmp_path_factory: pytest.TempPathFactory) -> Logged:
    m1, m2 = map_pair("office", (4.0, 4.0), (23.0, 12.0), np.array([1.0, 2.0, 0.5]))
    result = merge_maps(m1, m2, rng=0, trace=True)
    assert not result.merged, result.reason
    path = tmp_path_factory.mktemp("refused") / "refused.rrd"
    return Logged(m1, m2, result, _log(path, result, m1, m2))


def only(recording: Recording, entity: str, column: str) -> Any:
    (row,) = recording.at_step(entity, column, STEP)
    return row


def grid_image(recording: Recording, entity: str) -> np.ndarray:
    """A logged map's class-id image, row 0 = lowest y (as our grids)."""
    fmt = recording.column(entity, "SegmentationImage:format")[0][0]
    data = np.array(recording.column(entity, "SegmentationImage:buffer")[0][0], dtype=np.uint8)
    return data.reshape(fmt["height"], fmt["width"])


# -- what is in the file ---------------------------------------------------------------------


def test_merge_entities_are_recorded(merged: Logged) -> None:
    assert set(merged.recording.chunks) >= MERGE_ENTITIES
    assert "/metrics/merge/seconds" in merged.recording.chunks


def test_single_shot_entities_are_at_the_current_step(merged: Logged) -> None:
    recording = merged.recording
    for entity, column in [
        ("/merge/map1", "Transform3D:translation"),
        ("/merge/result", "Transform3D:translation"),
        ("/merge/hypotheses", "Arrows2D:origins"),
        ("/merge/refine/best", "Arrows2D:origins"),
        ("/metrics/merge/psi", "Scalars:scalars"),
    ]:
        assert recording.column(entity, "step") == [STEP], entity
        assert recording.at_step(entity, column, STEP), entity
    # The iteration timeline is reset afterwards: later data is on step / sim_time only.
    for batch in recording.batches("/events"):
        assert "merge_iteration" not in batch.schema.names
    texts = [t[0] for t in recording.column("/events", "TextLog:text")]
    assert texts == [f"#{STEP:<5} {merged.result.reason}", f"#{STEP:<5} after the merge"]


def test_inputs_and_fused_map_line_up_in_map1_frame(merged: Logged) -> None:
    recording, m1, m2, result = merged.recording, merged.m1, merged.m2, merged.result
    assert result.transform is not None and result.fused is not None
    # Map 1 and the fused map are drawn as they are: in map 1's frame, unturned.
    for entity, grid in (("/merge/map1", m1), ("/merge/result", result.fused)):
        (translation,) = only(recording, entity, "Transform3D:translation")
        (rotation,) = only(recording, entity, "Transform3D:rotation_axis_angle")
        np.testing.assert_allclose(translation, [*grid.origin, 0.0], atol=1e-6)
        assert rotation["angle"] == pytest.approx(0.0, abs=1e-9)
        (scale,) = only(recording, entity, "Transform3D:scale")
        np.testing.assert_allclose(scale, [m1.resolution, m1.resolution, 1.0])
    # The fused grid is on m1's lattice (whole cells apart; it spans both maps' known
    # areas) ...
    fused = result.fused
    offset = (np.asarray(m1.origin) - np.asarray(fused.origin)) / fused.resolution
    col0, row0 = np.rint(offset).astype(int)
    np.testing.assert_allclose(offset, [col0, row0], atol=1e-6)
    # ... so its image, where map 1 has walls, shows walls at the same places.
    image = grid_image(recording, "/merge/result")
    assert image.shape == fused.shape
    walls = np.argwhere(m1.occupied) + np.array([row0, col0])
    known = np.argwhere(~m1.unknown) + np.array([row0, col0])
    assert fused.contains(known).all()
    assert np.all(image[walls[:, 0], walls[:, 1]] == PIXEL[OCCUPIED])
    assert np.all(image[known[:, 0], known[:, 1]] != PIXEL[UNKNOWN])
    np.testing.assert_array_equal(image == PIXEL[OCCUPIED], fused.occupied)
    # Map 2 is placed by the answer: its corner moved, its axes turned.
    (translation,) = only(recording, "/merge/map2", "Transform3D:translation")
    (rotation,) = only(recording, "/merge/map2", "Transform3D:rotation_axis_angle")
    corner = transform_points(result.transform, np.array([m2.origin]))[0]
    np.testing.assert_allclose(translation, [*corner, 0.0], atol=1e-5)
    assert rotation["angle"] == pytest.approx(result.transform[2], abs=1e-6)


def _cleaning(config: SkeletonConfig) -> dict[str, float]:
    return {
        "clearance": config.clearance,
        "min_hole_area": config.min_hole_area,
        "smoothing_radius": config.smoothing_radius,
        "min_component_area": config.min_component_area,
    }


def test_skeletons_and_virtual_runs_lie_on_map1_free_space(merged: Logged) -> None:
    recording, result = merged.recording, merged.result
    assert result.trace is not None
    working1 = result.trace.working1

    def cells_of(points: np.ndarray, grid: GridMap) -> np.ndarray:
        cells = grid.world_to_cell(points)
        assert grid.contains(cells).all()
        return grid.cells[cells[:, 0], cells[:, 1]]

    skeleton1 = only(recording, "/merge/skeleton/map1", "Points2D:positions")
    skeleton1 = np.asarray(skeleton1, dtype=np.float64)
    assert len(skeleton1) == np.count_nonzero(result.trace.hypotheses.skeleton1.skeleton)
    # On map 1's cleaned free space (FREE cells plus the small holes and noise specks
    # the cleaning fills; the skeleton may cross a speck), drawn where it belongs.
    cleaned = clean_free_space(working1, **_cleaning(MergeConfig().virtual.skeleton))
    at = working1.world_to_cell(skeleton1)
    assert cleaned[at[:, 0], at[:, 1]].all()
    assert np.mean(cells_of(skeleton1, working1) == FREE) >= 0.99
    # Map 2's skeleton is drawn where the answer puts it: on map 2's free space.
    skeleton2 = only(recording, "/merge/skeleton/map2", "Points2D:positions")
    assert result.transform is not None
    back = transform_points(inverse(result.transform), np.asarray(skeleton2, dtype=np.float64))
    assert np.mean(cells_of(back, result.trace.working2) == FREE) >= 0.999
    # One strip per virtual run, through its poses, on map 1's cleaned free space.
    runs = result.trace.hypotheses.runs
    strips = only(recording, "/merge/virtual_robot/path", "LineStrips2D:strips")
    assert len(strips) == len(runs) >= 2
    on_free, on_cleaned = [], []
    for strip, run in zip(strips, runs, strict=True):
        np.testing.assert_allclose(strip, run.poses_in_map1[:, :2], atol=1e-5)
        points = np.asarray(strip, dtype=np.float64)
        on_free.extend(cells_of(points, working1) == FREE)
        at = working1.world_to_cell(points)
        on_cleaned.extend(cleaned[at[:, 0], at[:, 1]])
    assert all(on_cleaned)
    assert np.mean(on_free) >= 0.99


def test_virtual_scans_hit_map1_walls(merged: Logged) -> None:
    recording, result = merged.recording, merged.result
    assert result.trace is not None
    runs = result.trace.hypotheses.runs
    rows = recording.column("/merge/virtual_robot/scan", "Points2D:positions")
    iterations = recording.column("/merge/virtual_robot/scan", "merge_iteration")
    assert len(rows) == sum(len(run.poses_in_map1) for run in runs)
    assert iterations == list(range(len(rows)))
    first = runs[0]
    reference = scan_hits_world(
        first.poses_in_map1[0],
        np.nan_to_num(first.ranges[0], nan=first.max_range),
        first.beam_angles,
        first.max_range,
    )
    np.testing.assert_allclose(rows[0], reference, atol=1e-4)
    # Returns end on walls of the map the virtual robot scans (within a working cell).
    working1 = result.trace.working1
    near_wall = ndimage.binary_dilation(working1.occupied, iterations=1)
    hits = np.concatenate([np.asarray(r, dtype=np.float64).reshape(-1, 2) for r in rows])
    cells = working1.world_to_cell(hits)
    inside = working1.contains(cells)
    assert inside.all()
    assert np.mean(near_wall[cells[:, 0], cells[:, 1]]) >= 0.99


def test_particles_are_the_mcl_history_placed_by_the_answer(merged: Logged) -> None:
    recording, result = merged.recording, merged.result
    assert result.trace is not None and result.transform is not None
    hypotheses = result.trace.hypotheses
    rows = recording.column("/merge/mcl/particles", "Points2D:positions")
    assert len(rows) == sum(len(r.history) for r in hypotheses.mcl_results) > 0
    history = hypotheses.mcl_results[0].history
    for t in (0, len(history) - 1):
        expected = transform_points(result.transform, history[t][:, :2])
        np.testing.assert_allclose(rows[t], expected, atol=1e-4)
    # Iterations of the particles share the scans' timeline.
    scan_iterations = set(recording.column("/merge/virtual_robot/scan", "merge_iteration"))
    assert set(recording.column("/merge/mcl/particles", "merge_iteration")) <= scan_iterations


def test_hypotheses_and_random_walk(merged: Logged) -> None:
    recording, result = merged.recording, merged.result
    assert result.trace is not None and result.transform is not None
    origins = np.asarray(only(recording, "/merge/hypotheses", "Arrows2D:origins"))
    labels = only(recording, "/merge/hypotheses", "Arrows2D:labels")
    expected = np.array([h.map1_from_map2[:2] for h in result.hypotheses])
    np.testing.assert_allclose(origins, expected, atol=1e-5)
    assert len(labels) == len(result.hypotheses)
    assert labels[0].startswith("#0 the virtual robot: agreement ")
    # The best candidate's random walk: every proposal, after the virtual robot's stages.
    walk = result.trace.refinements[0].trace
    assert walk is not None
    candidates = recording.column("/merge/refine/candidate", "Points2D:positions")
    assert len(candidates) == len(walk.candidates)
    # Each proposal is drawn where it puts map 2's origin.
    np.testing.assert_allclose(np.concatenate(candidates), walk.candidates[:, :2], atol=1e-4)
    first = min(recording.column("/merge/refine/candidate", "merge_iteration"))
    assert first > max(recording.column("/merge/virtual_robot/scan", "merge_iteration"))
    best_psi = np.array(
        [v[0] for v in recording.column("/metrics/merge/refine_psi", "Scalars:scalars")]
    )
    assert len(best_psi) == len(walk.candidates)
    assert np.all(np.diff(best_psi[np.isfinite(best_psi)]) <= 1e-9)  # never increases
    (best,) = only(recording, "/merge/refine/best", "Arrows2D:origins")
    np.testing.assert_allclose(best, result.transform[:2], atol=1e-5)


def test_scalars_are_the_result(merged: Logged) -> None:
    recording, result = merged.recording, merged.result
    assert result.agreement is not None
    (psi,) = only(recording, "/metrics/merge/psi", "Scalars:scalars")
    (index,) = only(recording, "/metrics/merge/acceptance_index", "Scalars:scalars")
    (seconds,) = only(recording, "/metrics/merge/seconds", "Scalars:scalars")
    assert psi == pytest.approx(result.psi)
    assert index == pytest.approx(result.agreement.index)
    assert seconds == pytest.approx(result.seconds["total"])


# -- a refusal -------------------------------------------------------------------------------


def test_refusal_draws_map2_beside_map1_and_no_result(refused: Logged) -> None:
    recording, m1, m2, result = refused.recording, refused.m1, refused.m2, refused.result
    entities = set(recording.chunks)
    assert {
        "/merge/map1",
        "/merge/map2",
        "/merge/skeleton/map2",
        "/merge/mcl/particles",
    } <= entities
    assert not {"/merge/result", "/merge/refine/best", "/metrics/merge/psi"} & entities
    (translation,) = only(recording, "/merge/map2", "Transform3D:translation")
    (rotation,) = only(recording, "/merge/map2", "Transform3D:rotation_axis_angle")
    assert translation[0] > m1.extent[2]  # right of map 1, not overlapping it
    assert translation[1] == pytest.approx(m1.origin[1])
    assert rotation["angle"] == pytest.approx(0.0, abs=1e-9)
    assert m2.cells.size > 0
    texts = [t[0] for t in recording.column("/events", "TextLog:text")]
    assert texts[0] == f"#{STEP:<5} {result.reason}"
    assert result.reason.startswith("no confident merge")


# -- mrslam merge --rrd ------------------------------------------------------------------------


def test_cli_merge_writes_the_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    m1, m2 = map_pair("maze", (5.0, 5.0), (9.0, 7.0), TRUTH)
    map1, map2 = save_map(tmp_path / "m1.yaml", m1), save_map(tmp_path / "m2.yaml", m2)
    rrd = tmp_path / "merge.rrd"
    status = main(
        ["merge", str(map1), str(map2), "--rrd", str(rrd), "-o", str(tmp_path / "o.yaml")]
    )
    out, err = capsys.readouterr()
    assert status == 0, err
    recording = Recording(rrd)
    assert set(recording.chunks) >= MERGE_ENTITIES
    loaded = load_map(map1)
    (translation,) = recording.column("/merge/map1", "Transform3D:translation")[0]
    np.testing.assert_allclose(translation, [*loaded.origin, 0.0], atol=1e-6)
    fused = load_map(tmp_path / "o.yaml")
    (translation,) = recording.column("/merge/result", "Transform3D:translation")[0]
    np.testing.assert_allclose(translation, [*fused.origin, 0.0], atol=1e-6)
    assert grid_image(recording, "/merge/result").shape == fused.shape
    assert "map1_from_map2" in out


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> tuple[Recording, Path]:
    """The default run (office, seed 0) to step 300: merge attempt 4 is refused at step
    126, its hypothesis from the virtual robot verified and accepted at step 135."""
    from scenarios.experiment import RunConfig, run_experiment

    out = tmp_path_factory.mktemp("live")
    report = run_experiment(RunConfig(out=out, max_steps=300, figure=False, progress=False))
    run_dir = Path(report["outputs"]["recording"]).parent
    return Recording(run_dir / "recording.rrd"), run_dir


def test_live_merge_view_and_events_tell_one_story(live: tuple[Recording, Path]) -> None:
    """Issue 39: the Merge view stayed on the refused attempt 4, and its WARN contradicted
    the acceptance without naming where the verified hypothesis came from."""
    recording, _ = live
    wrapped = {
        step: labels[0]
        for batch in recording.batches("/merge/caption", static=False)
        for step, labels in zip(
            batch.column("step").to_pylist(),
            batch.column("Points2D:labels").to_pylist(),
            strict=True,
        )
        if labels
    }
    # Long captions are wrapped into lines that fit a half-width view.
    assert all(len(line) <= 64 for text in wrapped.values() for line in text.split("\n"))
    assert any("\n" in text for text in wrapped.values())
    captions = {step: " ".join(text.split()) for step, text in wrapped.items()}
    assert captions[126].startswith("hypothesis #0 (1 of 1), from the virtual robot")
    assert "verifying at the rendezvous" in captions[126]
    assert captions[135].startswith("robot_1: accepted at step 135, refined: ")
    assert "refined: " in captions[135] and "from the verified estimate" in captions[135]
    assert max(captions) == 135  # nothing replaces the accepted merge before step 300
    # After acceptance the Merge view holds the accepted transform and the fused map.
    assert recording.at_step("/merge/result", "SegmentationImage:format", 135)
    assert recording.at_step("/merge/refine/best", "Arrows2D:origins", 135)
    assert recording.at_step("/merge/skeleton/map1", "Clear:is_recursive", 126) == [[False]]
    texts = [t[0] for t in recording.column("/events", "TextLog:text")]
    levels = [t[0] for t in recording.column("/events", "TextLog:level")]
    (refusal,) = [
        (t, lv) for t, lv in zip(texts, levels, strict=True) if "merge attempt 4 (robot" in t
    ]
    assert refusal[1] == "WARN" and " refused: no confident merge" in refusal[0]
    assert "hypothesis #0 (from the virtual robot, agreement" in refusal[0]
    assert "goes to verification by rendezvous" in refusal[0]
    assert not any("hypotheses to verify by rendezvous" in t for t in texts)
    (accepted,) = [t for t in texts if "map accepted at step 135" in t]
    assert "from the virtual robot (merge attempt 4)" in accepted


def test_live_team_map_is_current(live: tuple[Recording, Path]) -> None:
    """Issue 39: the Team view showed robot 0's stale view of the merged map; it is the
    fusion of every robot's current map, logged whenever it changed."""
    recording, run_dir = live
    steps = sorted(set(recording.column("/team/merged_map", "step")))
    assert steps[0] == 135  # at the acceptance, not at the next step maps are due
    # At the last step, the map logged in the loop is the run's merged map (merged.yaml).
    merged = load_map(run_dir / "merged.yaml")
    images = [
        np.array(buffer[0], dtype=np.uint8).reshape(fmt[0]["height"], fmt[0]["width"])
        for buffer, fmt in zip(
            recording.at_step("/team/merged_map", "SegmentationImage:buffer", 300),
            recording.at_step("/team/merged_map", "SegmentationImage:format", 300),
            strict=True,
        )
    ]
    assert len(images) == 2  # the loop's and the run's end
    expected = np.full(merged.cells.shape, 0, dtype=np.uint8)
    expected[merged.cells == FREE] = 1
    expected[merged.cells == OCCUPIED] = 2
    for image in images:
        np.testing.assert_array_equal(image, expected)
