"""The Rerun sink: one :class:`Recorder` writes one ``.rrd`` file (docs/design.md §7).

This is the only module of the project that imports :mod:`rerun`. It logs through an
explicit :class:`rerun.RecordingStream` (never the global one), saves straight to a file
(no viewer, no network) and attaches a default blueprint to the same file.

Entity paths
------------
All spatial data is in metres. Robots are numbered from 0 (``robot_0``, ``robot_1``...).

=============================  ==========================================================
``world/ground_truth``         static ground-truth occupancy grid (``rr.GridMap``)
``world/walls``                static wall outlines, ``LineStrips2D`` of the lidar segments
``world/robot_i/true_pose``    ground-truth pose: heading arrow + footprint circle
``world/robot_i/scan``         lidar hits in the world frame (``Points2D``)
``robot_i/map``                robot i's own map (``rr.GridMap``) in its map frame
``robot_i/pose``               its SLAM pose there: heading arrow + footprint circle
``robot_i/path``               its SLAM trajectory there (``LineStrips2D``)
``merge/...``                  merge stages, in map 1's frame (:meth:`Recorder.log_merge`)
``rendezvous/...``, ``team/...``  the team's decisions
``metrics/<name>``             ``Scalars``
``events``                     ``TextLog`` of everything the team decides
=============================  ==========================================================

Timelines: ``step`` (sequence) and ``sim_time`` (duration, seconds). Wall-clock
``log_time`` is switched off so that a recording depends only on the simulation.

Frames and the y axis
---------------------
Every spatial root (``world``, ``robot_i``, ``merge``, ``rendezvous``, ``team``) holds data
in its own right-handed, **y-up** frame, exactly as docs/design.md §2 defines it: points are logged
as they are, never negated. Rerun's 2-D view draws +y *down*, so each root carries one
static ``Transform3D``, a rotation of pi about the x axis, which turns (x right, y up,
z towards the viewer) into the 2-D view's (x right, y down, z into the screen). The
default blueprint's 2-D views therefore use ``origin="/"`` (the root transforms apply
below a view's origin, never at it) and select their entities with ``contents``. A 3-D
view should use e.g. ``origin="/world"`` so as not to see the world upside down.

Grids are logged as ``rr.GridMap``: the image's row 0 is the *top* row (highest y), so
rows are flipped, and its ``translation`` is the lower-left (outer) corner of cell
[0, 0], i.e. ``GridMap.origin``, with one pixel per cell of ``cell_size = resolution``.
Cell (iy, ix) thus covers ``[ox + ix*res, ox + (ix+1)*res] x [oy + iy*res, oy + (iy+1)*res]``
in its root's frame, the frame poses and scans are logged in, so maps and poses drawn in
one view line up. Cells are drawn as ROS ``map_server`` grey levels: free 254,
occupied 0, unknown 205.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Final, Self

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import transform_points, wrap_angle
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap

if TYPE_CHECKING:
    from mrslam_env.merge.pipeline import MergeResult
    from mrslam_env.sim.world import WorldSpec

__all__ = [
    "SPATIAL_ROOTS",
    "Recorder",
    "default_blueprint",
    "grid_corner_pose",
    "occupancy_image",
    "robot_entity",
    "scan_hits_world",
]

#: Root entities that hold y-up spatial data besides ``robot_i``.
SPATIAL_ROOTS: Final = ("world", "merge", "rendezvous", "team")

# ROS map_server grey levels (docs/design.md §2), so a recorded map looks like the map file.
_GREY_FREE: Final = 254
_GREY_OCCUPIED: Final = 0
_GREY_UNKNOWN: Final = 205

# Higher is drawn on top: grids under walls under scans under poses.
_DRAW_ORDER_GROUND_TRUTH: Final = -20.0
_DRAW_ORDER_GRID: Final = -10.0
_DRAW_ORDER_WALLS: Final = 10.0
_DRAW_ORDER_SCAN: Final = 20.0
_DRAW_ORDER_POSE: Final = 30.0

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

_LEVELS: Final = {"WARNING": "WARN", "FATAL": "CRITICAL"}


def robot_entity(robot: int) -> str:
    """Entity-path name of robot ``robot`` (numbered from 0): ``"robot_0"``..."""
    return f"robot_{robot}"


def robot_colour(robot: int) -> tuple[int, int, int]:
    """A fixed RGB colour per robot, shared by all its entities."""
    return _ROBOT_COLOURS[robot % len(_ROBOT_COLOURS)]


def occupancy_image(grid: GridMap) -> NDArray[np.uint8]:
    """Grey image (rows, cols) uint8 of a grid, row 0 = **top** (highest y).

    Free 254, occupied 0, unknown 205, as ROS ``map_server`` images. The input is not
    modified.
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


