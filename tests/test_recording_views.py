"""The default blueprint against the recording: every view draws what it selects.

A small synthetic run (the maze's ground truth, two robots' maps in their own frames,
poses, scans, paths, plans, a rendezvous, two live merge attempts of a traced
``merge_maps`` result, the merged map, metrics and events) is written through the
:class:`~mrslam_env.recording.Recorder` (an explicit ``RecordingStream``) to a temporary
``.rrd`` file and read back with Rerun's own reader (``rerun.chunk.RrdReader``). For each
view of each blueprint in the file, the entities its contents select are resolved with
Rerun's query rules, and each must be of an archetype that view type draws: images,
points, lines, arrows, ellipses (no ``GridMap``: the viewer draws it only in 3-D views)
in the 2-D views; scalars in the time series; text logs in the text views. Every map is
a class-id image of its grid's size, placed by a transform whose scale is the resolution,
so that poses land on its free cells. Then the default zoom and the merge attempts.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pytest
from merge_fixtures import map_pair, poses_near
from test_recording import Recording

from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap
from mrslam_env.merge.pipeline import MergeResult, merge_maps
from mrslam_env.recording import MAP_STYLES, Recorder, default_blueprint, grid_corner_pose
from mrslam_env.registry import build_world
from mrslam_env.sim.lidar import beam_angles, cast_scan
from mrslam_env.sim.world import WorldSpec, ground_truth_map

TRUTH = np.array([1.1, -0.4, -1.9])  # map1_from_map2 of the maze pair (test_recording_merge)
CENTRES = ((5.0, 5.0), (9.0, 7.0))
WORLD_FROM_MAP0 = np.array([5.0, 5.0, 0.3])  # merge_fixtures.map_pair's frame of map 1
N_STEPS = 6
N_BEAMS = 90
MAX_RANGE = 8.0
MERGE_STEP = 4

# What each view class draws (rerun 0.41 visualizers), and what it tolerates beside that.
DRAWN = {
    "2D": {
        "Points2D",
        "LineStrips2D",
        "Arrows2D",
        "Ellipses2D",
        "Boxes2D",
        "Image",
        "SegmentationImage",
        "DepthImage",
        "EncodedImage",
    },
    "TimeSeries": {"Scalars"},
    "TextLog": {"TextLog"},
}
TOLERATED = {
    "2D": {"Transform3D", "AnnotationContext", "Clear"},
    "TimeSeries": {"SeriesLines", "SeriesPoints", "Clear"},
    "TextLog": {"Clear"},
}
MAPS = (
    "/world/ground_truth",
    "/robot_0/map",
    "/robot_1/map",
    "/team/merged_map",
    "/merge/map1",
    "/merge/map2",
    "/merge/result",
)


@dataclass(frozen=True)
class Run:
    recording: Recording
    world: WorldSpec
    truth: GridMap
    maps: tuple[GridMap, GridMap]
    world_from_maps: tuple[np.ndarray, np.ndarray]
    true_poses: tuple[np.ndarray, np.ndarray]
    result: MergeResult


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    world = build_world("maze")
    truth = ground_truth_map(world, 0.05)
    m1, m2 = map_pair("maze", CENTRES[0], CENTRES[1], TRUTH)
    result = merge_maps(m1, m2, rng=0, trace=True)
    assert result.merged and result.trace is not None and result.fused is not None
    world_from_maps = (WORLD_FROM_MAP0, compose(WORLD_FROM_MAP0, TRUTH))
    rng = np.random.default_rng(1)
    true_poses = (
        poses_near(world, CENTRES[0], 2.0, N_STEPS, rng),
        poses_near(world, CENTRES[1], 2.0, N_STEPS, rng),
    )
    angles = beam_angles(N_BEAMS)
    path = tmp_path_factory.mktemp("views") / "views.rrd"
    with Recorder(path, recording_name="views", n_robots=2, map_every=2) as recorder:
        recorder.log_ground_truth(world, truth)
        recorder.log_text("team/state", "independent_exploration")
        slam_paths: list[list[np.ndarray]] = [[], []]
        for step in range(N_STEPS):
            recorder.set_time(step, 0.1 * step)
            # Three live attempts: merged, refused, merged (each replaces the previous).
            if step == MERGE_STEP - 2:
                recorder.log_merge_attempt(1, result, m1, m2, "maps exchanged")
            if step == MERGE_STEP - 1:
                recorder.log_merge_attempt(2, refused(result), m1, m2, "maps grew")
            if step == MERGE_STEP:
                recorder.log_merge_attempt(3, result, m1, m2, "maps grew again")
                recorder.set_team_transform(1, result.transform)
                recorder.log_grid("team/merged_map", result.fused)
                recorder.clear_rendezvous("hypothesis #0 accepted")
            for i, grid in enumerate((m1, m2)):
                true = true_poses[i][step]
                slam = compose(inverse(world_from_maps[i]), true)
                slam_paths[i].append(slam)
                recorder.log_true_pose(i, true)
                recorder.log_robot_pose(i, slam)
                ranges = cast_scan(
                    true[0], true[1], true[2], N_BEAMS, MAX_RANGE, world.segments, np.zeros((0, 3))
                )
                recorder.log_scan(i, true, ranges, angles, MAX_RANGE)
                recorder.log_robot_path(i, np.array(slam_paths[i]))
                if recorder.map_due:
                    recorder.log_grid(f"robot_{i}/map", grid)
                recorder.log_points(f"robot_{i}/frontiers", slam[None, :2] + 1.0, robot=i)
                recorder.log_line(f"robot_{i}/plan", [slam[:2], slam[:2] + 1.0], robot=i)
                recorder.log_scalar(f"ate/robot_{i}", 0.001 * step)
            if step == 2:
                plan_1 = transform_points(TRUTH, [[0.0, 0.0], [1.0, 1.0]])
                recorder.log_rendezvous(
                    [2.0, 1.0],
                    [[[0.0, 0.0], [2.0, 1.0]], plan_1],
                    poses=[np.zeros(3), TRUTH],
                    sightings=[[1.9, 1.1], [3.0, 3.0]],
                    sighting_matches=[True, False],
                    verdict="rendezvous for hypothesis #0",
                )
            recorder.log_scalar("coverage/team", 0.1 * step)
            recorder.log_scalar("count/hypotheses_tested", step // 2)
            recorder.log_event(f"step {step} done", level="WARNING" if step == 3 else "INFO")
    return Run(Recording(path), world, truth, (m1, m2), world_from_maps, true_poses, result)


def refused(result: MergeResult) -> MergeResult:
    """The same attempt, as if no hypothesis had been confident."""
    return replace(
        result,
        transform=None,
        chosen=None,
        fused=None,
        agreement=None,
        psi=float("nan"),
        reason="no confident merge: (test) no hypothesis passed",
    )


# -- reading the blueprint back -------------------------------------------------------------


@dataclass(frozen=True)
class View:
    kind: str  # ViewBlueprint:class_identifier: "2D", "TimeSeries", "TextLog", ...
    name: str
    origin: str
    queries: tuple[str, ...]
    properties: dict[str, Any]  # e.g. "VisualBounds2D:range" -> value


def blueprint_views(recording: Recording, which: str) -> dict[str, View]:
    """The views of the ``"initial"`` blueprint (sent at ``save``, no zoom) or the
    ``"final"`` one (sent on ``close``, zoomed to the maps), by display name. The reader
    lists the stores in no particular order."""
    stores = recording.reader.blueprints()
    assert len(stores) == 2, stores
    zoomed = [
        any("VisualBounds2D:range" in v.properties for v in _views(recording, s).values())
        for s in stores
    ]
    assert sorted(zoomed) == [False, True]
    return _views(recording, stores[zoomed.index(which == "final")])


def _views(recording: Recording, store: Any) -> dict[str, View]:
    latest: dict[str, dict[str, Any]] = {}
    for chunk in recording.reader.stream(store=store):
        batch = chunk.to_record_batch()
        values = latest.setdefault(chunk.entity_path, {})
        for name in batch.schema.names:
            if ":" in name:
                rows = [v for v in batch.column(name).to_pylist() if v is not None]
                if rows:
                    values[name] = rows[-1]
    views: dict[str, View] = {}
    for path, values in latest.items():
        if "ViewBlueprint:class_identifier" not in values:
            continue
        properties = {
            key: value
            for sub, components in latest.items()
            if sub.startswith(path + "/")
            for key, value in components.items()
        }
        name = values["ViewBlueprint:display_name"][0]
        views[name] = View(
            kind=values["ViewBlueprint:class_identifier"][0],
            name=name,
            origin=values["ViewBlueprint:space_origin"][0],
            queries=tuple(properties.get("ViewContents:query", [])),
            properties=properties,
        )
    return views


def selected(view: View, entities: set[str]) -> set[str]:
    """The entities a view's contents select, by Rerun's rules (ViewContents docstring):
    rules sorted by path, a subtree rule before the exact one, the last match wins."""
    rules = []
    for query in view.queries:
        query = query.strip().replace("$origin", view.origin.rstrip("/"))
        include = not query.startswith("-")
        path = query.lstrip("+-").strip()
        subtree = path.endswith("/**")
        path = path.removesuffix("/**") or "/"
        rules.append((path, not subtree, include, subtree))
    rules.sort(key=lambda rule: (rule[0], rule[1]))

    def matches(entity: str, path: str, subtree: bool) -> bool:
        if entity == path:
            return True
        return subtree and (path == "/" or entity.startswith(path + "/"))

    chosen = set()
    for entity in entities:
        verdict = False
        for path, _, include, subtree in rules:
            if matches(entity, path, subtree):
                verdict = include
        if verdict:
            chosen.add(entity)
    return chosen


def archetypes(recording: Recording, entity: str) -> set[str]:
    names: set[str] = set()
    for batch in recording.batches(entity):
        names.update(n.split(":")[0] for n in batch.schema.names if ":" in n)
    return names


# -- every view draws what it holds -----------------------------------------------------------


def test_file_holds_initial_and_zoomed_blueprints(run: Run) -> None:
    blueprints = run.recording.reader.blueprints()
    assert len(blueprints) == 2  # at save(), and again on close() with the default zoom
    assert all(b.application_id == "mrslam" for b in blueprints)
    for which in ("initial", "final"):
        views = blueprint_views(run.recording, which)
        assert {
            "World",
            "Team",
            "Merge",
            "Robot 0",
            "Robot 1",
            "Fractions (0–1)",
            "Errors (m)",
            "Counts",
            "Other metrics",
            "Events",
            "Team state",
        } == set(views)


@pytest.mark.parametrize("which", ["initial", "final"])
def test_every_view_selects_only_what_it_draws(run: Run, which: str) -> None:
    recording = run.recording
    entities = set(recording.chunks)
    for view in blueprint_views(recording, which).values():
        assert view.kind in DRAWN, f"{view.name}: unexpected view class {view.kind}"
        if view.kind == "2D":
            # The y-up root transforms apply below the origin only (module docstring).
            assert view.origin == "/", view.name
        chosen = selected(view, entities)
        drawn = [e for e in chosen if archetypes(recording, e) & DRAWN[view.kind]]
        assert drawn, f"view {view.name!r} would say 'No data available'"
        for entity in chosen:
            kinds = archetypes(recording, entity)
            extra = kinds - DRAWN[view.kind] - TOLERATED[view.kind]
            assert not extra, f"view {view.name!r} ({view.kind}) cannot draw {entity}: {extra}"
            assert "GridMap" not in kinds, f"{entity}: a 2-D view needs a pinhole for GridMap"


def test_views_show_the_entities_of_their_job(run: Run) -> None:
    entities = set(run.recording.chunks)
    views = blueprint_views(run.recording, "final")
    want = {
        "World": {"/world/ground_truth", "/world/walls", "/world/robot_1/true_pose"},
        "Team": {
            "/robot_0/map",  # robot 0's map frame is the team frame
            "/team/merged_map",
            "/team/robot_0/pose",
            "/team/robot_1/pose",
            "/team/robot_1/path",
            "/rendezvous/meeting_point",
            "/rendezvous/plan_1",
            "/rendezvous/sightings",
            "/rendezvous/robot_1",
        },
        "Merge": {
            "/merge/map1",
            "/merge/map2",
            "/merge/skeleton/map1",
            "/merge/virtual_robot/path",
            "/merge/virtual_robot/scan",
            "/merge/mcl/particles",
            "/merge/hypotheses",
            "/merge/refine/candidates",
            "/merge/refine/best",
            "/merge/result",
        },
        "Robot 1": {"/robot_1/map", "/robot_1/pose", "/robot_1/path", "/robot_1/scan"},
        "Fractions (0–1)": {"/metrics/coverage/team", "/metrics/merge/acceptance_index"},
        "Errors (m)": {"/metrics/ate/robot_0", "/metrics/ate/robot_1"},
        "Counts": {"/metrics/count/hypotheses_tested", "/metrics/merge/psi"},
        "Other metrics": {"/metrics/merge/seconds"},
        "Events": {"/events"},
        "Team state": {"/team/state", "/rendezvous/status"},
    }
    for name, expected in want.items():
        chosen = selected(views[name], entities)
        assert expected <= chosen, f"{name} misses {expected - chosen}"
    # Each metric is plotted exactly once, on the axis of its unit.
    metrics = {e for e in entities if e.startswith("/metrics/")}
    plotted = [e for v in views.values() if v.kind == "TimeSeries" for e in selected(v, metrics)]
    assert sorted(plotted) == sorted(metrics)
    assert views["Fractions (0–1)"].properties["ScalarAxis:range"][0] == pytest.approx([0.0, 1.02])


def test_legends_are_out_of_the_way_and_events_show_their_step(run: Run) -> None:
    views = blueprint_views(run.recording, "final")
    for view in views.values():
        if view.kind == "TimeSeries":
            assert view.properties["PlotLegend:corner"] == [1]  # LeftTop
    events = views["Events"].properties
    # Timeline columns hidden (the viewer clips them), the step starts each line instead.
    assert not any(c["visible"] for c in events["TextLogColumns:timeline_columns"])
    texts = [t[0] for t in run.recording.column("/events", "TextLog:text")]
    assert texts[-1] == f"#{N_STEPS - 1:<5} step {N_STEPS - 1} done"
    assert all(t.startswith("#") and t[1:6].strip().isdigit() for t in texts)


# -- maps: the right size, scaled by the resolution, under the poses ----------------------------


def image_and_transform(recording: Recording, entity: str) -> tuple[np.ndarray, dict[str, Any]]:
    """The last class-id image of a map entity and its transform."""

    def last(column: str) -> Any:
        rows = [r for r in recording.column(entity, column) if r is not None]
        assert rows, f"{entity} has no {column}"
        return rows[-1][0]

    fmt = last("SegmentationImage:format")
    buffer = np.array(last("SegmentationImage:buffer"), dtype=np.uint8)
    image = buffer.reshape(fmt["height"], fmt["width"])
    transform = {
        "translation": np.array(last("Transform3D:translation")),
        "axis_angle": last("Transform3D:rotation_axis_angle"),
        "scale": np.array(last("Transform3D:scale")),
    }
    return image, transform


def grid_of(run: Run, entity: str) -> tuple[GridMap, np.ndarray | None, str]:
    """The grid a map entity was logged from, where it was placed, and its style."""
    m1, m2 = run.maps
    result = run.result
    assert result.fused is not None
    return {
        "/world/ground_truth": (run.truth, None, "map"),
        "/robot_0/map": (m1, None, "map"),
        "/robot_1/map": (m2, None, "map"),
        "/team/merged_map": (result.fused, None, "map"),
        "/merge/map1": (m1, None, "see_through"),
        "/merge/map2": (m2, result.transform, "overlay"),
        "/merge/result": (result.fused, None, "map"),
    }[entity]


@pytest.mark.parametrize("entity", MAPS)
def test_every_map_is_an_image_scaled_by_its_resolution(run: Run, entity: str) -> None:
    image, transform = image_and_transform(run.recording, entity)
    grid, placement, style = grid_of(run, entity)
    assert image.shape == grid.shape
    np.testing.assert_allclose(transform["scale"], [grid.resolution, grid.resolution, 1.0])
    corner = np.array([*grid.origin])
    angle = 0.0
    if placement is not None:
        corner = transform_points(placement, corner[None, :])[0]
        angle = float(placement[2])
    np.testing.assert_allclose(transform["translation"], [*corner, 0.0], atol=1e-5)
    np.testing.assert_allclose(transform["axis_angle"]["axis"], [0.0, 0.0, 1.0])
    assert transform["axis_angle"]["angle"] == pytest.approx(angle, abs=1e-6)
    # Row 0 is the grid's row 0 (lowest y): the root's y-up turn puts it at the bottom.
    offset = MAP_STYLES[style]
    np.testing.assert_array_equal(image == offset + 1, grid.cells == FREE)
    np.testing.assert_array_equal(image == offset + 2, grid.cells == OCCUPIED)
    np.testing.assert_array_equal(image == offset, grid.cells == UNKNOWN)


def test_map_classes_are_annotated_on_every_root(run: Run) -> None:
    for root in ("/world", "/robot_0", "/robot_1", "/merge", "/rendezvous", "/team"):
        (context,) = run.recording.static_value(root, "AnnotationContext:context")
        labels = {c["class_id"]: c["class_description"]["info"]["label"] for c in context}
        for offset in MAP_STYLES.values():
            assert labels[offset].endswith("unknown"), root
            assert labels[offset + 1].endswith("free"), root
            assert labels[offset + 2].endswith("occupied"), root


def _pixel_of(transform: dict[str, Any], point: np.ndarray) -> tuple[int, int]:
    """Image (row, column) under a point of the root frame, by the entity's transform:
    root = translation + R_z(angle) (scale * pixel)."""
    angle = transform["axis_angle"]["angle"]
    c, s = np.cos(angle), np.sin(angle)
    local = np.array([[c, s], [-s, c]]) @ (point - transform["translation"][:2])
    u, v = local / transform["scale"][:2]
    return int(np.floor(v)), int(np.floor(u))


def test_poses_and_scans_land_on_their_maps(run: Run) -> None:
    recording = run.recording
    for entity, frame_of in (
        ("/world/ground_truth", lambda i: np.zeros(3)),
        ("/robot_0/map", lambda i: inverse(run.world_from_maps[0]) if i == 0 else None),
        ("/robot_1/map", lambda i: inverse(run.world_from_maps[1]) if i == 1 else None),
    ):
        image, transform = image_and_transform(recording, entity)
        for i in range(2):
            frame_from_world = frame_of(i)
            if frame_from_world is None:
                continue
            for step in range(N_STEPS):
                true = run.true_poses[i][step]
                row, col = _pixel_of(transform, compose(frame_from_world, true)[:2])
                if entity == "/world/ground_truth":
                    assert image[row, col] == 1, (entity, i, step)  # free
                elif image[row, col] != 0:  # a robot's partial map: free where known
                    assert image[row, col] == 1, (entity, i, step)
    # The last scan in robot 0's frame ends on walls of robot 0's map (cells or next to them).
    image, transform = image_and_transform(recording, "/robot_0/map")
    (scan,) = recording.at_step("/robot_0/scan", "Points2D:positions", N_STEPS - 1)
    on_wall = 0
    for point in np.asarray(scan, dtype=np.float64):
        row, col = _pixel_of(transform, point)
        window = image[max(row - 1, 0) : row + 2, max(col - 1, 0) : col + 2]
        on_wall += bool(np.any(window == 2))
    known = [p for p in np.asarray(scan) if image[_pixel_of(transform, p)] != 0]
    assert on_wall >= 0.9 * len(known) > 0


def test_default_zoom_covers_the_known_map(run: Run) -> None:
    views = blueprint_views(run.recording, "final")
    for name, grid, key in (
        ("World", run.truth, "world"),
        ("Robot 1", run.maps[1], "robot_1"),
    ):
        bounds = views[name].properties["VisualBounds2D:range"][0]
        known = np.argwhere(grid.cells != UNKNOWN)
        lo = np.array(grid.origin) + known.min(axis=0)[::-1] * grid.resolution
        hi = np.array(grid.origin) + (known.max(axis=0)[::-1] + 1) * grid.resolution
        x_range, y_range = np.array(bounds["x_range"]), np.array(bounds["y_range"])
        # The known cells, with a small margin; the view's y is the negated y-up range.
        margin = 0.05 * max(hi - lo) + 1e-6
        np.testing.assert_allclose(x_range, [lo[0], hi[0]], atol=margin, err_msg=key)
        np.testing.assert_allclose(-y_range[::-1], [lo[1], hi[1]], atol=margin, err_msg=key)
        assert x_range[0] < lo[0] and x_range[1] > hi[0] and y_range[0] < -hi[1], key
    # Only the initial blueprint has no zoom (nothing was known at save()).
    assert all(
        "VisualBounds2D:range" not in v.properties
        for v in blueprint_views(run.recording, "initial").values()
    )
    assert default_blueprint(3) is not None  # any number of robots


# -- the live merge ------------------------------------------------------------------------------


def test_merge_attempts_replace_each_other(run: Run) -> None:
    recording, result = run.recording, run.result
    assert result.trace is not None
    # The refusal clears what it does not draw: the fused map and the accepted transform.
    cleared = {
        entity
        for entity in recording.chunks
        if entity.startswith("/merge/")
        and any(v is not None for v in recording.column(entity, "Clear:is_recursive"))
    }
    assert cleared == {"/merge/result", "/merge/refine/best"}
    for entity in cleared:
        assert recording.at_step(entity, "Clear:is_recursive", MERGE_STEP - 1) == [[False]]
    # Entities drawn again are not cleared (the viewer would drop a map's new transform).
    assert not any(v is not None for v in recording.column("/merge/map1", "Clear:is_recursive"))
    # ... and the last attempt draws them again.
    assert recording.at_step("/merge/result", "SegmentationImage:format", MERGE_STEP)
    assert recording.at_step("/merge/refine/best", "Arrows2D:origins", MERGE_STEP)
    # Every attempt's stages, at its step; their iterations never overlap.
    iterations = recording.column("/merge/virtual_robot/scan", "merge_iteration")
    per_attempt = sum(len(r.poses_in_map1) for r in result.trace.hypotheses.runs)
    assert len(iterations) == 3 * per_attempt == len(set(iterations))
    steps = recording.column("/merge/virtual_robot/scan", "step")
    assert sorted(set(steps)) == [MERGE_STEP - 2, MERGE_STEP - 1, MERGE_STEP]
    # The walk's psi is on merge_iteration only: it would pile up at one step otherwise.
    for batch in recording.batches("/metrics/merge/refine_psi", static=False):
        assert "step" not in batch.schema.names
    # Hypotheses carry their scores, in words: where each came from and its agreement.
    labels = recording.column("/merge/hypotheses", "Arrows2D:labels")[-1]
    assert labels[0].startswith("#0 the virtual robot: agreement ") and "overlap" in labels[0]
    assert not any(" ai " in label or " psi " in label for label in labels)
    texts = [t[0] for t in recording.column("/events", "TextLog:text")]
    levels = [t[0] for t in recording.column("/events", "TextLog:level")]
    attempts = [(t, lv) for t, lv in zip(texts, levels, strict=True) if "merge attempt" in t]
    assert attempts == [
        (f"#{MERGE_STEP - 2:<5} merge attempt 1 (maps exchanged) merged: {result.reason}", "INFO"),
        (
            f"#{MERGE_STEP - 1:<5} merge attempt 2 (maps grew) refused: "
            "no confident merge: (test) no hypothesis passed",
            "WARN",
        ),
        (
            f"#{MERGE_STEP:<5} merge attempt 3 (maps grew again) merged: {result.reason}",
            "INFO",
        ),
    ]


def test_team_view_places_every_robot_in_robot_0_frame(run: Run) -> None:
    recording, result = run.recording, run.result
    assert result.transform is not None
    step = N_STEPS - 1
    for i in range(2):
        (team,) = recording.at_step(f"/team/robot_{i}/pose", "Points2D:positions", step)
        (own,) = recording.at_step(f"/robot_{i}/pose", "Points2D:positions", step)
        team_from_map = np.zeros(3) if i == 0 else result.transform
        expected = transform_points(team_from_map, np.asarray(own, dtype=np.float64))
        np.testing.assert_allclose(team, expected, atol=1e-5)
        # ... where the true pose says robot i is, seen from robot 0's frame (merge error).
        true_in_team = compose(inverse(run.world_from_maps[0]), run.true_poses[i][step])
        np.testing.assert_allclose(team[0], true_in_team[:2], atol=0.15)
    # Robot 1 joins the Team view at the merge, not before.
    assert min(recording.column("/team/robot_1/pose", "step")) == MERGE_STEP
    # The rendezvous entities are cleared when it ends.
    clears = recording.at_step("/rendezvous/meeting_point", "Clear:is_recursive", MERGE_STEP)
    assert clears == [[True]]
    colours = recording.at_step("/rendezvous/sightings", "Points2D:colors", 2)[0]
    assert len(colours) == 2 and colours[0] != colours[1]


def test_merge_view_follows_the_team_to_the_accepted_merge(run: Run, tmp_path: Any) -> None:
    """A refused attempt, its hypothesis under verification, then the acceptance: the
    Merge view shows each in turn, labelled in words, and the last one holds the accepted
    transform and the fused map (issue 39: it stayed on the refused attempt)."""
    result, (m1, m2) = run.result, run.maps
    assert result.transform is not None and result.fused is not None
    verified = result.transform + np.array([0.05, -0.03, 0.01])
    path = tmp_path / "story.rrd"
    with Recorder(path, n_robots=2) as recorder:
        recorder.set_time(2, 0.2)
        recorder.log_merge_attempt(
            4, refused(result), m1, m2, "maps at step 2", then="hypothesis #0 goes to verification"
        )
        recorder.set_time(3, 0.3)
        recorder.log_merge_verification(
            verified, m1, m2, "hypothesis #0 (1 of 1), from the virtual robot: verifying"
        )
        recorder.set_time(5, 0.5)
        recorder.log_merge_accepted(
            verified, result.transform, m1, m2, result.fused, "accepted at step 5, refined"
        )
    recording = Recording(path)

    def caption(step: int) -> str:
        (labels,) = recording.at_step("/merge/caption", "Points2D:labels", step)
        return " ".join(str(labels[0]).split())

    assert caption(2).startswith("merge attempt 4 refused: no confident merge")
    assert caption(3) == "hypothesis #0 (1 of 1), from the virtual robot: verifying"
    assert caption(5) == "accepted at step 5, refined"
    # Verification: map 2 placed by the hypothesis, its arrow there; the attempt's stages
    # cleared but its judged hypotheses kept.
    (origin,) = recording.at_step("/merge/verifying", "Arrows2D:origins", 3)
    np.testing.assert_allclose(origin[0], verified[:2], atol=1e-5)
    assert recording.at_step("/merge/skeleton/map1", "Clear:is_recursive", 3) == [[False]]
    assert not recording.at_step("/merge/hypotheses", "Clear:is_recursive", 3)
    (translations,) = recording.at_step("/merge/map2", "Transform3D:translation", 3)
    corner = grid_corner_pose(m2, verified)
    np.testing.assert_allclose(translations[0][:2], corner[:2], atol=1e-5)
    # Acceptance: the refined transform, the verified estimate, the fused map; the
    # hypothesis under verification cleared.
    (best,) = recording.at_step("/merge/refine/best", "Arrows2D:origins", 5)
    np.testing.assert_allclose(best[0], result.transform[:2], atol=1e-5)
    (before,) = recording.at_step("/merge/verified", "Arrows2D:origins", 5)
    np.testing.assert_allclose(before[0], verified[:2], atol=1e-5)
    (fused,) = recording.at_step("/merge/result", "SegmentationImage:format", 5)
    assert (fused[0]["height"], fused[0]["width"]) == result.fused.cells.shape
    assert recording.at_step("/merge/verifying", "Clear:is_recursive", 5) == [[False]]
    texts = [t[0] for t in recording.column("/events", "TextLog:text")]
    assert texts == [
        "#2     merge attempt 4 (maps at step 2) refused: no confident merge: (test) no "
        "hypothesis passed; hypothesis #0 goes to verification",
        "#3     hypothesis #0 (1 of 1), from the virtual robot: verifying",
        "#5     accepted at step 5, refined",
    ]
