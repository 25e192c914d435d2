"""The Rerun recorder, read back with Rerun's own reader (``rerun.chunk.RrdReader``).

A small recording is written to a temporary file once per module and its chunks are
checked: entity paths (docs/design.md §7), timelines, per-step content, static ground truth, the
blueprint, and that maps and poses line up under Rerun's placement rules.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from mrslam_env.geometry import transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.recording import (
    Recorder,
    grid_corner_pose,
    occupancy_classes,
    occupancy_image,
    scan_hits_world,
)
from mrslam_env.sim.world import WorldSpec, box, ground_truth_map

N_STEPS = 6
DT = 0.1  # s per step
N_BEAMS = 36
MAX_RANGE = 5.0
ANGLES = np.linspace(-np.pi, np.pi, N_BEAMS, endpoint=False)
MAP_FROM_WORLD = np.array([1.0, -0.5, 0.3])  # robot_0/map placement in the test


def make_world() -> WorldSpec:
    return WorldSpec.from_walls(
        "box",
        [box(0, 0, 10, 0.1), box(0, 0, 0.1, 10), box(9.9, 0, 10, 10), box(0, 9.9, 10, 10)],
        [(2, 2, 0), (8, 8, 3.14)],
    )


def true_pose(robot: int, step: int) -> np.ndarray:
    start = np.array([[2.0, 2.0, 0.0], [8.0, 8.0, 3.14]])[robot]
    return start + np.array([0.1 * step, 0.0, 0.05 * step])


def scan_ranges(step: int) -> np.ndarray:
    """``step`` max-range returns, one NaN dropout, the rest hits at 1 + beam/10 m."""
    ranges = 1.0 + np.arange(N_BEAMS) / 10.0
    ranges[:step] = MAX_RANGE
    ranges[-1] = np.nan
    return ranges


def expected_hits(step: int) -> int:
    return N_BEAMS - step - 1


class Recording:
    """The chunks of one .rrd file, grouped by entity path."""

    def __init__(self, path: Path) -> None:
        self.reader = RrdReader(path)
        self.chunks: dict[str, list[Any]] = {}
        for chunk in self.reader.stream():
            self.chunks.setdefault(chunk.entity_path, []).append(chunk)

    def batches(self, entity: str, *, static: bool | None = None) -> Iterator[pa.RecordBatch]:
        for chunk in self.chunks.get(entity, []):
            if static is None or chunk.is_static == static:
                yield chunk.to_record_batch()

    def column(self, entity: str, column: str, *, static: bool | None = None) -> list[Any]:
        """All rows of one column, concatenated over the entity's chunks."""
        rows: list[Any] = []
        for batch in self.batches(entity, static=static):
            if column in batch.schema.names:
                rows.extend(batch.column(column).to_pylist())
        return rows

    def at_step(self, entity: str, column: str, step: int) -> list[Any]:
        """The component values logged on ``entity`` at ``step`` (one list per row)."""
        rows: list[Any] = []
        for batch in self.batches(entity, static=False):
            if column not in batch.schema.names:  # e.g. a Clear's chunk
                continue
            steps = batch.column("step").to_pylist()
            values = batch.column(column).to_pylist()
            rows.extend(
                v for s, v in zip(steps, values, strict=True) if s == step and v is not None
            )
        return rows

    def static_value(self, entity: str, column: str) -> Any:
        rows = self.column(entity, column, static=True)
        assert rows, f"no static {column} on {entity}"
        return rows[-1]


@pytest.fixture(scope="module")
def world() -> WorldSpec:
    return make_world()


@pytest.fixture(scope="module")
def ground_truth(world: WorldSpec) -> GridMap:
    return ground_truth_map(world, 0.1)


@pytest.fixture(scope="module")
def recording(
    tmp_path_factory: pytest.TempPathFactory, world: WorldSpec, ground_truth: GridMap
) -> Recording:
    path = tmp_path_factory.mktemp("rec") / "recording.rrd"
    with Recorder(path, recording_name="test", n_robots=2, map_every=2) as recorder:
        recorder.log_ground_truth(world, ground_truth)
        recorder.log_event("recording started")
        for step in range(N_STEPS):
            recorder.set_time(step, step * DT)
            for robot in range(2):
                pose = true_pose(robot, step)
                recorder.log_true_pose(robot, pose)
                recorder.log_scan(robot, pose, scan_ranges(step), ANGLES, MAX_RANGE)
            recorder.log_scalar("coverage", 0.1 * step)
            recorder.log_event(f"step {step}", level="warning" if step == 4 else "INFO")
            if recorder.map_due:
                recorder.log_grid("robot_0/map", ground_truth, parent_from_grid=MAP_FROM_WORLD)
    return Recording(path)