def default_blueprint(n_robots: int) -> rrb.Blueprint:
    """The default viewer layout (docs/design.md §7).

    Top row: the world (ground truth, true poses, scans), the merge stages, the team
    (merged map, rendezvous). Middle row: one view per robot's own map frame. Bottom row:
    metrics over time and the event log. 2-D views have ``origin="/"`` so that the y-up
    root transforms apply (see the module docstring).
    """
    robots = [
        rrb.Spatial2DView(
            origin="/",
            contents=[f"+ /{robot_entity(i)}/**"],
            name=f"Robot {i}",
        )
        for i in range(n_robots)
    ]
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(
                rrb.Spatial2DView(origin="/", contents=["+ /world/**"], name="World"),
                rrb.Spatial2DView(origin="/", contents=["+ /merge/**"], name="Merge"),
                rrb.Spatial2DView(
                    origin="/", contents=["+ /team/**", "+ /rendezvous/**"], name="Team"
                ),
            ),
            rrb.Horizontal(*robots),
            rrb.Horizontal(
                rrb.TimeSeriesView(origin="/metrics", name="Metrics"),
                rrb.TextLogView(origin="/events", name="Events"),
            ),
            row_shares=[3, 3, 2],
        ),
        rrb.TimePanel(timeline="step"),
    )


