"""The Rerun sink: one :class:`Recorder` writes one ``.rrd`` file (docs/design.md §7).

This is the only module of the project that imports :mod:`rerun`. It logs through an
explicit :class:`rerun.RecordingStream` (never the global one), saves straight to a file
(no viewer, no network) and attaches a default blueprint (:func:`default_blueprint`) to
the same file.

Entity paths
------------
All spatial data is in metres. Robots are numbered from 0 (``robot_0``, ``robot_1``...).

==================================  =====================================================
``world/ground_truth``              static ground-truth occupancy grid (a map, see below)
``world/walls``                     static wall outlines, ``LineStrips2D`` of the segments
``world/robot_i/true_pose``         ground-truth pose: disc, heading arrow, footprint
``world/robot_i/scan``              lidar hits in the world frame (``Points2D``)
``robot_i/map``                     robot i's own map, in its map frame
``robot_i/pose``                    its SLAM pose there (disc, arrow, footprint)
``robot_i/path``                    its SLAM trajectory there (``LineStrips2D``)
``robot_i/scan``                    the same scan placed at the SLAM pose (``Points2D``)
``robot_i/frontiers``, ``/plan``    its exploration targets and plan (:meth:`log_points`)
``merge/...``                       merge stages, in map 1's frame (:meth:`log_merge`,
                                    :meth:`log_merge_attempt`), then the hypothesis
                                    under verification (``merge/verifying``,
                                    :meth:`log_merge_verification`) and the accepted
                                    merge (``merge/verified``, ``merge/refine/best``,
                                    ``merge/result``, :meth:`log_merge_accepted`)
``merge/caption``                   the Merge view's state in words (a label)
``rendezvous/...``                  the rendezvous, in robot 0's map frame
                                    (:meth:`log_rendezvous`)
``team/merged_map``                 every robot's current map fused, in robot 0's map
                                    frame (logged whenever a map or transform changes)
``team/robot_i/{pose,path}``        the robots in that frame (:meth:`set_team_transform`)
``team/state``                      ``TextLog``: the team's state (:meth:`log_text`)
``rendezvous/status``               ``TextLog``: the rendezvous' verdicts
``metrics/<name>``                  ``Scalars`` (see :func:`default_blueprint` for units)
``events``                          ``TextLog`` of everything the team decides
==================================  =====================================================

Timelines: ``step`` (sequence) and ``sim_time`` (duration, seconds); the merge stages that
iterate are also on ``merge_iteration``. Wall-clock ``log_time`` is switched off so that a
recording depends only on the simulation. Every ``TextLog`` line starts with its step,
``"#312  ..."`` (:meth:`Recorder.log_event`): the viewer sizes a text log's timeline column
once and clips longer steps, so the default blueprint hides those columns.

The file holds two blueprints: the full layout, written when the file is opened, and the
one made for what was logged (views without content left out, 2-D views zoomed to their
maps), written by :meth:`Recorder.close` and made active.

Frames and the y axis
---------------------
Every spatial root (``world``, ``robot_i``, ``merge``, ``rendezvous``, ``team``) holds data
in its own right-handed, **y-up** frame, exactly as docs/design.md §2 defines it: points are
logged as they are, never negated. Rerun's 2-D view draws +y *down*, so each root carries
one static ``Transform3D``, a rotation of pi about the x axis, which turns (x right, y up,
z towards the viewer) into the 2-D view's (x right, y down, z into the screen). The
default blueprint's 2-D views therefore use ``origin="/"`` (the root transforms apply
below a view's origin, never at it) and select their entities with ``contents``.
``robot_0``, ``rendezvous``, ``team`` and (in a live run) ``merge`` share one frame, robot
0's map frame, so the Team view draws ``robot_0/map`` under ``team/merged_map``.

Maps
----
A map entity carries a ``SegmentationImage`` of class ids (:func:`occupancy_classes`) and
a ``Transform3D`` that places it: the image's pixel (column u, row v) covers
``[u, u+1] x [v, v+1]`` of the entity's own space, the transform scales that by
``resolution`` and moves it to the grid's lower-left corner (:func:`grid_corner_pose`).
Row 0 is the **lowest** y (no flip: the root's y-up turn shows it at the bottom), so
cell (iy, ix) covers ``[ox + ix*res, ox + (ix+1)*res] x [oy + iy*res, oy + (iy+1)*res]`` of
its root's frame, the frame poses and scans are logged in. Each root carries a static
``AnnotationContext`` (:func:`annotation_context`) that colours the classes as ROS
``map_server`` does: free 254, occupied 0, unknown 205 (grey levels); overlays use
transparent unknown cells. Images are 2-D content: the 2-D views draw them, unlike
``rr.GridMap`` which only a 3-D view draws.
"""

from __future__ import annotations

import errno
import math
import shutil
import textwrap
from collections.abc import Collection, Mapping, Sequence
from contextlib import suppress
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Final, Literal, Self

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import compose, transform_points, wrap_angle
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap

if TYPE_CHECKING:
    from mrslam_env.merge.pipeline import MergeResult
    from mrslam_env.sim.world import WorldSpec

__all__ = [
    "MAP_STYLES",
    "SPATIAL_ROOTS",
    "Bounds",
    "Recorder",
    "RecordingError",
    "annotation_context",
    "default_blueprint",
    "grid_corner_pose",
    "occupancy_classes",
    "occupancy_image",
    "robot_entity",
    "scan_hits_world",
    "source_words",
]

#: Root entities that hold y-up spatial data besides ``robot_i``.
SPATIAL_ROOTS: Final = ("world", "merge", "rendezvous", "team")

#: ``(xmin, ymin, xmax, ymax)`` in metres, in a root's y-up frame (as ``GridMap.extent``).
Bounds = tuple[float, float, float, float]

MapStyle = Literal["map", "see_through", "overlay"]
#: Class-id offset of each map style: classes ``offset + (0 unknown, 1 free, 2 occupied)``.
#: ``map`` is opaque, ``see_through`` has transparent unknown cells (a map drawn over another
#: one), ``overlay`` is tinted in robot 1's colour with transparent unknown cells and
#: translucent free space (map 2 placed on map 1 in the Merge view).
MAP_STYLES: Final[Mapping[str, int]] = {"map": 0, "see_through": 3, "overlay": 6}

# ROS map_server grey levels (docs/design.md §2), so a recorded map looks like the map file.
_GREY_FREE: Final = 254
_GREY_OCCUPIED: Final = 0
_GREY_UNKNOWN: Final = 205

# Higher is drawn on top: grids under walls under paths under scans under poses.
_DRAW_ORDER_GROUND_TRUTH: Final = -20.0
_DRAW_ORDER_GRID: Final = -10.0
_DRAW_ORDER_TEAM_GRID: Final = -5.0
_DRAW_ORDER_WALLS: Final = 10.0
_DRAW_ORDER_PATH: Final = 15.0
_DRAW_ORDER_SCAN: Final = 20.0
_DRAW_ORDER_POSE: Final = 30.0

# Marker sizes, metres: a robot is drawn at its footprint radius (the callers' ``radius``).
_SCAN_RADIUS: Final = 0.04
_PATH_RADIUS: Final = 0.03
_PLAN_RADIUS: Final = 0.04
_ARROW_RADIUS: Final = 0.04
_OUTLINE_RADIUS: Final = 0.015

_ROBOT_COLOURS: Final = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (23, 190, 207),
)
_OUTLINE: Final = (20, 20, 20)
_MERGE_GREEN: Final = (0, 170, 0)
_CAPTION_WIDTH: Final = 64
"""Characters a line of the Merge view's caption (a half-width view of the default
blueprint at 1600 px shows about 70)."""
_MERGE_RED: Final = (200, 0, 0)

_LEVELS: Final = {"WARNING": "WARN", "FATAL": "CRITICAL"}
_TIMELINES: Final = ("step", "sim_time", "merge_iteration")

_RENDEZVOUS_PARTS: Final = ("meeting_point", "sightings")

# Metric path prefixes per time-series view (see default_blueprint).
_FRACTION_METRICS: Final = ("coverage", "fraction", "merge/acceptance_index")
_ERROR_METRICS: Final = ("ate", "error_m")
_COUNT_METRICS: Final = ("count", "merge/psi", "merge/refine_psi")