# -- what is in the file ---------------------------------------------------------------


def test_entity_paths_follow_design(recording: Recording) -> None:
    expected = {
        "/world/ground_truth",
        "/world/walls",
        "/world/robot_0/true_pose",
        "/world/robot_1/true_pose",
        "/world/robot_0/scan",
        "/world/robot_1/scan",
        "/robot_0/map",
        "/metrics/coverage",
        "/events",
    }
    assert expected <= set(recording.chunks)


def test_timelines_are_step_and_sim_time(recording: Recording) -> None:
    temporal = [c for cs in recording.chunks.values() for c in cs if not c.is_static]
    assert temporal
    # Wall-clock log_time is off: a recording depends on the simulation only.
    assert all(set(c.timeline_names) == {"step", "sim_time"} for c in temporal)
    batch = next(recording.batches("/metrics/coverage", static=False))
    assert pa.types.is_integer(batch.schema.field("step").type)
    assert pa.types.is_duration(batch.schema.field("sim_time").type)
    steps = recording.column("/metrics/coverage", "step", static=False)
    times = recording.column("/metrics/coverage", "sim_time", static=False)
    assert steps == list(range(N_STEPS))
    np.testing.assert_allclose([t.total_seconds() for t in times], np.arange(N_STEPS) * DT)


def test_scan_at_step_3_has_the_hits_of_that_scan(recording: Recording) -> None:
    rows = recording.at_step("/world/robot_0/scan", "Points2D:positions", 3)
    assert len(rows) == 1
    points = np.array(rows[0])
    assert points.shape == (expected_hits(3), 2)
    reference = scan_hits_world(true_pose(0, 3), scan_ranges(3), ANGLES, MAX_RANGE)
    np.testing.assert_allclose(points, reference, atol=1e-5)
    for step in range(N_STEPS):
        (row,) = recording.at_step("/world/robot_1/scan", "Points2D:positions", step)
        assert len(row) == expected_hits(step)


def test_true_pose_has_disc_arrow_and_footprint(recording: Recording) -> None:
    entity = "/world/robot_1/true_pose"
    (centre,) = recording.at_step(entity, "Points2D:positions", 2)
    (radius,) = recording.at_step(entity, "Points2D:radii", 2)
    (label,) = recording.at_step(entity, "Points2D:labels", 2)
    (origin,) = recording.at_step(entity, "Arrows2D:origins", 2)
    (vector,) = recording.at_step(entity, "Arrows2D:vectors", 2)
    (half,) = recording.at_step(entity, "Ellipses2D:half_sizes", 2)
    pose = true_pose(1, 2)
    # The footprint at its true size (m): a disc, its outline, a heading arrow twice as long.
    np.testing.assert_allclose(centre[0], pose[:2], atol=1e-6)
    assert radius == [pytest.approx(0.2)]
    assert label == ["robot_1"]
    np.testing.assert_allclose(origin[0], pose[:2], atol=1e-6)
    np.testing.assert_allclose(
        vector[0], 0.4 * np.array([np.cos(pose[2]), np.sin(pose[2])]), atol=1e-6
    )
    np.testing.assert_allclose(half[0], [0.2, 0.2], atol=1e-6)


