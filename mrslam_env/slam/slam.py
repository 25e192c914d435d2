"""One robot's onboard SLAM: a growing occupancy grid and scan-to-map matching (docs/design.md §4).

:class:`RobotSlam` takes, every step, the robot's dead-reckoning pose (its odom frame) and
its lidar scan, and returns its pose in its *map* frame. The map frame is the robot's start
pose, i.e. the odom frame at the first update, so the first pose is ``(0, 0, 0)``.

Per update (``mode="slam"``):

1. **Predict**: apply the odometry motion since the last matched scan to the pose of that
   scan (``pose_k = pose_ref ∘ inverse(odom_ref) ∘ odom_k``).
2. **Motion filter**: unless the robot has moved ``min_translation`` or turned
   ``min_rotation`` since the last matched scan, stop here (the prediction is the pose).
3. **Match** the scan from the prediction
   (:func:`~mrslam_env.slam.matcher.match_scan`) to the map *as it was* ``match_lag``
   integrated scans ago (the *matched map*: the map without its newest scans, which wait
   to enter it); if the match is rejected, the waiting scans enter the matched map at
   once, the prediction is kept (odometry) and the scan is not integrated, unless
   ``integrate_rejected_after`` matches in a row have failed (then mapping goes on with
   odometry, e.g. into an area the map does not cover yet). Why the lag: matched against
   the current map, each scan inherits the heading errors of the scans just before it,
   which it would then pass on; on the walls of real buildings (the raster outline of a
   map) a scan matched against a young map is off by up to ~0.2°, and the errors of the
   first scans chained into a map a quarter degree off. Matched against the map of 20
   scans ago, those scans are placed independently against a common map and their errors
   average out in it (docs/decisions.md, "Onboard SLAM").
4. **Integrate** the scan at the resulting pose (:meth:`OccupancyGrid.integrate_scan`)
   into the map (:attr:`RobotSlam.grid`, always current) and queue it for the matched map,
   but only once the robot has moved ``map_update_translation`` or turned
   ``map_update_rotation`` since the last integrated scan (a scan matched but not
   integrated still sets the pose). The defaults equal the motion filter's, so every
   matched scan is integrated: sparser updates cut the heading random walk in SLAM-only
   runs but measured worse end to end, see :class:`~mrslam_env.slam.config.SlamConfig`).

``mode="pose_graph"`` runs the same front end and hands every integrated scan to a
:class:`~mrslam_env.slam.backend.LocalChain` (the scan matched against a local map of the
newest scans only, for the graph's odometry where the front end may have pulled itself
onto an old map) and a :class:`~mrslam_env.slam.backend.PoseGraphBackend` (keyframes,
pose graph, loop closures). When an optimisation after a loop closure moves some node more
than the redraw tolerance from where its scans are drawn, both maps are redrawn from all
the scans at their optimised poses (the matched map without the scans still waiting for
it), and the front end's poses (the robot's pose, ``map_from_odom``) move with the newest
node; below the tolerance the maps and the poses stay as they were.
:attr:`RobotSlam.trajectory` keeps the poses as they were returned;
:attr:`RobotSlam.optimized_trajectory` gives every step's pose through the optimised graph.

``mode="odometry"`` skips step 3 (the pose is the odometry itself) and
``mode="ground_truth"`` replaces steps 1–3 by the true pose (in the map frame) passed in.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import compose, wrap_scalar
from mrslam_env.slam.backend import LocalChain, PoseGraphBackend, normals_of
from mrslam_env.slam.config import SlamConfig
from mrslam_env.slam.grid import OccupancyGrid
from mrslam_env.slam.matcher import MatchResult, match_scan
from mrslam_env.slam.scan import scan_normals

FloatArray = NDArray[np.float64]

__all__ = ["RobotSlam"]


def _relative(
    a: tuple[float, float, float], b: tuple[float, float, float]
) -> tuple[float, float, float]:
    """``inverse(a) ∘ b`` for scalar poses (a fast path for the per-step bookkeeping)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, wrap_scalar(b[2] - a[2]))