def robot_entity(robot: int) -> str:
    """Entity-path name of robot ``robot`` (numbered from 0): ``"robot_0"``..."""
    return f"robot_{robot}"


def robot_colour(robot: int) -> tuple[int, int, int]:
    """A fixed RGB colour per robot, shared by all its entities."""
    return _ROBOT_COLOURS[robot % len(_ROBOT_COLOURS)]


_SOURCE_WORDS: Final = {
    "virtual robot": "the virtual robot",
    "correlation": "the wall correlation",
    "hough": "the Hough spectra",
    "symmetry": "the symmetry check",
    "twin": "the 180° twin",
    "neighbour": "a neighbour of the best",
    "sighting": "sightings",
}


def source_words(proposed_by: str) -> str:
    """Where a hypothesis came from, in words: ``"virtual robot"`` -> ``"the virtual
    robot"``, ``"hough"`` -> ``"the Hough spectra"``, ``"sighting"`` -> ``"sightings"``..."""
    return _SOURCE_WORDS.get(proposed_by, proposed_by)


def occupancy_classes(grid: GridMap, style: MapStyle = "map") -> NDArray[np.uint8]:
    """Class-id image (rows, cols) uint8 of a grid, row 0 = **lowest** y (the grid's row 0).

    Unknown ``offset + 0``, free ``offset + 1``, occupied ``offset + 2`` with ``offset =
    MAP_STYLES[style]``; :func:`annotation_context` names and colours them. The input is not
    modified.
    """
    offset = MAP_STYLES[style]
    cells = grid.cells
    classes = np.full(cells.shape, offset, dtype=np.uint8)
    classes[cells == FREE] = offset + 1
    classes[cells == OCCUPIED] = offset + 2
    return np.ascontiguousarray(classes)


def annotation_context() -> rr.AnnotationContext:
    """Labels and colours (RGBA) of the map classes of :func:`occupancy_classes`."""
    grey = {
        "unknown": (_GREY_UNKNOWN,) * 3,
        "free": (_GREY_FREE,) * 3,
        "occupied": (_GREY_OCCUPIED,) * 3,
    }
    tint = robot_colour(1)
    light = tuple(int(255 - 0.35 * (255 - c)) for c in tint)
    classes: list[tuple[int, str, tuple[int, int, int, int]]] = [
        (0, "unknown", (*grey["unknown"], 255)),
        (1, "free", (*grey["free"], 255)),
        (2, "occupied", (*grey["occupied"], 255)),
        (3, "unknown", (0, 0, 0, 0)),
        (4, "free", (*grey["free"], 255)),
        (5, "occupied", (*grey["occupied"], 255)),
        (6, "map 2: unknown", (0, 0, 0, 0)),
        (7, "map 2: free", (light[0], light[1], light[2], 90)),
        (8, "map 2: occupied", (*tint, 255)),
    ]
    return rr.AnnotationContext(classes)


def occupancy_image(grid: GridMap) -> NDArray[np.uint8]:
    """Grey image (rows, cols) uint8 of a grid, row 0 = **top** (highest y).

    Free 254, occupied 0, unknown 205, as ROS ``map_server`` images (e.g. for figures; the
    recorder itself logs :func:`occupancy_classes`). The input is not modified.
    """
    cells = grid.cells
    grey = np.full(cells.shape, _GREY_UNKNOWN, dtype=np.uint8)
    grey[cells == FREE] = _GREY_FREE
    grey[cells == OCCUPIED] = _GREY_OCCUPIED
    grey[cells == UNKNOWN] = _GREY_UNKNOWN
    return np.ascontiguousarray(grey[::-1])