class Recorder:
    """Writes one ``.rrd`` file through an explicit :class:`rerun.RecordingStream`.

    No viewer, no network: the file carries the recording and its default blueprint.
    Use as a context manager, or call :meth:`close`. Everything logged before the first
    :meth:`set_time` lands at step 0, sim_time 0.

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
        self._closed = False
        self._y_up_roots: set[str] = set()
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

    # -- the world -----------------------------------------------------------------------

    def log_ground_truth(self, world: WorldSpec, grid: GridMap) -> None:
        """Log the static ground truth: ``world/ground_truth`` (grid) and ``world/walls``."""
        self._check_open()
        self._log_grid("world/ground_truth", grid, None, _DRAW_ORDER_GROUND_TRUTH, static=True)
        # One two-point strip per lidar segment (x0, y0, x1, y1).
        strips = list(np.asarray(world.segments, dtype=np.float64).reshape(-1, 2, 2))
        self._stream.log(
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
        """Log ``world/robot_i/true_pose``: a heading arrow and the footprint circle.

        ``pose_xytheta`` is the ground-truth pose (m, m, rad); ``radius`` the footprint (m).
        """
        self._check_open()
        self._check_robot(robot)
        self._log_pose(f"world/{robot_entity(robot)}/true_pose", robot, pose_xytheta, radius)

    def log_robot_pose(self, robot: int, pose_in_map: ArrayLike, radius: float = 0.2) -> None:
        """Log ``robot_i/pose``: the robot's SLAM pose in its own map frame (arrow and
        footprint), drawn over ``robot_i/map``."""
        self._check_open()
        self._check_robot(robot)
        self._log_pose(f"{robot_entity(robot)}/pose", robot, pose_in_map, radius)

    def log_robot_path(self, robot: int, poses_in_map: ArrayLike) -> None:
        """Log ``robot_i/path``: the robot's trajectory (T, 3) or (T, 2) in its map frame."""
        self._check_open()
        self._check_robot(robot)
        path = np.asarray(poses_in_map, dtype=np.float64)
        if path.ndim != 2 or path.shape[1] not in (2, 3) or not np.all(np.isfinite(path)):
            raise ValueError(f"poses_in_map must be finite, shape (T, 2|3), got {path.shape}")
        self._stream.log(
            f"{robot_entity(robot)}/path",
            rr.LineStrips2D(
                [path[:, :2]],
                radii=0.02,
                colors=robot_colour(robot),
                draw_order=_DRAW_ORDER_SCAN,
            ),
        )

    def log_scan(
        self,
        robot: int,
        pose_xytheta: ArrayLike,
        ranges: ArrayLike,
        angles: ArrayLike,
        max_range: float,
    ) -> None:
        """Log ``world/robot_i/scan``: the hits of one scan in the world frame.

        See :func:`scan_hits_world`; returns at ``max_range`` or beyond are not drawn.
        """
        self._check_open()
        self._check_robot(robot)
        hits = scan_hits_world(pose_xytheta, ranges, angles, max_range)
        self._stream.log(
            f"world/{robot_entity(robot)}/scan",
            rr.Points2D(
                hits,
                radii=0.03,
                colors=robot_colour(robot),
                draw_order=_DRAW_ORDER_SCAN,
            ),
        )

    # -- events and metrics --------------------------------------------------------------

    def log_event(self, text: str, level: str = "INFO") -> None:
        """Append to the ``events`` text log.

        ``level`` is one of Rerun's ``CRITICAL, ERROR, WARN, INFO, DEBUG, TRACE``
        (case-insensitive; ``WARNING`` means ``WARN``).
        """
        self._check_open()
        normalised = level.upper()
        self._stream.log("events", rr.TextLog(text, level=_LEVELS.get(normalised, normalised)))

    def log_scalar(self, path: str, value: float) -> None:
        """Log one value of the time series ``metrics/<path>`` (e.g. ``"coverage/robot_0"``)."""
        self._check_open()
        name = path.strip("/")
        if not name:
            raise ValueError("log_scalar needs a non-empty metric path")
        self._stream.log(f"metrics/{name}", rr.Scalars(float(value)))

    # -- grids ---------------------------------------------------------------------------

    def log_grid(
        self,
        entity: str,
        grid: GridMap,
        parent_from_grid: ArrayLike | None = None,
        *,
        static: bool = False,
        draw_order: float = _DRAW_ORDER_GRID,
        opacity: float | None = None,
    ) -> None:
        """Log a grid anywhere, e.g. ``robot_0/map``, ``merge/result``, ``team/merged_map``.

        Parameters
        ----------
        entity : str
            Entity path below a root (``"robot_0/map"``; a bare root is refused because it
            carries the y-up transform). The grid is drawn in its root's frame.
        grid : GridMap
        parent_from_grid : array_like, shape (3,), optional
            The SE(2) transform ``(x, y, theta)`` mapping the grid's own
            frame (where ``grid.origin`` is given) into the entity's frame, e.g.
            ``map1_from_map2`` to draw map 2 under ``robot_1/...`` or ``team/...``. It is
            folded into the ``GridMap`` pose; no transform is logged on the entity.
        static : bool
            Log as static (timeless) data.
        draw_order : float
            Layering among overlapping 2-D content; higher is drawn on top.
        opacity : float, optional
            0..1; useful when overlaying two maps.
        """
        self._check_open()
        self._log_grid(entity, grid, parent_from_grid, draw_order, static=static, opacity=opacity)

    # -- plans, frontiers, team ---------------------------------------------------------

    def log_points(
        self, entity: str, points: ArrayLike, robot: int | None = None, radius: float = 0.06
    ) -> None:
        """Log ``Points2D`` (N, 2) at ``entity`` (e.g. ``robot_0/frontiers``,
        ``rendezvous/meeting_point``) in its root's frame; coloured as ``robot`` if given."""
        self._check_open()
        array = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        colour = robot_colour(robot) if robot is not None else (0, 170, 0)
        self._stream.log(
            entity.strip("/"),
            rr.Points2D(array, radii=radius, colors=colour, draw_order=_DRAW_ORDER_POSE),
        )

    def log_line(self, entity: str, points: ArrayLike, robot: int | None = None) -> None:
        """Log one line strip (N, 2) at ``entity`` (e.g. ``robot_0/plan``)."""
        self._check_open()
        array = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        colour = robot_colour(robot) if robot is not None else (0, 170, 0)
        strips = [array] if len(array) >= 2 else []
        self._stream.log(
            entity.strip("/"),
            rr.LineStrips2D(strips, radii=0.03, colors=colour, draw_order=_DRAW_ORDER_SCAN),
        )

    def log_text(self, entity: str, text: str) -> None:
        """Log a one-line state (``TextLog``) at ``entity``, e.g. ``team/state``."""
        self._check_open()
        self._stream.log(entity.strip("/"), rr.TextLog(text))

    # -- map merging ---------------------------------------------------------------------

    def log_merge(self, result: MergeResult, m1: GridMap, m2: GridMap) -> None:
        """Log one :func:`~mrslam_env.merge.pipeline.merge_maps` outcome under ``merge/``.

        The ``merge`` view is map 1's frame. Entities, all at the current ``step``; the
        stages that iterate are also on a ``merge_iteration`` timeline:

        ==============================  ============================================
        ``merge/map1``, ``merge/map2``  the inputs; map 2 placed by the result's
                                        transform, or beside map 1 when not merged
        ``merge/skeleton/map1|map2``    skeleton cells (Points2D), same placement
        ``merge/virtual_robot/path``    the virtual runs along map 1's skeleton
        ``merge/virtual_robot/scan``    the virtual scans' returns (map 1 frame)
        ``merge/mcl/particles``         MCL particles in map 2 per iteration
        ``merge/hypotheses``            judged hypotheses: where each puts map 2's
                                        origin (arrows), labelled by rank
        ``merge/refine/candidate``      random-walk proposals of the best candidate
        ``merge/refine/best``           its best transform so far
        ``merge/result``                the fused map (when merged)
        ``metrics/merge/*``             psi, acceptance index, seconds
        ==============================  ============================================

        Needs a result made with ``trace=True`` for the skeleton, virtual robot, MCL and
        random-walk entities; without it only maps, hypotheses and the result are logged.
        """
        self._check_open()
        step = self._step
        transform = result.transform
        if transform is not None:
            placement = np.asarray(transform, dtype=np.float64)
        else:
            # Side by side: map 2's frame shifted right of map 1's extent.
            x1 = m1.origin[0] + m1.cells.shape[1] * m1.resolution
            placement = np.array([x1 + 2.0 - m2.origin[0], m1.origin[1] - m2.origin[1], 0.0])
        self._log_grid("merge/map1", m1, None, _DRAW_ORDER_GRID, static=False)
        self._log_grid("merge/map2", m2, placement, _DRAW_ORDER_GRID + 1, static=False, opacity=0.6)
        trace = result.trace
        if trace is not None:
            hypotheses = trace.hypotheses
            w1, w2 = trace.working1, trace.working2
            for name, graph, grid, where in (
                ("map1", hypotheses.skeleton1, w1, None),
                ("map2", hypotheses.skeleton2, w2, placement),
            ):
                points = grid.cell_to_world(np.argwhere(graph.skeleton))
                if where is not None:
                    points = transform_points(where, points)
                self._stream.log(
                    f"merge/skeleton/{name}",
                    rr.Points2D(points, radii=0.03, colors=(230, 120, 0), draw_order=15.0),
                )
            paths = [run.poses_in_map1[:, :2] for run in hypotheses.runs]
            if paths:
                self._stream.log(
                    "merge/virtual_robot/path",
                    rr.LineStrips2D(paths, radii=0.03, colors=(200, 0, 200), draw_order=16.0),
                )
            iteration = 0
            for k, run in enumerate(hypotheses.runs):
                history = (
                    hypotheses.mcl_results[k].history if k < len(hypotheses.mcl_results) else []
                )
                for t, pose in enumerate(run.poses_in_map1):
                    self._stream.set_time("merge_iteration", sequence=iteration)
                    iteration += 1
                    ranges = np.nan_to_num(run.ranges[t], nan=run.max_range)
                    hits = scan_hits_world(pose, ranges, run.beam_angles, run.max_range)
                    self._stream.log(
                        "merge/virtual_robot/scan",
                        rr.Points2D(hits, radii=0.03, colors=(200, 0, 200), draw_order=17.0),
                    )
                    if t < len(history):
                        particles = transform_points(placement, history[t][:, :2])
                        self._stream.log(
                            "merge/mcl/particles",
                            rr.Points2D(
                                particles, radii=0.02, colors=(0, 150, 255), draw_order=18.0
                            ),
                        )
            if trace.refinements and trace.refinements[0].trace is not None:
                walk = trace.refinements[0].trace
                origin = np.zeros((1, 2))
                for j, candidate in enumerate(walk.candidates):
                    self._stream.set_time("merge_iteration", sequence=iteration + j)
                    self._stream.log(
                        "merge/refine/candidate",
                        rr.Points2D(
                            transform_points(candidate, origin),
                            radii=0.05,
                            colors=(120, 120, 120),
                        ),
                    )
                    self._stream.log("metrics/merge/refine_psi", rr.Scalars(walk.best_psi[j]))
            self._stream.reset_time()
            self.set_time(step, self._sim_time)
        if result.hypotheses:
            origins = np.array([h.map1_from_map2[:2] for h in result.hypotheses])
            headings = np.array(
                [
                    [math.cos(h.map1_from_map2[2]), math.sin(h.map1_from_map2[2])]
                    for h in result.hypotheses
                ]
            )
            self._stream.log(
                "merge/hypotheses",
                rr.Arrows2D(
                    origins=origins,
                    vectors=0.5 * headings,
                    labels=[
                        f"#{i} ai {h.acceptance_index:.2f}" for i, h in enumerate(result.hypotheses)
                    ],
                    colors=[(0, 170, 0) if h.confident else (200, 0, 0) for h in result.hypotheses],
                    radii=0.04,
                    draw_order=_DRAW_ORDER_POSE,
                ),
            )
        if result.chosen is not None and transform is not None:
            best = np.asarray(transform, dtype=np.float64)
            self._stream.log(
                "merge/refine/best",
                rr.Arrows2D(
                    origins=best[None, :2],
                    vectors=[[0.5 * math.cos(best[2]), 0.5 * math.sin(best[2])]],
                    colors=(0, 170, 0),
                    radii=0.06,
                    draw_order=_DRAW_ORDER_POSE,
                ),
            )
            self.log_scalar("merge/psi", result.psi)
            if result.agreement is not None:
                self.log_scalar("merge/acceptance_index", result.agreement.index)
        if result.fused is not None:
            self._log_grid("merge/result", result.fused, None, _DRAW_ORDER_GRID + 2, static=False)
        self.log_scalar("merge/seconds", result.seconds.get("total", math.nan))
        self.log_event(result.reason)

    # -- lifetime ------------------------------------------------------------------------

    def close(self) -> None:
        """Flush everything to the file and close it. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._stream.flush()
        self._stream.disconnect()

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

    def _log_grid(
        self,
        entity: str,
        grid: GridMap,
        parent_from_grid: ArrayLike | None,
        draw_order: float,
        *,
        static: bool,
        opacity: float | None = None,
    ) -> None:
        path = entity.strip("/")
        parts = path.split("/")
        if len(parts) < 2 or not all(parts):
            raise ValueError(
                f"log_grid needs an entity below a root such as 'robot_0/map', got {entity!r}"
            )
        self._declare_y_up(parts[0])
        image = occupancy_image(grid)
        corner = grid_corner_pose(grid, parent_from_grid)
        rows, cols = image.shape
        self._stream.log(
            path,
            rr.GridMap(
                data=image.tobytes(),
                format=rr.components.ImageFormat(
                    width=cols, height=rows, color_model="L", channel_datatype="U8"
                ),
                cell_size=grid.resolution,
                translation=[corner[0], corner[1], 0.0],
                rotation_axis_angle=rr.RotationAxisAngle(axis=[0.0, 0.0, 1.0], radians=corner[2]),
                opacity=opacity,
                draw_order=draw_order,
            ),
            static=static,
        )

    def _log_pose(self, entity: str, robot: int, pose_xytheta: ArrayLike, radius: float) -> None:
        pose = _as_pose(pose_xytheta, "pose")
        if not (radius > 0 and math.isfinite(radius)):
            raise ValueError(f"radius must be a finite number > 0 m, got {radius}")
        centre = pose[None, :2]
        heading = radius * np.array([[math.cos(pose[2]), math.sin(pose[2])]])
        colour = robot_colour(robot)
        self._stream.log(
            entity,
            rr.Arrows2D(
                origins=centre,
                vectors=heading,
                radii=0.03,
                colors=colour,
                labels=robot_entity(robot),
                show_labels=False,
                draw_order=_DRAW_ORDER_POSE,
            ),
            rr.Ellipses2D(
                centers=centre,
                half_sizes=[[radius, radius]],
                line_radii=0.02,
                colors=colour,
                draw_order=_DRAW_ORDER_POSE,
            ),
        )

    def _declare_y_up(self, root: str) -> None:
        """Give a root entity the static y-up -> 2-D-view rotation (once)."""
        if root in self._y_up_roots:
            return
        self._y_up_roots.add(root)
        self._stream.log(
            root,
            rr.Transform3D(
                rotation_axis_angle=rr.RotationAxisAngle(axis=[1.0, 0.0, 0.0], radians=math.pi)
            ),
            static=True,
        )

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"Recorder for {str(self.path)!r} is closed")

    def _check_robot(self, robot: int) -> None:
        if not (0 <= robot < self.n_robots):
            raise ValueError(f"robot must be in [0, {self.n_robots}), got {robot}")


def _as_pose(value: ArrayLike, name: str) -> NDArray[np.float64]:
    pose = np.asarray(value, dtype=np.float64)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ValueError(f"{name} must be a finite (x, y, theta), got {value!r}")
    return np.array([pose[0], pose[1], float(wrap_angle(pose[2]))])