def _compose(
    a: tuple[float, float, float], b: tuple[float, float, float]
) -> tuple[float, float, float]:
    """``a ∘ b`` for scalar poses."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_scalar(a[2] + b[2]))


def _as_pose(value: ArrayLike, name: str) -> tuple[float, float, float]:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be a finite (x, y, theta), got {value!r}")
    return (float(array[0]), float(array[1]), float(array[2]))


class RobotSlam:
    """Grid SLAM for one robot, in its own map frame.

    Parameters
    ----------
    config : SlamConfig or None
        Mode, motion filter, grid and matcher settings (None: the defaults).
    n_beams : int
        Beams per scan (beam i at ``-pi + i 2 pi / n_beams`` from the heading).
    max_range : float
        The lidar's maximum range, m; a range at or above it means no return.

    Examples
    --------
    >>> slam = RobotSlam(SlamConfig(), n_beams=360, max_range=8.0)  # doctest: +SKIP
    >>> pose_in_map = slam.update(obs["odom"], obs["scan"])  # doctest: +SKIP
    >>> gridmap = slam.grid.to_gridmap()  # doctest: +SKIP
    """

    def __init__(self, config: SlamConfig | None, n_beams: int, max_range: float) -> None:
        if not isinstance(n_beams, int) or n_beams < 4:
            raise ValueError(f"n_beams must be an int >= 4, got {n_beams!r}")
        if not (math.isfinite(max_range) and max_range > 0):
            raise ValueError(f"max_range must be > 0 m, got {max_range!r}")
        self.config = config if config is not None else SlamConfig()
        self.n_beams = n_beams
        self.max_range = float(max_range)
        matching = self.config.mode in ("slam", "pose_graph")
        lag = self.config.match_lag if matching else 0
        # With a lag, the map is never matched against: it needs no likelihood fields.
        self.grid = OccupancyGrid(self.config.grid, fields=lag == 0)
        self._matched_grid = OccupancyGrid(self.config.grid) if lag > 0 else self.grid
        # (pose, scan, normals) of the scans the matched map has yet to take, oldest first
        self._waiting: deque[tuple[tuple[float, float, float], FloatArray, FloatArray | None]]
        self._waiting = deque()
        self._pose = (0.0, 0.0, 0.0)
        self._reference_pose: tuple[float, float, float] | None = None
        self._reference_odom = (0.0, 0.0, 0.0)
        self._mapped_pose = (0.0, 0.0, 0.0)
        self._trajectory = np.zeros((256, 3))
        self._length = 0
        self.last_match: MatchResult | None = None
        """The most recent match (``None`` before the first one, and in other modes)."""
        self.n_integrated = 0
        """Scans integrated so far."""
        self.n_matched = 0
        """Scans matched so far (accepted or not)."""
        self.n_rejected = 0
        """Matches rejected so far (the pose fell back to odometry)."""
        self._rejected_in_a_row = 0
        self.backend: PoseGraphBackend | None = None
        """The pose graph and its loop closures (``pose_graph`` mode), else None."""
        self._chain: LocalChain | None = None
        if self.config.mode == "pose_graph":
            self.backend = PoseGraphBackend(self.config, self.max_range)
            self._chain = LocalChain(self.config, self.max_range)
        # Per step (pose_graph mode): the newest node then, and the pose relative to it.
        self._step_nodes = np.zeros(256, dtype=np.int64)
        self._step_offsets = np.zeros((256, 3))
        self.n_rerenders = 0
        """Times the maps were redrawn from the optimised graph (``pose_graph`` mode)."""

    # --- state --------------------------------------------------------------------------

    @property
    def pose(self) -> FloatArray:
        """Current pose ``(x, y, theta)`` in the map frame."""
        return np.array(self._pose)

    @property
    def trajectory(self) -> FloatArray:
        """Every pose returned by :meth:`update` so far, (T, 3), map frame."""
        return self._trajectory[: self._length].copy()

    @property
    def optimized_trajectory(self) -> FloatArray:
        """Every step's pose (T, 3) through the current pose graph: the pose relative to
        the newest node at that step, composed with that node's optimised pose (in modes
        other than ``pose_graph``, :attr:`trajectory`)."""
        if self.backend is None:
            return self.trajectory
        nodes = self._step_nodes[: self._length]
        offsets = self._step_offsets[: self._length]
        return compose(self.backend.graph.poses[nodes], offsets)

    @property
    def map_from_odom(self) -> FloatArray:
        """``map_from_odom`` as of the last update: ``pose = map_from_odom ∘ odom_pose``.

        In ``odometry`` mode it stays ``inverse(first odom_pose)`` (the identity when, as in
        the env, odometry starts at zero); in ``slam`` mode it absorbs the corrections."""
        if self._reference_pose is None:
            return np.zeros(3)
        return np.array(
            _compose(self._reference_pose, _relative(self._reference_odom, (0.0, 0.0, 0.0)))
        )

    # --- the update ---------------------------------------------------------------------

    def update(
        self,
        odom_pose: ArrayLike,
        ranges: ArrayLike,
        true_pose_in_map: ArrayLike | None = None,
    ) -> FloatArray:
        """Process one step: odometry and scan in, pose in the map frame out.

        Parameters
        ----------
        odom_pose : array_like, shape (3,)
            Dead-reckoning pose in the robot's odom frame (the env's ``odom`` observation).
        ranges : array_like, shape (n_beams,)
            The scan (the env's ``scan`` observation), m.
        true_pose_in_map : array_like, shape (3,), optional
            The true pose in the map frame; required in ``ground_truth`` mode, ignored
            otherwise.

        Returns
        -------
        ndarray, shape (3,)
            The pose in the map frame.
        """
        odom = _as_pose(odom_pose, "odom_pose")
        scan = np.asarray(ranges, dtype=np.float64)
        if scan.shape != (self.n_beams,):
            raise ValueError(f"ranges must have shape ({self.n_beams},), got {scan.shape}")
        mode = self.config.mode
        truth = None
        if mode == "ground_truth":
            if true_pose_in_map is None:
                raise ValueError("ground_truth mode needs true_pose_in_map")
            truth = _as_pose(true_pose_in_map, "true_pose_in_map")

        if self._reference_pose is None:
            # The map frame is the start pose.
            pose = truth if truth is not None else (0.0, 0.0, 0.0)
            return self._record(self._integrate(pose, odom, scan))

        reference = self._reference_pose
        motion = _relative(self._reference_odom, odom)
        predicted = _compose(reference, motion)
        if truth is not None:
            predicted = truth
        translation = math.hypot(motion[0], motion[1])
        rotation = abs(motion[2])
        if translation < self.config.min_translation and rotation < self.config.min_rotation:
            return self._record(predicted)
        pose = predicted
        normals = scan_normals(scan, self.max_range, self.config.grid.min_range)
        result: MatchResult | None = None
        if mode in ("slam", "pose_graph"):
            result = match_scan(
                self._matched_grid,
                scan,
                self.max_range,
                np.array(predicted),
                translation,
                rotation,
                self.config.matcher,
                normals,
            )
            self.last_match = result
            self.n_matched += 1
            pose = (float(result.pose[0]), float(result.pose[1]), float(result.pose[2]))
            if not result.accepted:
                self.n_rejected += 1
                self._rejected_in_a_row += 1
                self._catch_up(0)
                if self._rejected_in_a_row < self.config.integrate_rejected_after:
                    # A scan placed by odometry alone would smear a wrong copy of the walls
                    # into the map; keep the reference, so the next window is wider.
                    return self._record(pose)
            self._rejected_in_a_row = 0
            moved = _relative(self._mapped_pose, pose)
            if (
                result.accepted
                and math.hypot(moved[0], moved[1]) < self.config.map_update_translation
                and abs(moved[2]) < self.config.map_update_rotation
            ):
                # Matched, but too close to the last integrated scan to be worth its error.
                self._reference_pose = pose
                self._reference_odom = odom
                return self._record(pose)
        return self._record(self._integrate(pose, odom, scan, normals, result))

    def _integrate(
        self,
        pose: tuple[float, float, float],
        odom: tuple[float, float, float],
        scan: FloatArray,
        normals: FloatArray | None = None,
        match: MatchResult | None = None,
    ) -> tuple[float, float, float]:
        """Integrate the scan at ``pose``; returns the pose, moved with the maps if a loop
        closure had them redrawn (``pose_graph`` mode)."""
        self.grid.integrate_scan(pose, scan, self.max_range, normals)
        if self._matched_grid is not self.grid:
            # Copies: the caller may reuse its scan buffer.
            self._waiting.append((pose, scan.copy(), None if normals is None else normals.copy()))
            self._catch_up(0 if self.n_integrated == 0 else self.config.match_lag)
        self._mapped_pose = pose
        self._reference_pose = pose
        self._reference_odom = odom
        self.n_integrated += 1
        if self.backend is not None:
            assert self._chain is not None
            local, local_match = self._chain.add(pose, scan, normals, self.backend.in_snap_window)
            self.backend.add_scan(pose, local, scan, match, local_match)
            if self.backend.needs_rerender():
                self._rerender()
                assert self._reference_pose is not None
                return self._reference_pose
        return pose

    def _rerender(self) -> None:
        """Redraw both maps from every scan at its optimised pose (the matched map without
        the scans still waiting for it); the front end's poses move with the newest node."""
        assert self.backend is not None
        correction = self.backend.correction()
        poses = self.backend.scan_poses()
        scans = self.backend.scans
        held = len(self._waiting)
        reach = self.max_range
        matched = OccupancyGrid(self.config.grid)
        matched.ensure_contains(
            float(poses[:, 0].min() - reach),
            float(poses[:, 1].min() - reach),
            float(poses[:, 0].max() + reach),
            float(poses[:, 1].max() + reach),
        )
        min_range = self.config.grid.min_range
        normals = [normals_of(scan, reach, min_range) for scan in scans]
        for k in range(len(scans) - held):
            matched.integrate_scan(poses[k], scans[k], reach, normals[k])
        if self._matched_grid is self.grid:
            self.grid = self._matched_grid = matched
        else:
            grid = matched.copy(fields=False)
            self._waiting = deque()
            for k in range(len(scans) - held, len(scans)):
                pose = (float(poses[k, 0]), float(poses[k, 1]), float(poses[k, 2]))
                grid.integrate_scan(pose, scans[k], reach, normals[k])
                self._waiting.append((pose, scans[k], normals[k]))
            self.grid, self._matched_grid = grid, matched
        self.grid.forget_written()
        assert self._reference_pose is not None
        self._reference_pose = _compose(correction, self._reference_pose)
        self._mapped_pose = _compose(correction, self._mapped_pose)
        self.n_rerenders += 1

    def _catch_up(self, lag: int) -> None:
        """Integrate into the matched map the waiting scans but the last ``lag``."""
        while len(self._waiting) > lag:
            pose, scan, normals = self._waiting.popleft()
            self._matched_grid.integrate_scan(pose, scan, self.max_range, normals)

    def _record(self, pose: tuple[float, float, float]) -> FloatArray:
        if self.backend is not None:
            if self._length == len(self._step_nodes):
                self._step_nodes = np.concatenate([self._step_nodes, self._step_nodes])
                self._step_offsets = np.concatenate([self._step_offsets, self._step_offsets])
            node = self.backend.last_node
            self._step_nodes[self._length] = node
            self._step_offsets[self._length] = _relative(self.backend.drawn_pose(node), pose)
        self._pose = pose
        if self._length == len(self._trajectory):
            self._trajectory = np.concatenate([self._trajectory, np.zeros_like(self._trajectory)])
        self._trajectory[self._length] = pose
        self._length += 1
        return np.array(pose)