def test_ground_truth_is_static_and_complete(
    recording: Recording, world: WorldSpec, ground_truth: GridMap
) -> None:
    assert all(c.is_static for c in recording.chunks["/world/ground_truth"])
    assert all(c.is_static for c in recording.chunks["/world/walls"])
    entity = "/world/ground_truth"
    fmt = recording.static_value(entity, "SegmentationImage:format")[0]
    rows, cols = ground_truth.shape
    assert (fmt["height"], fmt["width"]) == (rows, cols)
    data = np.array(recording.static_value(entity, "SegmentationImage:buffer")[0], dtype=np.uint8)
    # Image row 0 is the grid's row 0 (lowest y): the root's y-up turn draws it at the bottom.
    classes = data.reshape(rows, cols)
    np.testing.assert_array_equal(classes == 2, ground_truth.occupied)
    np.testing.assert_array_equal(classes == 1, ground_truth.free)
    np.testing.assert_allclose(
        recording.static_value(entity, "Transform3D:scale")[0], [0.1, 0.1, 1.0]
    )
    np.testing.assert_allclose(
        recording.static_value(entity, "Transform3D:translation")[0],
        [*ground_truth.origin, 0.0],
    )
    strips = recording.static_value("/world/walls", "LineStrips2D:strips")
    assert len(strips) == len(world.segments)
    np.testing.assert_allclose(np.array(strips).reshape(-1, 4), world.segments, atol=1e-5)


def test_grid_is_logged_with_its_transform_when_due(
    recording: Recording, ground_truth: GridMap
) -> None:
    assert recording.column("/robot_0/map", "step") == [0, 2, 4]  # map_every=2
    (translation,) = recording.at_step("/robot_0/map", "Transform3D:translation", 2)
    (rotation,) = recording.at_step("/robot_0/map", "Transform3D:rotation_axis_angle", 2)
    (scale,) = recording.at_step("/robot_0/map", "Transform3D:scale", 2)
    (fmt,) = recording.at_step("/robot_0/map", "SegmentationImage:format", 2)
    assert (fmt[0]["height"], fmt[0]["width"]) == ground_truth.shape
    np.testing.assert_allclose(scale[0], [0.1, 0.1, 1.0])
    corner = transform_points(MAP_FROM_WORLD, np.array([ground_truth.origin]))[0]
    np.testing.assert_allclose(translation[0], [*corner, 0.0], atol=1e-6)
    np.testing.assert_allclose(rotation[0]["axis"], [0.0, 0.0, 1.0])
    assert rotation[0]["angle"] == pytest.approx(MAP_FROM_WORLD[2])


def test_events_and_scalars(recording: Recording) -> None:
    texts = recording.column("/events", "TextLog:text")
    levels = recording.column("/events", "TextLog:level")
    # Each line starts with its step, in six columns (the viewer clips a step column).
    assert [t[0] for t in texts] == ["#0     recording started"] + [
        f"#{s:<5} step {s}" for s in range(N_STEPS)
    ]
    assert levels[5][0] == "WARN"  # "warning" normalised to Rerun's level name
    values = recording.column("/metrics/coverage", "Scalars:scalars")
    # A static style names the series after its path.
    assert recording.static_value("/metrics/coverage", "SeriesLines:names") == ["coverage"]
    np.testing.assert_allclose([v[0] for v in values], 0.1 * np.arange(N_STEPS))


def test_spatial_roots_are_turned_y_up(recording: Recording) -> None:
    for root in ("/world", "/robot_0", "/robot_1", "/merge", "/rendezvous", "/team"):
        (rotation,) = recording.static_value(root, "Transform3D:rotation_axis_angle")
        np.testing.assert_allclose(rotation["axis"], [1.0, 0.0, 0.0])
        assert rotation["angle"] == pytest.approx(np.pi)


def _blueprint_views(recording: Recording, store: Any) -> dict[str, str]:
    views: dict[str, str] = {}
    for chunk in recording.reader.stream(store=store):
        batch = chunk.to_record_batch()
        if "ViewBlueprint:display_name" in batch.schema.names:
            name = batch.column("ViewBlueprint:display_name").to_pylist()[-1][0]
            views[name] = batch.column("ViewBlueprint:space_origin").to_pylist()[-1][0]
    return views


def test_default_blueprints_are_in_the_file(recording: Recording) -> None:
    """The full layout (at save) and the one made for what was logged (on close): here
    no merge, no team, nothing in robot 1's frame. test_recording_views checks them."""
    blueprints = recording.reader.blueprints()
    assert [b.application_id for b in blueprints] == ["mrslam", "mrslam"]
    full, made = sorted((_blueprint_views(recording, b) for b in blueprints), key=len)[::-1]
    assert {"World", "Team", "Merge", "Robot 0", "Robot 1", "Events"} <= set(full)
    assert {"World", "Robot 0", "Fractions (0–1)", "Events"} == set(made)
    # 2-D views sit at the root so that the y-up root transforms apply.
    assert full["World"] == full["Robot 0"] == full["Merge"] == "/"