def grid_corner_pose(
    grid: GridMap, parent_from_grid: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Pose ``(x, y, theta)`` of the outer lower-left corner of cell [0, 0].

    Parameters
    ----------
    grid : GridMap
    parent_from_grid : array_like, shape (3,), optional
        The SE(2) transform mapping the grid's own frame (the one
        ``grid.origin`` is given in) into the frame of the entity it is drawn under.
        ``None`` is the identity.

    Returns
    -------
    ndarray, shape (3,), float64
        Corner position (m) and the grid's x-axis direction (rad) in the entity's frame.
    """
    origin = np.asarray(grid.origin, dtype=np.float64)
    if parent_from_grid is None:
        return np.array([origin[0], origin[1], 0.0])
    transform = _as_pose(parent_from_grid, "parent_from_grid")
    corner = transform_points(transform, origin[None, :])[0]
    return np.array([corner[0], corner[1], float(transform[2])])


def scan_hits_world(
    pose_xytheta: ArrayLike, ranges: ArrayLike, angles: ArrayLike, max_range: float
) -> NDArray[np.float64]:
    """World coordinates (K, 2) of the lidar returns that hit something.

    Parameters
    ----------
    pose_xytheta : array_like, shape (3,)
        Sensor pose in the world frame (m, m, rad).
    ranges : array_like, shape (N,)
        Measured ranges (m).
    angles : array_like, shape (N,)
        Beam angles relative to the sensor heading (rad).
    max_range : float
        Returns at or beyond this range (m), and non-finite ones, are misses and dropped.

    Returns
    -------
    ndarray, shape (K, 2), float64
        K <= N hit points, in beam order.
    """
    pose = _as_pose(pose_xytheta, "pose_xytheta")
    measured = np.asarray(ranges)
    r = measured.astype(np.float64)
    a = np.asarray(angles, dtype=np.float64)
    if r.ndim != 1 or a.shape != r.shape:
        raise ValueError(
            f"ranges and angles must be 1-D of equal length, got {r.shape} and {a.shape}"
        )
    if not (max_range > 0 and math.isfinite(max_range)):
        raise ValueError(f"max_range must be a finite number > 0 m, got {max_range}")
    # Compare in the ranges' own precision: a float32 scan stores max_range rounded, and
    # float32(12.7) < 12.7 would otherwise turn every miss into a hit.
    limit = measured.dtype.type(max_range) if measured.dtype.kind == "f" else max_range
    hit = np.isfinite(r) & (r >= 0.0) & (measured < limit)
    bearing = pose[2] + a[hit]
    return np.stack(
        [pose[0] + r[hit] * np.cos(bearing), pose[1] + r[hit] * np.sin(bearing)], axis=-1
    )


# -- the blueprint -----------------------------------------------------------------------


def _visual_bounds(bounds: Bounds | None) -> rrb.VisualBounds2D | None:
    """The 2-D view's visible range for y-up ``bounds`` (the view's y is the negated y)."""
    if bounds is None:
        return None
    xmin, ymin, xmax, ymax = bounds
    margin = 0.03 * max(xmax - xmin, ymax - ymin, 1.0)
    return rrb.VisualBounds2D(
        x_range=[xmin - margin, xmax + margin], y_range=[-ymax - margin, -ymin + margin]
    )


def _metric_queries(prefixes: Sequence[str]) -> list[str]:
    return [q for p in prefixes for q in (f"+ /metrics/{p}", f"+ /metrics/{p}/**")]


def _metric_unit(name: str) -> str:
    """Which time-series view plots ``metrics/<name>``: by path prefix."""
    for unit, prefixes in (
        ("fractions", _FRACTION_METRICS),
        ("errors", _ERROR_METRICS),
        ("counts", _COUNT_METRICS),
    ):
        if any(name == p or name.startswith(p + "/") for p in prefixes):
            return unit
    return "other"


def default_blueprint(
    n_robots: int,
    bounds: Mapping[str, Bounds] | None = None,
    *,
    logged: Collection[str] | None = None,
) -> rrb.Blueprint:
    """The default viewer layout (docs/design.md §7).

    2-D views, all with ``origin="/"`` so that the y-up root transforms apply (module
    docstring), each selecting its entities with ``contents``:

    * **World**: ``world/**`` (ground truth, walls, true poses, scans; world frame);
    * **Team**: ``robot_0/map`` under ``team/**`` and ``rendezvous/**`` (the merged map,
      the robots placed there, the rendezvous; robot 0's map frame);
    * **Merge**: ``merge/**`` (the latest merge attempt's stages; map 1's frame);
    * **Robot i**: ``robot_i/**`` (map, SLAM pose, path, scan, frontiers, plan; robot i's
      map frame).

    Time series, by unit (by metric path prefix, see :meth:`Recorder.log_scalar`), with
    the legend in the top-left corner, where the curves start low: **Fractions (0–1)**
    (``coverage/``, ``fraction/``, ``merge/acceptance_index``; y axis 0..1), and as tabs
    **Errors (m)** (``ate/``, ``error_m/``), **Counts** (``count/``, ``merge/psi``,
    ``merge/refine_psi``; psi is in cells) and **Other metrics** (the rest).

    Text logs, as tabs: **Events** (``events``) and **Team state** (``team/state``,
    ``rendezvous/status``), their timeline columns hidden (the viewer sizes them once and
    clips longer steps): each line starts with its step (:meth:`Recorder.log_event`).

    Layout: World, Team, Merge in the top row; the Robot views and the metrics in the
    middle row; the text logs across the bottom. The time panel is collapsed to its
    time bar, on the ``step`` timeline.

    Parameters
    ----------
    n_robots : int
        One Robot view each.
    bounds : mapping, optional
        Default zoom per 2-D view, ``(xmin, ymin, xmax, ymax)`` in metres in the view's
        y-up frame, keyed ``"world"``, ``"team"``, ``"merge"``, ``"robot_i"``. A view
        without bounds fits its content.
    logged : collection of str, optional
        The entity paths logged (without the leading ``/``). When given, views that would
        select none of them are left out (e.g. only Merge, metrics and events for a
        recording of one offline merge); a root entity alone does not count.
    """
    if not (isinstance(n_robots, int) and n_robots >= 1):
        raise ValueError(f"n_robots must be an integer >= 1, got {n_robots!r}")
    bounds = dict(bounds or {})
    paths = None if logged is None else {e.strip("/") for e in logged}

    def has(*prefixes: str) -> bool:
        return paths is None or any(e.startswith(p + "/") for e in paths for p in prefixes)

    def has_metrics(unit: str) -> bool:
        # merge/refine_psi alone is no reason for a view: it is on merge_iteration only.
        return paths is None or any(
            _metric_unit(e.removeprefix("metrics/")) == unit
            for e in paths
            if e.startswith("metrics/") and e != "metrics/merge/refine_psi"
        )

    def has_entity(*entities: str) -> bool:
        return paths is None or any(e in paths for e in entities)

    def spatial(name: str, key: str, contents: list[str]) -> rrb.Spatial2DView:
        return rrb.Spatial2DView(
            origin="/",
            contents=contents,
            name=name,
            visual_bounds=_visual_bounds(bounds.get(key)),
        )

    top = []
    if has("world"):
        top.append(spatial("World", "world", ["+ /world/**"]))
    if has("team", "rendezvous"):
        top.append(
            spatial(
                "Team",
                "team",
                [
                    f"+ /{robot_entity(0)}/map",
                    "+ /team/**",
                    "- /team/state",
                    "+ /rendezvous/**",
                    "- /rendezvous/status",
                ],
            )
        )
    if has("merge"):
        top.append(spatial("Merge", "merge", ["+ /merge/**"]))
    robots = [
        spatial(f"Robot {i}", robot_entity(i), [f"+ /{robot_entity(i)}/**"])
        for i in range(n_robots)
        if has(robot_entity(i))
    ]

    legend = rrb.PlotLegend(corner=rrb.Corner2D.LeftTop)
    metric_views = []
    for unit, name, prefixes, axis in (
        ("fractions", "Fractions (0–1)", _FRACTION_METRICS, rrb.ScalarAxis(range=(0.0, 1.02))),
        ("errors", "Errors (m)", _ERROR_METRICS, None),
        ("counts", "Counts", _COUNT_METRICS, None),
    ):
        if has_metrics(unit):
            metric_views.append(
                rrb.TimeSeriesView(
                    origin="/metrics",
                    contents=_metric_queries(prefixes),
                    name=name,
                    axis_y=axis,
                    plot_legend=legend,
                )
            )
    if has_metrics("other"):
        known = (*_FRACTION_METRICS, *_ERROR_METRICS, *_COUNT_METRICS)
        metric_views.append(
            rrb.TimeSeriesView(
                origin="/metrics",
                contents=[
                    "+ /metrics/**",
                    *(q.replace("+", "-", 1) for q in _metric_queries(known)),
                ],
                name="Other metrics",
                plot_legend=legend,
            )
        )

    hidden_timelines = [rrb.encodings.TimelineColumn(t, visible=False) for t in _TIMELINES]
    texts = []
    if has_entity("events"):
        texts.append(
            rrb.TextLogView(
                origin="/events",
                contents=["+ /events"],
                name="Events",
                columns=rrb.TextLogColumns(
                    timeline_columns=hidden_timelines, text_log_columns=["loglevel", "body"]
                ),
                format_options=rrb.TextLogFormat(monospace_body=True),
            )
        )
    if has_entity("team/state", "rendezvous/status"):
        texts.append(
            rrb.TextLogView(
                origin="/",
                contents=["+ /team/state", "+ /rendezvous/status"],
                name="Team state",
                columns=rrb.TextLogColumns(
                    timeline_columns=hidden_timelines, text_log_columns=["entitypath", "body"]
                ),
                format_options=rrb.TextLogFormat(monospace_body=True),
            )
        )

    metrics: rrb.Container | rrb.View | None = None
    if len(metric_views) == 1:
        metrics = metric_views[0]
    elif len(metric_views) == 2:
        metrics = rrb.Vertical(*metric_views)
    elif metric_views:
        metrics = rrb.Vertical(metric_views[0], rrb.Tabs(*metric_views[1:]))
    rows: list[rrb.Container] = []
    shares: list[float] = []
    if robots:
        if top:
            rows.append(rrb.Horizontal(*top))
            shares.append(3)
        rows.append(rrb.Horizontal(*robots, *([metrics] if metrics is not None else [])))
        shares.append(3)
    elif top or metrics is not None:
        # No robots (e.g. one offline merge): the metrics beside the top views.
        views = [*top, *([metrics] if metrics is not None else [])]
        rows.append(
            rrb.Horizontal(*views, column_shares=[2] * len(top) + [1] * (len(views) - len(top)))
        )
        shares.append(3)
    if texts:
        rows.append(rrb.Tabs(*texts) if len(texts) > 1 else rrb.Horizontal(*texts))
        shares.append(2 if len(rows) > 2 else 1)
    return rrb.Blueprint(
        rrb.Vertical(*rows, row_shares=shares),
        rrb.TimePanel(timeline="step", state="collapsed"),
        collapse_panels=True,
    )


# -- the recorder ------------------------------------------------------------------------


class RecordingError(OSError):
    """A recording could not be written (:meth:`Recorder.close`); ``errno`` is ``ENOSPC``
    when the disk is full."""

    @classmethod
    def of(cls, path: Path, error: BaseException) -> RecordingError:
        """The error of writing ``path`` that failed with ``error`` (rerun's, which names
        no cause when its file-writer thread stopped: a folder with under 1 MiB free is
        taken as full)."""
        text = " ".join(str(error).split()) or type(error).__name__
        full = "os error 28" in text or "No space left" in text
        if not full:
            with suppress(OSError):
                full = shutil.disk_usage(Path(path).parent).free < 1 << 20
        cause = "no space left on device" if full else text
        made = cls(f"cannot write recording {path}: {cause}")  # str(): the message alone
        made.errno = errno.ENOSPC if full else None
        return made


class Recorder:
    """Writes one ``.rrd`` file through an explicit :class:`rerun.RecordingStream`.

    No viewer, no network: the file carries the recording and its default blueprint, the
    full layout at the start and, on :meth:`close`, the layout made for what was logged
    (``default_blueprint(n_robots, bounds, logged)``: e.g. only the Merge view, metrics
    and events for ``mrslam merge --rrd``), which the viewer shows. Use as a context
    manager, or call :meth:`close`. Everything logged before the first :meth:`set_time`
    lands at step 0, sim_time 0.

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file to write (its directory must exist; an existing file is replaced).
    application_id : str
        Rerun application id; the viewer groups recordings and blueprints by it.
    recording_name : str, optional
        Name shown in the viewer.
    n_robots : int
        Number of robots: one view and one y-up root entity ``robot_i`` per robot.
    map_every : int
        Log robot maps every ``map_every`` steps; see :attr:`map_due`.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        application_id: str = "mrslam",
        recording_name: str | None = None,
        n_robots: int = 2,
        map_every: int = 10,
    ) -> None:
        if not (isinstance(n_robots, int) and n_robots >= 1):
            raise ValueError(f"n_robots must be an integer >= 1, got {n_robots!r}")
        if not (isinstance(map_every, int) and map_every >= 1):
            raise ValueError(f"map_every must be an integer >= 1, got {map_every!r}")
        self.path = Path(path)
        self.n_robots = n_robots
        self.map_every = map_every
        self._step = 0
        self._sim_time = 0.0
        self._closed = False
        self._y_up_roots: set[str] = set()
        self._styled_metrics: set[str] = set()
        self._logged: set[str] = set()
        self._collect: set[str] | None = None
        self._merge_entities: set[str] = set()
        self._bounds: dict[str, Bounds] = {}
        self._slam_poses: dict[int, tuple[int, NDArray[np.float64]]] = {}
        self._team_from_map: dict[int, NDArray[np.float64]] = {0: np.zeros(3)}
        self._merge_iteration = 0
        self._stream = rr.RecordingStream(application_id)
        self._stream.set_log_time_enabled(False)
        self._stream.save(self.path, default_blueprint=default_blueprint(n_robots))
        if recording_name is not None:
            self._stream.send_recording_name(recording_name)
        for root in (*SPATIAL_ROOTS, *(robot_entity(i) for i in range(n_robots))):
            self._declare_y_up(root)
        self.set_time(0, 0.0)

    # -- time ----------------------------------------------------------------------------

    def set_time(self, step: int, sim_time: float) -> None:
        """Set the time of what follows: timelines ``step`` and ``sim_time`` (s)."""
        self._check_open()
        if step < 0:
            raise ValueError(f"step must be >= 0, got {step}")
        if not math.isfinite(sim_time):
            raise ValueError(f"sim_time must be finite, got {sim_time}")
        self._step = int(step)
        self._sim_time = float(sim_time)
        self._stream.set_time("step", sequence=self._step)
        self._stream.set_time("sim_time", duration=float(sim_time))

    @property
    def step(self) -> int:
        """The current ``step`` (last :meth:`set_time`)."""
        return self._step

    @property
    def map_due(self) -> bool:
        """Whether maps should be logged at the current step (every ``map_every`` steps).

        Grids are large; callers throttle :meth:`log_grid` with it. :meth:`log_grid` itself
        always logs.
        """
        return self._step % self.map_every == 0

    @property
    def bounds(self) -> dict[str, Bounds]:
        """Extent ``(xmin, ymin, xmax, ymax)`` of the maps logged so far per 2-D view
        (``"world"``, ``"team"``, ``"merge"``, ``"robot_i"``), the default zoom that
        :meth:`close` writes into the blueprint."""
        return dict(self._bounds)

    # -- the world -----------------------------------------------------------------------

    def log_ground_truth(self, world: WorldSpec, grid: GridMap) -> None:
        """Log the static ground truth: ``world/ground_truth`` (map) and ``world/walls``."""
        self._check_open()
        self._log_grid(
            "world/ground_truth", grid, None, _DRAW_ORDER_GROUND_TRUTH, static=True, opacity=1.0
        )
        # One two-point strip per lidar segment (x0, y0, x1, y1).
        strips = list(np.asarray(world.segments, dtype=np.float64).reshape(-1, 2, 2))
        self._log(
            "world/walls",
            rr.LineStrips2D(
                strips,
                radii=0.02,
                colors=(60, 60, 60),
                draw_order=_DRAW_ORDER_WALLS,
            ),
            static=True,
        )

    def log_true_pose(self, robot: int, pose_xytheta: ArrayLike, radius: float = 0.2) -> None:
        """Log ``world/robot_i/true_pose``: a disc of the footprint, its outline and a
        heading arrow twice as long.

        ``pose_xytheta`` is the ground-truth pose (m, m, rad); ``radius`` the footprint (m).
        """
        self._check_open()
        self._check_robot(robot)
        self._log_pose(f"world/{robot_entity(robot)}/true_pose", robot, pose_xytheta, radius)

    def log_robot_pose(self, robot: int, pose_in_map: ArrayLike, radius: float = 0.2) -> None:
        """Log ``robot_i/pose``: the robot's SLAM pose in its own map frame, drawn over
        ``robot_i/map`` as :meth:`log_true_pose` draws the true one.

        Also ``team/robot_i/pose`` when the robot's map is placed in the team frame
        (:meth:`set_team_transform`), and remembered for :meth:`log_scan` at this step.
        """
        self._check_open()
        self._check_robot(robot)
        pose = _as_pose(pose_in_map, "pose_in_map")
        self._slam_poses[robot] = (self._step, pose)
        self._log_pose(f"{robot_entity(robot)}/pose", robot, pose, radius)
        team_from_map = self._team_from_map.get(robot)
        if team_from_map is not None:
            self._log_pose(
                f"team/{robot_entity(robot)}/pose", robot, compose(team_from_map, pose), radius
            )

    def log_robot_path(self, robot: int, poses_in_map: ArrayLike) -> None:
        """Log ``robot_i/path``: the robot's trajectory (T, 3) or (T, 2) in its map frame
        (and ``team/robot_i/path`` when placed in the team frame)."""
        self._check_open()
        self._check_robot(robot)
        path = np.asarray(poses_in_map, dtype=np.float64)
        if path.ndim != 2 or path.shape[1] not in (2, 3) or not np.all(np.isfinite(path)):
            raise ValueError(f"poses_in_map must be finite, shape (T, 2|3), got {path.shape}")
        self._log_path(f"{robot_entity(robot)}/path", robot, path[:, :2])
        team_from_map = self._team_from_map.get(robot)
        if team_from_map is not None:
            self._log_path(
                f"team/{robot_entity(robot)}/path",
                robot,
                transform_points(team_from_map, path[:, :2]),
            )

    def set_team_transform(self, robot: int, team_from_map: ArrayLike | None) -> None:
        """Place robot ``robot``'s map frame in the team frame (robot 0's map frame).

        From now on :meth:`log_robot_pose` and :meth:`log_robot_path` also log
        ``team/robot_i/{pose,path}``, so the Team view shows every robot on the merged map.
        Robot 0 is placed by the identity from the start; call this with the verified
        ``map0_from_map1`` (``team.transform``) for robot 1 once the merge is verified, and
        with ``None`` to take a robot out of the Team view (its entities are cleared).
        """
        self._check_open()
        self._check_robot(robot)
        if team_from_map is None:
            self._team_from_map.pop(robot, None)
            self._log(f"team/{robot_entity(robot)}", rr.Clear(recursive=True))
            return
        self._team_from_map[robot] = _as_pose(team_from_map, "team_from_map")

    def log_scan(
        self,
        robot: int,
        pose_xytheta: ArrayLike,
        ranges: ArrayLike,
        angles: ArrayLike,
        max_range: float,
    ) -> None:
        """Log ``world/robot_i/scan``: the hits of one scan in the world frame.

        See :func:`scan_hits_world`; returns at ``max_range`` or beyond are not drawn. When
        :meth:`log_robot_pose` logged the robot's SLAM pose at this step, the same scan is
        also logged at that pose as ``robot_i/scan`` (in the robot's map frame, where it
        lies on the walls of ``robot_i/map`` as far as SLAM is right).
        """
        self._check_open()
        self._check_robot(robot)
        placements = [(f"world/{robot_entity(robot)}/scan", pose_xytheta)]
        slam = self._slam_poses.get(robot)
        if slam is not None and slam[0] == self._step:  # also at the SLAM pose, in its map
            placements.append((f"{robot_entity(robot)}/scan", slam[1]))
        for entity, pose in placements:
            self._log(
                entity,
                rr.Points2D(
                    scan_hits_world(pose, ranges, angles, max_range),
                    radii=_SCAN_RADIUS,
                    colors=robot_colour(robot),
                    draw_order=_DRAW_ORDER_SCAN,
                ),
            )

    # -- events and metrics --------------------------------------------------------------

    def log_event(self, text: str, level: str = "INFO") -> None:
        """Append to the ``events`` text log: ``"#<step> <text>"``, the step left-aligned
        in five columns (``"#312   rendezvous for ..."``), since the viewer clips a step
        column.

        ``level`` is one of Rerun's ``CRITICAL, ERROR, WARN, INFO, DEBUG, TRACE``
        (case-insensitive; ``WARNING`` means ``WARN``).
        """
        self._check_open()
        self._log("events", rr.TextLog(self._stamp(text), level=_level(level)))

    def log_scalar(self, path: str, value: float) -> None:
        """Log one value of the time series ``metrics/<path>`` (e.g. ``"coverage/robot_0"``).

        The default blueprint plots metrics by unit, by path prefix: ``coverage/``,
        ``fraction/`` and ``merge/acceptance_index`` (0..1), ``ate/`` and ``error_m/``
        (metres), ``count/``, ``merge/psi`` and ``merge/refine_psi`` (counts, cells); any
        other path is plotted under "Other metrics". A path naming a robot (``robot_i``)
        is drawn in that robot's colour.
        """
        self._check_open()
        name = path.strip("/")
        if not name:
            raise ValueError("log_scalar needs a non-empty metric path")
        entity = f"metrics/{name}"
        self._style_metric(entity)
        self._log(entity, rr.Scalars(float(value)))

    # -- grids ---------------------------------------------------------------------------

    def log_grid(
        self,
        entity: str,
        grid: GridMap,
        parent_from_grid: ArrayLike | None = None,
        *,
        static: bool = False,
        draw_order: float | None = None,
        opacity: float | None = None,
        style: MapStyle = "map",
    ) -> None:
        """Log a grid anywhere, e.g. ``robot_0/map``, ``merge/result``, ``team/merged_map``.

        The entity gets a ``SegmentationImage`` of :func:`occupancy_classes` and a
        ``Transform3D`` (translation: the grid's lower-left corner, rotation about z,
        scale: the resolution) that places it in its root's frame (module docstring).

        Parameters
        ----------
        entity : str
            Entity path below a root (``"robot_0/map"``; a bare root is refused because it
            carries the y-up transform). The grid is drawn in its root's frame.
        grid : GridMap
        parent_from_grid : array_like, shape (3,), optional
            The SE(2) transform ``(x, y, theta)`` mapping the grid's own
            frame (where ``grid.origin`` is given) into the entity's root frame, e.g.
            ``map1_from_map2`` to draw map 2 under ``team/...``. It is folded into the
            entity's ``Transform3D``.
        static : bool
            Log as static (timeless) data.
        draw_order : float, optional
            Layering among overlapping 2-D content; higher is drawn on top. Default: -5 for
            ``team/...`` (over ``robot_0/map`` in the Team view), else -10.
        opacity : float, optional
            0..1 (default 1).
        style : {"map", "see_through", "overlay"}
            Class set (:data:`MAP_STYLES`): opaque, transparent unknown cells, or tinted.
        """
        self._check_open()
        if draw_order is None:
            draw_order = (
                _DRAW_ORDER_TEAM_GRID if entity.strip("/").startswith("team/") else _DRAW_ORDER_GRID
            )
        self._log_grid(
            entity,
            grid,
            parent_from_grid,
            draw_order,
            static=static,
            opacity=1.0 if opacity is None else opacity,
            style=style,
        )

    # -- plans, frontiers, team ---------------------------------------------------------

    def log_points(
        self, entity: str, points: ArrayLike, robot: int | None = None, radius: float = 0.06
    ) -> None:
        """Log ``Points2D`` (N, 2) at ``entity`` (e.g. ``robot_0/frontiers``,
        ``rendezvous/meeting_point``) in its root's frame; coloured as ``robot`` if given."""
        self._check_open()
        array = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        colour = robot_colour(robot) if robot is not None else _MERGE_GREEN
        self._log(
            entity.strip("/"),
            rr.Points2D(array, radii=radius, colors=colour, draw_order=_DRAW_ORDER_POSE),
        )

    def log_line(self, entity: str, points: ArrayLike, robot: int | None = None) -> None:
        """Log one line strip (N, 2) at ``entity`` (e.g. ``robot_0/plan``)."""
        self._check_open()
        array = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        colour = robot_colour(robot) if robot is not None else _MERGE_GREEN
        strips = [array] if len(array) >= 2 else []
        self._log(
            entity.strip("/"),
            rr.LineStrips2D(strips, radii=_PLAN_RADIUS, colors=colour, draw_order=_DRAW_ORDER_SCAN),
        )

    def log_text(self, entity: str, text: str) -> None:
        """Log a one-line state (``TextLog``) at ``entity``, e.g. ``team/state``, led by
        the step as in :meth:`log_event`."""
        self._check_open()
        self._log(entity.strip("/"), rr.TextLog(self._stamp(text)))

    # -- the rendezvous ------------------------------------------------------------------

    def log_rendezvous(
        self,
        meeting_point: ArrayLike | None,
        plans: Sequence[ArrayLike] = (),
        *,
        poses: Sequence[ArrayLike | None] | None = None,
        sightings: ArrayLike | None = None,
        sighting_matches: Sequence[bool] | None = None,
        verdict: str | None = None,
        level: str = "INFO",
        radius: float = 0.2,
    ) -> None:
        """Log the state of a rendezvous at the current step, all in robot 0's map frame.

        Call it every step while a rendezvous lasts (it can be settled within a few steps)
        and :meth:`clear_rendezvous` when it ends.

        Parameters
        ----------
        meeting_point : array_like, shape (2,), or None
            ``team.rendezvous.meeting_point`` -> ``rendezvous/meeting_point`` (a disc with a
            label).
        plans : sequence of array_like (N_i, 2)
            Robot i's plan to the meeting point **in robot 0's map frame** (robot 1's plan
            brought there by the hypothesis under test: ``transform_points(hypothesis,
            plan)``) -> ``rendezvous/plan_i``.
        poses : sequence of array_like (3,) or None, optional
            Where the hypothesis under test puts each robot in robot 0's map frame (robot
            0: its SLAM pose; robot 1: ``compose(hypothesis, its SLAM pose)``; None skips a
            robot) -> ``rendezvous/robot_i`` (disc, outline, arrow).
        sightings : array_like (K, 2), optional
            Where robot 1 was seen, in robot 0's map frame -> ``rendezvous/sightings``.
        sighting_matches : sequence of bool, optional
            Per sighting: did it match the prediction (green) or not (red).
        verdict : str, optional
            One line -> ``rendezvous/status`` and an event at ``level``.
        radius : float
            Footprint radius (m) of the robots drawn.
        """
        self._check_open()
        if meeting_point is not None:
            point = np.asarray(meeting_point, dtype=np.float64).reshape(-1, 2)
            self._log(
                "rendezvous/meeting_point",
                rr.Points2D(
                    point,
                    radii=0.15,
                    colors=_MERGE_GREEN,
                    labels="meeting point",
                    draw_order=_DRAW_ORDER_POSE - 1,
                ),
            )
        for i, plan in enumerate(plans):
            self.log_line(f"rendezvous/plan_{i}", plan, robot=i)
        for i, pose in enumerate(poses or ()):
            if pose is not None:
                self._check_robot(i)
                self._log_pose(f"rendezvous/{robot_entity(i)}", i, pose, radius)
        if sightings is not None:
            seen = np.asarray(sightings, dtype=np.float64).reshape(-1, 2)
            matches = [True] * len(seen) if sighting_matches is None else list(sighting_matches)
            if len(matches) != len(seen):
                raise ValueError(
                    f"{len(seen)} sightings but {len(matches)} sighting_matches were given"
                )
            self._log(
                "rendezvous/sightings",
                rr.Points2D(
                    seen,
                    radii=0.08,
                    colors=[_MERGE_GREEN if m else _MERGE_RED for m in matches],
                    draw_order=_DRAW_ORDER_POSE + 2,
                ),
            )
        if verdict is not None:
            self._log("rendezvous/status", rr.TextLog(self._stamp(verdict), level=_level(level)))
            self.log_event(verdict, level=level)

    def clear_rendezvous(self, verdict: str | None = None, level: str = "INFO") -> None:
        """End a rendezvous: clear its meeting point, plans, robots and sightings at the
        current step, and log ``verdict`` (if given) as :meth:`log_rendezvous` does."""
        self._check_open()
        parts = [
            *_RENDEZVOUS_PARTS,
            *(f"plan_{i}" for i in range(self.n_robots)),
            *(robot_entity(i) for i in range(self.n_robots)),
        ]
        for part in parts:
            self._log(f"rendezvous/{part}", rr.Clear(recursive=True))
        if verdict is not None:
            self._log("rendezvous/status", rr.TextLog(self._stamp(verdict), level=_level(level)))
            self.log_event(verdict, level=level)

    # -- map merging ---------------------------------------------------------------------

    def log_merge(self, result: MergeResult, m1: GridMap, m2: GridMap) -> None:
        """Log one :func:`~mrslam_env.merge.pipeline.merge_maps` outcome under ``merge/``.

        The ``merge`` view is map 1's frame. Entities, all at the current ``step``; the
        stages that iterate are also on a ``merge_iteration`` timeline (one counter for
        the whole recording, so that successive merges do not overlap on it):

        ===============================  ===========================================
        ``merge/map1``                   map 1, unknown cells see-through
        ``merge/map2``                   map 2 tinted (walls in robot 1's colour),
                                         placed by the result's transform, or beside
                                         map 1 when not merged
        ``merge/skeleton/map1|map2``     skeleton cells (Points2D), same placement
        ``merge/virtual_robot/path``     the virtual runs along map 1's skeleton
        ``merge/virtual_robot/scan``     the virtual scans' returns (map 1 frame), one
                                         per ``merge_iteration``
        ``merge/mcl/particles``          MCL particles in map 2, placed as map 2, one
                                         set per ``merge_iteration``
        ``merge/hypotheses``             judged hypotheses: where each puts map 2's
                                         origin (arrows), labelled by rank, acceptance
                                         index and psi; green when confident
        ``merge/refine/candidate``       the best candidate's random-walk proposals,
                                         one per ``merge_iteration``
        ``merge/refine/candidates``      all of them at once (where each puts map 2's
                                         origin)
        ``merge/refine/best``            the accepted transform (arrow)
        ``merge/result``                 the fused map (when merged), under map 1
        ``metrics/merge/psi``,           the result's psi (cells) and acceptance
        ``metrics/merge/acceptance_index``  index, when merged
        ``metrics/merge/seconds``        wall time of the merge
        ``metrics/merge/refine_psi``     the random walk's best psi per
                                         ``merge_iteration`` (on that timeline only)
        ``events``                       ``result.reason``
        ===============================  ===========================================

        Needs a result made with ``trace=True`` for the skeleton, virtual robot, MCL and
        random-walk entities; without it only maps, hypotheses and the result are logged.
        """
        self._check_open()
        self._log_merge_stages(result, m1, m2)
        self.log_event(result.reason)

    def log_merge_attempt(
        self,
        attempt: int,
        result: MergeResult,
        m1: GridMap,
        m2: GridMap,
        label: str = "",
        then: str = "",
    ) -> None:
        """Log one live merge attempt at the current step, replacing the previous one.

        Every stage of this one is logged as :meth:`log_merge` does, and the previous
        attempt's ``merge/...`` entities that this one does not draw again (e.g. the
        fused map and accepted transform after a refusal) are cleared at this step, so
        the Merge view always shows the latest attempt. An event names the
        attempt: ``"merge attempt {attempt} ({label}): {result.reason}"``, at level
        ``INFO`` when it merged, else ``WARN``.

        Parameters
        ----------
        attempt : int
            Number of the attempt in the run (1, 2, ...), for the event.
        result : MergeResult
            From :func:`mrslam_env.merge.pipeline.merge_maps` ``(m1, m2, ...,
            trace=True)`` (without the trace only the maps, hypotheses and result are
            drawn).
        m1, m2 : GridMap
            The two maps exactly as passed to ``merge_maps``: robot 0's map (its frame is
            the Merge view's frame, the team frame) and robot 1's.
        label : str
            What triggered the attempt, e.g. ``"maps exchanged at step 120"``.
        then : str
            What the team does next, appended to the event (e.g. that a hypothesis of
            this refused attempt still goes to verification).

        The Merge view's caption (``merge/caption``, a label at the top of the view) says
        the attempt's verdict in words: ``"merge attempt 4 refused: no confident merge:
        ..."``.
        """
        self._check_open()
        verdict = "merged" if result.merged else "refused"
        name = f"merge attempt {attempt}"
        caption = f"{name} {verdict}: {result.reason}"

        def draw() -> None:
            self._log_merge_stages(result, m1, m2)
            self._log_caption(caption, _MERGE_GREEN if result.merged else _MERGE_RED)

        self._replace_merge(draw)
        event = f"{name}" + (f" ({label})" if label else "") + f" {verdict}: {result.reason}"
        event += f"; {then}" if then else ""
        self.log_event(event, level="INFO" if result.merged else "WARN")

    def log_merge_verification(
        self,
        hypothesis: ArrayLike,
        m1: GridMap,
        m2: GridMap,
        text: str,
        caption: str | None = None,
    ) -> None:
        """Show the hypothesis under verification in the Merge view, replacing what was
        there (e.g. a refused attempt's stages; its judged hypotheses, ``merge/hypotheses``,
        stay): map 1, map 2 placed by ``hypothesis`` (``map1_from_map2``), the arrow
        ``merge/verifying`` where it puts map 2's origin (unlabelled: the hypothesis'
        own label says which it is) and the caption (``caption``, default ``text``;
        e.g. ``"hypothesis #0 (1 of 3), from the virtual robot: verifying at the
        rendezvous"``); ``text`` is logged as an event."""
        self._check_open()
        placement = _as_pose(hypothesis, "hypothesis")

        def draw() -> None:
            self._log_merge_maps(m1, m2, placement)
            self._log_arrow("merge/verifying", placement, (230, 160, 0), None)
            self._log_caption(caption or text, (200, 120, 0))

        self._replace_merge(draw, keep={"merge/hypotheses"})
        self.log_event(text)

    def log_merge_accepted(
        self,
        verified: ArrayLike,
        refined: ArrayLike,
        m1: GridMap,
        m2: GridMap,
        fused: GridMap | None,
        text: str,
        *,
        caption: str | None = None,
        event: bool = True,
    ) -> None:
        """Show an accepted merge in the Merge view, replacing what was there: map 1, map
        2 placed by the ``refined`` transform (``map1_from_map2``), the fused map
        (``merge/result``), the verified estimate (``merge/verified``, a thin arrow) and
        the refined transform (``merge/refine/best``), and the caption (``caption``,
        default ``text``; e.g. ``"accepted at step 135, refined: 0.02 m / 0.06° from the
        verified estimate"``); ``text`` is logged as an event unless ``event`` is False."""
        self._check_open()
        before = _as_pose(verified, "verified")
        after = _as_pose(refined, "refined")

        def draw() -> None:
            if fused is not None:
                self._log_grid(
                    "merge/result", fused, None, _DRAW_ORDER_GRID - 1, static=False, opacity=1.0
                )
            self._log_merge_maps(m1, m2, after)
            self._log_arrow("merge/verified", before, (90, 90, 90), None, 0.03)
            self._log_arrow("merge/refine/best", after, _MERGE_GREEN, "accepted, refined", 0.07)
            self._log_caption(caption or text, _MERGE_GREEN)

        self._replace_merge(draw)
        if event:
            self.log_event(text)

    def log_merge_caption(self, text: str, level: str = "INFO") -> None:
        """Replace the Merge view's caption (e.g. ``"hypothesis 1 of 2 rejected: ..."``)
        and clear the hypothesis under verification (``merge/verifying``); no event (the
        team's decision says it)."""
        self._check_open()
        colour = _MERGE_RED if _level(level) in ("WARN", "ERROR", "CRITICAL") else _MERGE_GREEN
        if "merge/verifying" in self._merge_entities:
            self._log("merge/verifying", rr.Clear(recursive=False))
            self._merge_entities.discard("merge/verifying")
        self._log_caption(text, colour)

    def merge_difference(
        self, verified: ArrayLike, refined: ArrayLike, m2: GridMap
    ) -> tuple[float, float]:
        """How far ``refined`` moves map 2's known centre from where ``verified`` puts it
        (m) and how much it turns it (degrees, absolute)."""
        before = _as_pose(verified, "verified")
        after = _as_pose(refined, "refined")
        known = np.argwhere(~m2.unknown)
        centre = m2.cell_to_world(known.mean(axis=0)[None, :]) if len(known) else np.zeros((1, 2))
        moved = float(
            np.hypot(*(transform_points(after, centre) - transform_points(before, centre))[0])
        )
        turned = abs(math.degrees(float(wrap_angle(after[2] - before[2]))))
        return moved, turned

    # -- lifetime ------------------------------------------------------------------------

    def close(self) -> None:
        """Send the blueprint again, made for what was logged (views without content
        left out, each 2-D view zoomed to the maps logged in it, :attr:`bounds`), flush
        everything to the file and close it. Idempotent.

        Raises
        ------
        RecordingError
            The file could not be written (e.g. the disk is full: rerun's file writer
            stops, and says why only in its log); one line naming the file and the cause.
        """
        if self._closed:
            return
        self._closed = True
        try:
            self._stream.send_blueprint(
                default_blueprint(self.n_robots, self._bounds, logged=self._logged),
                make_active=True,
                make_default=True,
            )
            self._stream.flush()
            self._stream.disconnect()
        except (RuntimeError, OSError) as error:
            raise RecordingError.of(self.path, error) from error

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else f"step={self._step}"
        return f"Recorder({str(self.path)!r}, n_robots={self.n_robots}, {state})"

    # -- internals -----------------------------------------------------------------------

    def _replace_merge(self, draw: Any, keep: Collection[str] = ()) -> None:
        """Run ``draw`` (it logs ``merge/...`` entities) and clear, at this step, what the
        Merge view showed before and ``draw`` did not draw again (but ``keep``). Entities
        drawn again are not cleared: the viewer would apply a Clear at the same step after
        the new Transform3D of a map (drawing it unscaled), though not after its image."""
        kept = self._merge_entities & set(keep)
        previous = self._merge_entities - kept
        self._collect = set()
        try:
            draw()
            current = {e for e in self._collect if e.startswith("merge/")}
        finally:
            self._collect = None
        for entity in sorted(previous - current):
            self._log(entity, rr.Clear(recursive=False))
        self._merge_entities = current | kept

    def _log_merge_maps(self, m1: GridMap, m2: GridMap, placement: NDArray[np.float64]) -> None:
        self._log_grid(
            "merge/map1", m1, None, _DRAW_ORDER_GRID, static=False, opacity=1.0, style="see_through"
        )
        self._log_grid(
            "merge/map2",
            m2,
            placement,
            _DRAW_ORDER_GRID + 1,
            static=False,
            opacity=1.0,
            style="overlay",
        )

    def _log_arrow(
        self,
        entity: str,
        pose: NDArray[np.float64],
        colour: tuple[int, int, int],
        label: str | None,
        radius: float = 0.05,
    ) -> None:
        self._log(
            entity,
            rr.Arrows2D(
                origins=pose[None, :2],
                vectors=[[0.8 * math.cos(pose[2]), 0.8 * math.sin(pose[2])]],
                colors=colour,
                radii=radius,
                labels=label,
                show_labels=True,
                draw_order=_DRAW_ORDER_POSE + 1,
            ),
        )

    def _log_caption(self, text: str, colour: tuple[int, int, int]) -> None:
        """``merge/caption``: the Merge view's state in words, a label centred at the top
        of what the view shows (its y-up bounds), in lines of at most
        :data:`_CAPTION_WIDTH` characters so that a long caption is not cut at the view's
        edges."""
        bounds = self._bounds.get("merge", (0.0, 0.0, 0.0, 0.0))
        text = textwrap.fill(text, _CAPTION_WIDTH, break_long_words=False)
        self._log(
            "merge/caption",
            rr.Points2D(
                [[0.5 * (bounds[0] + bounds[2]), bounds[3]]],
                radii=0.12,
                colors=colour,
                labels=text,
                show_labels=True,
                draw_order=_DRAW_ORDER_POSE + 5,
            ),
        )

    def _log_merge_stages(self, result: MergeResult, m1: GridMap, m2: GridMap) -> None:
        transform = result.transform
        if transform is not None:
            placement = np.asarray(transform, dtype=np.float64)
        else:
            # Side by side: map 2's frame shifted right of map 1's extent.
            x1 = m1.origin[0] + m1.cells.shape[1] * m1.resolution
            placement = np.array([x1 + 2.0 - m2.origin[0], m1.origin[1] - m2.origin[1], 0.0])
        self._log_merge_maps(m1, m2, placement)
        trace = result.trace
        if trace is not None:
            self._log_merge_trace(result, placement)
        if result.hypotheses:
            origins = np.array([h.map1_from_map2[:2] for h in result.hypotheses])
            headings = np.array(
                [
                    [math.cos(h.map1_from_map2[2]), math.sin(h.map1_from_map2[2])]
                    for h in result.hypotheses
                ]
            )
            self._log(
                "merge/hypotheses",
                rr.Arrows2D(
                    origins=origins,
                    vectors=0.5 * headings,
                    # Labels for the best three and the confident ones: a dozen overlap.
                    labels=[
                        f"#{i} {source_words(h.proposed_by)}: agreement "
                        f"{h.acceptance_index:.2f}, overlap {h.overlap:.0%}"
                        + ("" if h.confident else ", not confident")
                        if i < 3 or h.confident
                        else ""
                        for i, h in enumerate(result.hypotheses)
                    ],
                    colors=[_MERGE_GREEN if h.confident else _MERGE_RED for h in result.hypotheses],
                    radii=0.04,
                    draw_order=_DRAW_ORDER_POSE,
                ),
            )
        if result.chosen is not None and transform is not None:
            best = np.asarray(transform, dtype=np.float64)
            self._log(
                "merge/refine/best",
                rr.Arrows2D(
                    origins=best[None, :2],
                    vectors=[[0.8 * math.cos(best[2]), 0.8 * math.sin(best[2])]],
                    colors=_MERGE_GREEN,
                    radii=0.07,
                    draw_order=_DRAW_ORDER_POSE + 1,
                ),
            )
            self.log_scalar("merge/psi", result.psi)
            if result.agreement is not None:
                self.log_scalar("merge/acceptance_index", result.agreement.index)
        if result.fused is not None:
            self._log_grid(
                "merge/result", result.fused, None, _DRAW_ORDER_GRID - 1, static=False, opacity=1.0
            )
        self.log_scalar("merge/seconds", result.seconds.get("total", math.nan))

    def _log_merge_trace(self, result: MergeResult, placement: NDArray[np.float64]) -> None:
        trace = result.trace
        assert trace is not None
        hypotheses = trace.hypotheses
        w1, w2 = trace.working1, trace.working2
        for name, graph, grid, where in (
            ("map1", hypotheses.skeleton1, w1, None),
            ("map2", hypotheses.skeleton2, w2, placement),
        ):
            points = grid.cell_to_world(np.argwhere(graph.skeleton))
            if where is not None:
                points = transform_points(where, points)
            self._log(
                f"merge/skeleton/{name}",
                rr.Points2D(points, radii=0.03, colors=(230, 120, 0), draw_order=_DRAW_ORDER_PATH),
            )
        paths = [run.poses_in_map1[:, :2] for run in hypotheses.runs]
        if paths:
            self._log(
                "merge/virtual_robot/path",
                rr.LineStrips2D(
                    paths, radii=0.03, colors=(200, 0, 200), draw_order=_DRAW_ORDER_PATH + 1
                ),
            )
        step, sim_time = self._step, self._sim_time
        for k, run in enumerate(hypotheses.runs):
            history = hypotheses.mcl_results[k].history if k < len(hypotheses.mcl_results) else []
            for t, pose in enumerate(run.poses_in_map1):
                self._stream.set_time("merge_iteration", sequence=self._merge_iteration)
                self._merge_iteration += 1
                ranges = np.nan_to_num(run.ranges[t], nan=run.max_range)
                hits = scan_hits_world(pose, ranges, run.beam_angles, run.max_range)
                self._log(
                    "merge/virtual_robot/scan",
                    rr.Points2D(
                        hits, radii=0.03, colors=(200, 0, 200), draw_order=_DRAW_ORDER_SCAN
                    ),
                )
                if t < len(history):
                    particles = transform_points(placement, history[t][:, :2])
                    self._log(
                        "merge/mcl/particles",
                        rr.Points2D(
                            particles,
                            radii=0.025,
                            colors=(0, 150, 255),
                            draw_order=_DRAW_ORDER_SCAN + 1,
                        ),
                    )
        if trace.refinements and trace.refinements[0].trace is not None:
            walk = trace.refinements[0].trace
            origin = np.zeros((1, 2))
            first = self._merge_iteration
            proposals = np.array([transform_points(c, origin)[0] for c in walk.candidates])
            for j, where in enumerate(proposals):
                self._stream.set_time("merge_iteration", sequence=first + j)
                self._log(
                    "merge/refine/candidate",
                    rr.Points2D(
                        where[None, :],
                        radii=0.05,
                        colors=(90, 90, 90),
                        draw_order=_DRAW_ORDER_POSE - 2,
                    ),
                )
            self._merge_iteration = first + len(proposals)
            self._stream.reset_time()
            self.set_time(step, sim_time)
            if len(proposals):
                self._log(
                    "merge/refine/candidates",
                    rr.Points2D(
                        proposals,
                        radii=0.03,
                        colors=(90, 90, 90),
                        draw_order=_DRAW_ORDER_POSE - 2,
                    ),
                )
            # The walk's best psi per proposal, on merge_iteration only: on the step
            # timeline the whole walk would stack up at one step.
            self._stream.reset_time()
            self._style_metric("metrics/merge/refine_psi")
            for j, psi in enumerate(walk.best_psi):
                self._stream.set_time("merge_iteration", sequence=first + j)
                self._log("metrics/merge/refine_psi", rr.Scalars(float(psi)))
        self._stream.reset_time()
        self.set_time(step, sim_time)

    def _log_grid(
        self,
        entity: str,
        grid: GridMap,
        parent_from_grid: ArrayLike | None,
        draw_order: float,
        *,
        static: bool,
        opacity: float | None = None,
        style: MapStyle = "map",
    ) -> None:
        path = entity.strip("/")
        parts = path.split("/")
        if len(parts) < 2 or not all(parts):
            raise ValueError(
                f"log_grid needs an entity below a root such as 'robot_0/map', got {entity!r}"
            )
        if style not in MAP_STYLES:
            raise ValueError(f"style must be one of {sorted(MAP_STYLES)}, got {style!r}")
        self._declare_y_up(parts[0])
        classes = occupancy_classes(grid, style)
        corner = grid_corner_pose(grid, parent_from_grid)
        resolution = float(grid.resolution)
        self._log(
            path,
            rr.Transform3D(
                translation=[corner[0], corner[1], 0.0],
                rotation_axis_angle=rr.RotationAxisAngle(axis=[0.0, 0.0, 1.0], radians=corner[2]),
                scale=[resolution, resolution, 1.0],
            ),
            rr.SegmentationImage(classes, opacity=opacity, draw_order=draw_order),
            static=static,
        )
        # The default zoom covers the known cells (a SLAM grid is mostly unknown margin).
        known_rows = np.flatnonzero((grid.cells != UNKNOWN).any(axis=1))
        known_cols = np.flatnonzero((grid.cells != UNKNOWN).any(axis=0))
        if len(known_rows) == 0:
            return
        u0, u1 = known_cols[0] * resolution, (known_cols[-1] + 1) * resolution
        v0, v1 = known_rows[0] * resolution, (known_rows[-1] + 1) * resolution
        c, s = math.cos(corner[2]), math.sin(corner[2])
        box = ((u0, v0), (u1, v0), (u0, v1), (u1, v1))
        xs = [corner[0] + c * u - s * v for u, v in box]
        ys = [corner[1] + s * u + c * v for u, v in box]
        extent = (min(xs), min(ys), max(xs), max(ys))
        self._grow_bounds(parts[0], extent)
        if path == f"{robot_entity(0)}/map":
            self._grow_bounds("team", extent)

    def _log(self, entity: str, *archetypes: Any, static: bool = False) -> None:
        """Log through the stream and remember the entity (for the final blueprint and,
        while a merge attempt is logged, for the next one)."""
        self._logged.add(entity.strip("/"))
        if self._collect is not None:
            self._collect.add(entity.strip("/"))
        self._stream.log(entity, *archetypes, static=static)

    def _stamp(self, text: str) -> str:
        """A text-log line: "#", the step left-aligned in five columns, a space, ``text``."""
        return f"#{self._step:<5} {text}"

    def _grow_bounds(self, key: str, extent: Bounds) -> None:
        old = self._bounds.get(key)
        if old is not None:
            extent = (
                min(old[0], extent[0]),
                min(old[1], extent[1]),
                max(old[2], extent[2]),
                max(old[3], extent[3]),
            )
        self._bounds[key] = extent

    def _log_path(self, entity: str, robot: int, points: NDArray[np.float64]) -> None:
        self._log(
            entity,
            rr.LineStrips2D(
                [points],
                radii=_PATH_RADIUS,
                colors=robot_colour(robot),
                draw_order=_DRAW_ORDER_PATH,
            ),
        )

    def _log_pose(self, entity: str, robot: int, pose_xytheta: ArrayLike, radius: float) -> None:
        pose = _as_pose(pose_xytheta, "pose")
        if not (radius > 0 and math.isfinite(radius)):
            raise ValueError(f"radius must be a finite number > 0 m, got {radius}")
        centre = pose[None, :2]
        heading = 2.0 * radius * np.array([[math.cos(pose[2]), math.sin(pose[2])]])
        colour = robot_colour(robot)
        self._log(
            entity,
            rr.Points2D(
                centre,
                radii=radius,
                colors=colour,
                labels=robot_entity(robot),
                show_labels=True,
                draw_order=_DRAW_ORDER_POSE,
            ),
            rr.Ellipses2D(
                centers=centre,
                half_sizes=[[radius, radius]],
                line_radii=_OUTLINE_RADIUS,
                colors=_OUTLINE,
                draw_order=_DRAW_ORDER_POSE + 1,
            ),
            rr.Arrows2D(
                origins=centre,
                vectors=heading,
                radii=_ARROW_RADIUS,
                colors=colour,
                draw_order=_DRAW_ORDER_POSE + 1,
            ),
        )

    def _style_metric(self, entity: str) -> None:
        """Name a metric's series after its path, colour a robot's series as the robot, and
        mark the values of the merge metrics (one per merge)."""
        if entity in self._styled_metrics:
            return
        self._styled_metrics.add(entity)
        name = entity.removeprefix("metrics/")
        colour = next(
            (robot_colour(i) for i in range(self.n_robots) if robot_entity(i) in name.split("/")),
            None,
        )
        styles: list[Any] = [rr.SeriesLines(names=name, widths=2.0, colors=colour)]
        if name.startswith("merge/") and name != "merge/refine_psi":
            # One value per merge: a lone value draws no line, so mark each one.
            styles.append(rr.SeriesPoints(names=name, colors=colour, marker_sizes=4.0))
        self._log(entity, *styles, static=True)

    def _declare_y_up(self, root: str) -> None:
        """Give a root entity the static y-up -> 2-D-view rotation and the map classes'
        annotation context (once)."""
        if root in self._y_up_roots:
            return
        self._y_up_roots.add(root)
        self._log(
            root,
            rr.Transform3D(
                rotation_axis_angle=rr.RotationAxisAngle(axis=[1.0, 0.0, 0.0], radians=math.pi)
            ),
            annotation_context(),
            static=True,
        )

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"Recorder for {str(self.path)!r} is closed")

    def _check_robot(self, robot: int) -> None:
        if not (0 <= robot < self.n_robots):
            raise ValueError(f"robot must be in [0, {self.n_robots}), got {robot}")


def _level(level: str) -> str:
    normalised = level.upper()
    return _LEVELS.get(normalised, normalised)


def _as_pose(value: ArrayLike, name: str) -> NDArray[np.float64]:
    pose = np.asarray(value, dtype=np.float64)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ValueError(f"{name} must be a finite (x, y, theta), got {value!r}")
    return np.array([pose[0], pose[1], float(wrap_angle(pose[2]))])