# -- maps and poses line up --------------------------------------------------------------


def _rotation(axis: Any, angle: float) -> np.ndarray:
    x, y, z = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    c, s, t = np.cos(angle), np.sin(angle), 1.0 - np.cos(angle)
    return np.array(
        [
            [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
            [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
            [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
        ]
    )


def _view_from_root(recording: Recording, root: str) -> np.ndarray:
    rotation = recording.static_value(root, "Transform3D:rotation_axis_angle")[0]
    return _rotation(rotation["axis"], rotation["angle"])


def test_pose_lands_on_its_grid_cell_in_the_2d_view(
    recording: Recording, ground_truth: GridMap
) -> None:
    """Emulate Rerun's placement (image + entity transform + root transform) for a pose.

    An image's pixel (column u, row v) covers ``[u, u+1] x [v, v+1]`` of its entity's space;
    the entity's ``Transform3D`` maps that to its parent as ``t + R (s * p)``, and the root's
    rotation into the 2-D view (y down).
    """
    view_from_world = _view_from_root(recording, "/world")
    entity = "/world/ground_truth"
    fmt = recording.static_value(entity, "SegmentationImage:format")[0]
    w, h = fmt["width"], fmt["height"]
    image = np.array(recording.static_value(entity, "SegmentationImage:buffer")[0])
    image = image.reshape(h, w)
    translation = np.array(recording.static_value(entity, "Transform3D:translation")[0])
    rotation = recording.static_value(entity, "Transform3D:rotation_axis_angle")[0]
    scale = np.array(recording.static_value(entity, "Transform3D:scale")[0])
    world_from_pixel = _rotation(rotation["axis"], rotation["angle"]) @ np.diag(scale)
    view_from_pixel = view_from_world @ world_from_pixel
    pixel_origin = view_from_world @ translation

    def texel(point_in_view: np.ndarray) -> tuple[float, float]:
        a = np.linalg.lstsq(view_from_pixel[:, :2], point_in_view - pixel_origin)[0]
        return a[1], a[0]  # continuous (image row, column)

    (origin,) = recording.at_step("/world/robot_0/true_pose", "Arrows2D:origins", 0)
    pose_in_view = view_from_world @ [*origin[0], 0.0]
    row, col = texel(pose_in_view)
    # (2, 2) is a cell corner: the texel coordinates map back to exactly (2, 2).
    cell = ground_truth.resolution
    np.testing.assert_allclose(
        [translation[0] + col * cell, translation[1] + row * cell], [2.0, 2.0], atol=1e-5
    )
    # Points inside cells land on those cells' pixels, free and occupied alike.
    for probe in ([2.05, 2.05], [5.05, 0.05], [9.95, 7.05], [3.05, 9.95]):
        row, col = (int(np.floor(v)) for v in texel(view_from_world @ [*probe, 0.0]))
        iy, ix = ground_truth.world_to_cell(probe)
        assert (row, col) == (iy, ix)
        assert image[row, col] == (2 if ground_truth.cells[iy, ix] == OCCUPIED else 1)
    # Not mirrored: higher world y is higher on screen (the 2-D view's y points down).
    assert (view_from_world @ [2.0, 8.0, 0.0])[1] < pose_in_view[1]
    assert (view_from_world @ [8.0, 2.0, 0.0])[0] > pose_in_view[0]


def test_scan_in_the_map_frame_uses_the_slam_pose(tmp_path: Path) -> None:
    """``robot_i/scan`` is logged only when the SLAM pose is known at that step."""
    path = tmp_path / "scan.rrd"
    slam = np.array([1.0, 2.0, 0.5])
    with Recorder(path, n_robots=1) as recorder:
        recorder.log_scan(0, true_pose(0, 0), scan_ranges(0), ANGLES, MAX_RANGE)
        recorder.set_time(1, DT)
        recorder.log_robot_pose(0, slam)
        recorder.log_scan(0, true_pose(0, 1), scan_ranges(1), ANGLES, MAX_RANGE)
        recorder.set_time(2, 2 * DT)
        recorder.log_scan(0, true_pose(0, 2), scan_ranges(2), ANGLES, MAX_RANGE)
    recording = Recording(path)
    assert recording.column("/robot_0/scan", "step") == [1]
    (points,) = recording.at_step("/robot_0/scan", "Points2D:positions", 1)
    expected = scan_hits_world(slam, scan_ranges(1), ANGLES, MAX_RANGE)
    np.testing.assert_allclose(points, expected, atol=1e-5)


# -- pure helpers and errors ---------------------------------------------------------------


def test_scan_hits_skip_misses_and_dropouts() -> None:
    ranges = np.array([1.0, 5.0, np.inf, np.nan, 2.0, 6.0])
    angles = np.array([0.0, 0.1, 0.2, 0.3, np.pi / 2, 0.5])
    hits = scan_hits_world([1.0, 1.0, np.pi / 2], ranges, angles, 5.0)
    np.testing.assert_allclose(hits, [[1.0, 2.0], [-1.0, 1.0]], atol=1e-12)
    assert scan_hits_world([0, 0, 0], np.full(4, 5.0), np.zeros(4), 5.0).shape == (0, 2)
    # Observations are float32: float32(12.7) < 12.7, yet it is a miss.
    misses = np.full(3, 12.7, dtype=np.float32)
    assert scan_hits_world([0, 0, 0], misses, np.zeros(3), 12.7).shape == (0, 2)
    with pytest.raises(ValueError, match="equal length"):
        scan_hits_world([0, 0, 0], np.ones(3), np.zeros(2), 5.0)


def test_occupancy_image_flips_rows_and_keeps_input() -> None:
    cells = np.array([[FREE, OCCUPIED], [UNKNOWN, FREE]], dtype=np.int8)
    grid = GridMap(cells=cells, resolution=0.5)
    image = occupancy_image(grid)
    np.testing.assert_array_equal(image, [[205, 254], [254, 0]])
    assert image.dtype == np.uint8
    np.testing.assert_array_equal(grid.cells, cells)


def test_occupancy_classes_keep_rows_and_styles() -> None:
    cells = np.array([[FREE, OCCUPIED], [UNKNOWN, FREE]], dtype=np.int8)
    grid = GridMap(cells=cells, resolution=0.5)
    np.testing.assert_array_equal(occupancy_classes(grid), [[1, 2], [0, 1]])
    np.testing.assert_array_equal(occupancy_classes(grid, "overlay"), [[7, 8], [6, 7]])
    assert occupancy_classes(grid).dtype == np.uint8
    np.testing.assert_array_equal(grid.cells, cells)
    with pytest.raises(KeyError):
        occupancy_classes(grid, "plain")  # type: ignore[arg-type]


def test_grid_corner_pose() -> None:
    grid = GridMap(cells=np.zeros((2, 2), np.int8), resolution=1.0, origin=(1.0, 2.0))
    np.testing.assert_allclose(grid_corner_pose(grid), [1.0, 2.0, 0.0])
    np.testing.assert_allclose(
        grid_corner_pose(grid, [0.0, 0.0, np.pi / 2]), [-2.0, 1.0, np.pi / 2]
    )


def test_recorder_refuses_bad_use(tmp_path: Path, ground_truth: GridMap) -> None:
    recorder = Recorder(tmp_path / "r.rrd", n_robots=1)
    with pytest.raises(ValueError, match="robot"):
        recorder.log_true_pose(1, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="below a root"):
        recorder.log_grid("world", ground_truth)
    with pytest.raises(ValueError, match="pose_xytheta"):
        recorder.log_scan(0, (0.0, 0.0), [1.0], [0.0], 5.0)
    recorder.close()
    recorder.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        recorder.log_event("too late")
    with pytest.raises(ValueError, match="map_every"):
        Recorder(tmp_path / "s.rrd", map_every=0)


# -- layering ------------------------------------------------------------------------------


def test_rerun_is_not_imported_by_pure_modules() -> None:
    code = (
        "import sys\n"
        "import mrslam_env, mrslam_env.gridmap, mrslam_env.geometry, mrslam_env.sim.world\n"
        "bad = [m for m in ('rerun', 'mrslam_env.recording') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
