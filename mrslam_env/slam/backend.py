"""The pose-graph back end of mode ``pose_graph`` (docs/design.md §4).

The front end (:class:`~mrslam_env.slam.slam.RobotSlam`'s scan-to-map matching against
the whole map, as in mode ``slam``) gives the robot's pose. Matched against the whole
map, though, a robot that comes back to a place after a long loop pulls itself onto the
old map over a few metres once it is in range: the loop is closed, but its error sits in
those few metres and in the map drawn before them. Every scan the front end integrates
goes to :class:`PoseGraphBackend`, which keeps

* **Keyframes**: every integrated scan (its ranges), hanging off a graph *node* at its
  pose relative to the node's in the front end's map. A new node starts once the robot
  has moved ``node_translation`` or turned ``node_rotation`` since the last one; its own
  scan is the one that started it. It enters the graph where the front end has it
  (relative to the last node), so that an unoptimised graph is the map as drawn.
* **Odometry edges** between consecutive nodes: the front end's relative pose, with a
  covariance calibrated on replays (``odometry_*_std``), plus, along a direction the
  match could not measure (a corridor) or wholly where it was rejected,
  ``slip_std_per_m`` per metre. In a *snap window* (the first ``snap_window`` metres
  after parts of the map ``snap_path_gap`` old come within ``snap_radius``)
  :class:`LocalChain` measures each edge a second time, against a local map of the
  newest scans only, which has no pull; when a loop at least ``snap_path_gap`` long
  closes, the window's edges take that measurement.
* **Loop edges** from loop-closure searches: every ``loop_search_spacing`` metres driven
  (``loop_closure_spacing`` after an accepted closure), if some node at least
  ``loop_min_path_gap`` back along the path lies within ``loop_candidate_radius`` of the
  new node, the nearest such node (the lowest id among equals) is the candidate. The new
  node's scan is matched (:func:`~mrslam_env.slam.loop_closure.match_loop`) against the
  submap of old nodes around the candidate, drawn at their graph poses, over a window
  that grows with the distance driven since the robot was last tied to older scans. An
  accepted match adds a robust loop edge, and the graph is optimised
  (:meth:`~mrslam_env.slam.posegraph.PoseGraph.optimize`) unless the edge agrees with it
  already (``optimize_min_chi2``) and no edge took the local measurement.

The maps are the front end's: :meth:`PoseGraphBackend.needs_rerender` says whether an
optimisation has moved some node more than ``rerender_translation`` /
``rerender_rotation`` from where its scans are drawn, and
:meth:`PoseGraphBackend.scan_poses` gives every scan's pose in the optimised graph (from
then on the drawn poses) for the caller to redraw them.
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict, deque
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from mrslam_env.geometry import compose, inverse, wrap_scalar
from mrslam_env.slam.config import SlamConfig
from mrslam_env.slam.grid import OccupancyGrid
from mrslam_env.slam.loop_closure import LoopMatch, match_loop
from mrslam_env.slam.matcher import MatchResult, match_scan, translational_condition
from mrslam_env.slam.posegraph import OptimizationResult, PoseGraph, RobustKernel
from mrslam_env.slam.scan import (
    NORMAL_HALF_WIDTH,
    NORMAL_MAX_GAP,
    NORMAL_MAX_HALF_WIDTH,
    NORMAL_MIN_SPAN,
    scan_normals,
)

FloatArray = NDArray[np.float64]
Pose = tuple[float, float, float]

__all__ = ["Closure", "LocalChain", "PoseGraphBackend", "normals_of"]

_SUBMAP_CACHE = 3
"""Submaps kept for the next searches (a robot driving along an old stretch of path
matches against the same submap several times)."""
LOCAL_LAG = 4
"""Scans the local map takes last are left out of it for this many more of its scans
(about 1 m), as the front end's matched map lags (``SlamConfig.match_lag``)."""
_SUBMAP_TOLERANCE = 1e-3
"""A kept submap is drawn anew once one of its nodes moved more than this, m or rad."""


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class Closure:
    """One loop-closure search that got as far as a match.

    Attributes
    ----------
    node : int
        The new node whose scan was matched.
    candidate : int
        The old node the submap was built around (the loop edge's other end if accepted).
    candidate_pose : ndarray, shape (3,)
        Its graph pose at the time (the loop edge's measurement is ``inverse(candidate_pose)
        ∘ match.pose``).
    match : LoopMatch
        The match and its verdict (:attr:`LoopMatch.pose` in the map frame).
    chi2 : float
        The loop edge's squared Mahalanobis error in the graph as it was (NaN if not
        accepted): at most ``optimize_min_chi2``, the graph agreed and was not optimised.
    edge : int or None
        The loop edge's index in the graph, if accepted.
    optimization : OptimizationResult or None
        The optimisation the edge triggered (None if none).
    seconds : float
        Time of the search (submap and match), s.
    optimize_seconds : float
        Time of the optimisation, s (0 if none).
    """

    node: int
    candidate: int
    candidate_pose: FloatArray
    match: LoopMatch
    chi2: float
    edge: int | None
    optimization: OptimizationResult | None
    seconds: float
    optimize_seconds: float


def _relative(a: Pose, b: Pose) -> Pose:
    """``inverse(a) ∘ b`` for scalar poses."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, wrap_scalar(b[2] - a[2]))


def _compose(a: Pose, b: Pose) -> Pose:
    """``a ∘ b`` for scalar poses."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_scalar(a[2] + b[2]))


def normals_of(scan: FloatArray, max_range: float, min_range: float) -> FloatArray:
    """:func:`~mrslam_env.slam.scan.scan_normals` with every argument given: numba's
    dispatcher takes its slow path for omitted arguments (a tenth of a millisecond a call,
    which redrawing thousands of scans adds up)."""
    return scan_normals(
        scan,
        max_range,
        min_range,
        NORMAL_HALF_WIDTH,
        NORMAL_MAX_GAP,
        NORMAL_MIN_SPAN,
        NORMAL_MAX_HALF_WIDTH,
    )


def _inverse(a: Pose) -> Pose:
    """``inverse(a)`` for scalar poses."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-(c * a[0] + s * a[1]), s * a[0] - c * a[1], wrap_scalar(-a[2]))


def _in_frame(covariance: FloatArray, heading: float) -> FloatArray:
    """A covariance (3, 3) of ``(x, y, theta)`` in the map frame, expressed in the frame
    turned by ``heading`` (the frame of a pose graph edge's error)."""
    c, s = math.cos(heading), math.sin(heading)
    rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(rotation @ covariance @ rotation.T, dtype=np.float64)


class PoseGraphBackend:
    """Keyframes, pose graph and loop closures for one robot (module docstring).

    Parameters
    ----------
    config : SlamConfig
        Its ``pose_graph``, ``grid`` (the submaps) and ``matcher`` (the closure lattice).
    max_range : float
        The lidar's maximum range, m.
    """

    def __init__(self, config: SlamConfig, max_range: float) -> None:
        self.config = config.pose_graph
        self.grid_config = config.grid
        self.matcher = config.matcher
        self.max_range = float(max_range)
        self.graph = PoseGraph()
        """The pose graph: node ``k`` is the k-th node (ids 0, 1, 2, ...)."""
        self.scans: list[FloatArray] = []
        """Every scan integrated so far (ranges, copies)."""
        self._scan_node: list[int] = []
        self._scan_offset: list[Pose] = []
        self._node_scan: list[int] = []
        self._node_path: list[float] = []
        self._local = np.zeros((64, 3))
        self._drawn = np.zeros((64, 3))
        self._last_local: Pose = (0.0, 0.0, 0.0)
        self._path = 0.0
        self._slip = np.zeros((3, 3))
        self._local_slip = np.zeros((3, 3))
        # Per node but the first: its odometry edge's index, the local chain's measurement
        # of that edge (relative pose, information), whether old parts of the map were in
        # range there, and whether the edge has the local measurement now.
        self._odometry_edges: list[int] = []
        self._local_edges: list[tuple[Pose, FloatArray]] = []
        self._near: list[bool] = []
        self._unsnapped: list[bool] = []
        self._window_oldest = math.inf
        self._snap_until = -math.inf
        self._optimized = False  # since the last needs_rerender
        self.n_local_edges = 0
        """Odometry edges that took the local chain's measurement (:meth:`_unsnap`)."""
        self._next_search = 0.0
        self._tied_path = 0.0
        self.closures: list[Closure] = []
        """Every search that got as far as a match, accepted or not, in order."""
        self.n_searches = 0
        """Searches with a candidate (a scan matched against a submap)."""
        self._submaps: OrderedDict[
            tuple[int, int], tuple[OccupancyGrid, FloatArray, FloatArray]
        ] = OrderedDict()

    # --- state --------------------------------------------------------------------------

    @property
    def n_nodes(self) -> int:
        return len(self._node_scan)

    @property
    def last_node(self) -> int:
        """The newest node's id (-1 before the first scan)."""
        return len(self._node_scan) - 1

    @property
    def path_length(self) -> float:
        """Distance driven from scan to scan (front-end poses), m."""
        return self._path

    @property
    def in_snap_window(self) -> bool:
        """Whether the newest node lies in a snap window (:meth:`_near_old`): the local
        chain's measurement of the edges there may be needed."""
        return bool(self._near) and self._near[-1]

    @property
    def n_closures(self) -> int:
        """Loop edges added."""
        return sum(closure.edge is not None for closure in self.closures)

    def drawn_pose(self, node: int) -> Pose:
        """Where node ``node``'s scans are drawn in the front end's maps."""
        x, y, theta = self._drawn[node]
        return (float(x), float(y), float(theta))

    def correction(self) -> Pose:
        """``graph ∘ inverse(drawn)`` of the newest node: how a redraw moves the front
        end's frame near the robot."""
        node = self.last_node
        x, y, theta = self.graph.pose(node)
        return _compose((float(x), float(y), float(theta)), _inverse(self.drawn_pose(node)))

    def scan_poses(self) -> FloatArray:
        """Every scan's pose (S, 3) in the optimised graph; the nodes count as drawn there
        from now on (:meth:`needs_rerender`)."""
        n = self.n_nodes
        self._drawn[:n] = self.graph.poses
        nodes = np.array(self._scan_node, dtype=np.int64)
        offsets = np.array(self._scan_offset, dtype=np.float64).reshape(-1, 3)
        return compose(self._drawn[nodes], offsets)

    def needs_rerender(self) -> bool:
        """Whether the graph was optimised since the last call and some node has moved
        more than the redraw tolerance from where its scans are drawn."""
        n = self.n_nodes
        if n == 0 or not self._optimized:
            return False
        self._optimized = False
        change = self.graph.poses - self._drawn[:n]
        moved = np.hypot(change[:, 0], change[:, 1]).max()
        turned = np.abs(np.remainder(change[:, 2] + np.pi, 2.0 * np.pi) - np.pi).max()
        return bool(
            moved > self.config.rerender_translation or turned > self.config.rerender_rotation
        )

    # --- the update ---------------------------------------------------------------------

    def add_scan(
        self,
        drawn: Pose,
        local: Pose,
        scan: FloatArray,
        match: MatchResult | None = None,
        local_match: MatchResult | None = None,
    ) -> bool:
        """Take one integrated scan: its pose in the front end's map (``drawn``) and in the
        local chain (``local``), with the front end's and the local chain's matches of it
        (None: not matched); returns whether a loop closure was accepted."""
        self.scans.append(np.array(scan, dtype=np.float64))
        if not self._node_scan:
            self._add_node(drawn, local, drawn, fixed=True)
            self._last_local = local
            return False
        step = math.hypot(local[0] - self._last_local[0], local[1] - self._last_local[1])
        self._path += step
        self._last_local = local
        if match is not None:
            self._slip += self._slip_of(match, step)
        if local_match is not None:
            self._local_slip += self._slip_of(local_match, step)
        node = self.last_node
        relative = _relative(self.drawn_pose(node), drawn)
        config = self.config
        if (
            math.hypot(relative[0], relative[1]) < config.node_translation
            and abs(relative[2]) < config.node_rotation
        ):
            # The scan hangs off the node where the front end drew it.
            self._scan_node.append(node)
            self._scan_offset.append(relative)
            return False
        # The new node enters the graph where the front end has it (relative to the last
        # node), so that an unoptimised graph stays where the map is drawn.
        start = self.graph.pose(node)
        guess = _compose((float(start[0]), float(start[1]), float(start[2])), relative)
        new = self._add_node(drawn, local, guess)
        # The edge: the front end's motion. The local chain's is kept for the case a long
        # loop closes here (:meth:`_unsnap`).
        information = self._odometry_information(relative, self._slip, drawn[2])
        self._odometry_edges.append(self.graph.add_edge(node, new, relative, information))
        local_relative = _relative(self.local_pose(node), local)
        local_information = self._odometry_information(local_relative, self._local_slip, local[2])
        self._local_edges.append((local_relative, local_information))
        self._near.append(self._near_old(guess))
        self._slip = np.zeros((3, 3))
        self._local_slip = np.zeros((3, 3))
        return self._path >= self._next_search and self._search(new)

    def local_pose(self, node: int) -> Pose:
        """Node ``node``'s pose in the local chain's frame."""
        x, y, theta = self._local[node]
        return (float(x), float(y), float(theta))

    def _add_node(self, drawn: Pose, local: Pose, guess: Pose, *, fixed: bool = False) -> int:
        node = self.n_nodes
        self.graph.add_node(node, guess, fixed=fixed)
        if node == len(self._local):
            self._local = np.concatenate([self._local, np.zeros_like(self._local)])
            self._drawn = np.concatenate([self._drawn, np.zeros_like(self._drawn)])
        self._local[node] = local
        self._drawn[node] = drawn
        self._node_scan.append(len(self.scans) - 1)
        self._node_path.append(self._path)
        if node > 0:
            self._unsnapped.append(False)
        self._scan_node.append(node)
        self._scan_offset.append((0.0, 0.0, 0.0))
        return node

    def _slip_of(self, match: MatchResult, step: float) -> FloatArray:
        """Map-frame covariance the front end's pose took on from odometry at this scan:
        along the direction it could not measure (``"degenerate"``), or its odometry
        prior if the match was rejected."""
        if not match.accepted:
            return np.asarray(np.linalg.inv(match.prior_information), dtype=np.float64)
        if match.reason != "degenerate":
            return np.zeros((3, 3))
        _, weak = translational_condition(match.information)
        variance = (self.config.slip_std_per_m * step) ** 2
        slip = np.zeros((3, 3))
        slip[:2, :2] = variance * np.outer(weak, weak)
        return slip

    def _unsnap(self, node: int) -> int:
        """A loop at least ``snap_path_gap`` long closed at ``node``: on the way here, old
        parts of the map came into range and the front end may have pulled its scans onto
        them, taking the loop's error into a few edges. The edges back from ``node`` in
        the snap window (:meth:`_near_old`) take the local chain's measurement instead;
        returns how many changed."""
        changed = 0
        k = node
        while k > 0 and self._near[k - 1]:
            if not self._unsnapped[k - 1]:
                self.graph.replace_edge(self._odometry_edges[k - 1], *self._local_edges[k - 1])
                self._unsnapped[k - 1] = True
                changed += 1
            k -= 1
        self.n_local_edges += changed
        return changed

    def _near_old(self, pose: Pose) -> bool:
        """Whether the node at ``pose`` (its graph pose) lies in a *snap window*: the
        first ``snap_window`` metres after old parts of the map (nodes at least
        ``snap_path_gap`` back along the path) came within ``snap_radius``, or after parts
        another ``snap_path_gap`` older than those did."""
        config = self.config
        paths = np.array(self._node_path)
        old = np.flatnonzero(paths <= self._path - config.snap_path_gap)
        oldest = math.inf
        if len(old) > 0:
            poses = self.graph.poses[old]
            distance = np.hypot(poses[:, 0] - pose[0], poses[:, 1] - pose[1])
            near = distance <= config.snap_radius
            if near.any():
                oldest = float(paths[old[near]].min())
        if oldest == math.inf:
            self._window_oldest = math.inf
            return False
        if oldest <= self._window_oldest - config.snap_path_gap:
            self._window_oldest = oldest
            self._snap_until = self._path + config.snap_window
        return self._path <= self._snap_until

    def _odometry_information(self, relative: Pose, slip: FloatArray, heading: float) -> FloatArray:
        config = self.config
        distance = math.hypot(relative[0], relative[1])
        xy = config.odometry_xy_std + config.odometry_xy_std_per_m * distance
        angle = config.odometry_angle_std + config.odometry_angle_std_per_m * distance
        covariance = np.diag([xy * xy, xy * xy, angle * angle])
        covariance += _in_frame(slip, heading)
        return np.asarray(np.linalg.inv(covariance), dtype=np.float64)

    # --- loop closure -------------------------------------------------------------------

    def _submap(
        self, candidate: int, old: NDArray[np.bool_], poses: FloatArray
    ) -> tuple[OccupancyGrid, FloatArray]:
        """The submap around ``candidate`` and its frame's shift from the map frame.

        Submap ``s`` holds the scans of the old nodes among ``[s h, (s + 2) h)``, ``h``
        the nodes in ``submap_half_path`` (so consecutive submaps overlap by half); the one
        whose middle is nearest the candidate is used. Its frame is the map frame shifted
        by whole cells to its middle node, so its cells are the map's cells and the grid
        stays small. The last few are kept until their nodes move."""
        half = max(1, round(self.config.submap_half_path / self.config.node_translation))
        first = max(0, round(candidate / half) - 1) * half
        members = np.arange(first, min(first + 2 * half, len(old)))
        members = members[old[members]]
        key = (first, len(members))
        cached = self._submaps.pop(key, None)
        if cached is not None:
            grid, shift, drawn = cached
            moved = np.abs(poses[members] - drawn)
            if float(moved.max(initial=0.0)) <= _SUBMAP_TOLERANCE:
                self._submaps[key] = cached  # the most recently used goes last
                return grid, shift
        resolution = self.grid_config.resolution
        middle = poses[members[len(members) // 2]]
        shift = np.array(
            [
                round(middle[0] / resolution) * resolution,
                round(middle[1] / resolution) * resolution,
                0.0,
            ]
        )
        grid = OccupancyGrid(self.grid_config)
        member_poses = poses[members] - shift
        reach = self.max_range
        grid.ensure_contains(
            float(member_poses[:, 0].min() - reach),
            float(member_poses[:, 1].min() - reach),
            float(member_poses[:, 0].max() + reach),
            float(member_poses[:, 1].max() + reach),
        )
        min_range = self.grid_config.min_range
        for member, member_pose in zip(members, member_poses, strict=True):
            scan = self.scans[self._node_scan[member]]
            grid.integrate_scan(member_pose, scan, reach, normals_of(scan, reach, min_range))
        self._submaps[key] = (grid, shift, poses[members].copy())
        while len(self._submaps) > _SUBMAP_CACHE:
            self._submaps.popitem(last=False)
        return grid, shift

    def _search(self, node: int) -> bool:
        config = self.config
        poses = self.graph.poses
        here = poses[node]
        paths = np.array(self._node_path)
        old = paths <= self._path - config.loop_min_path_gap
        distance = np.hypot(poses[:, 0] - here[0], poses[:, 1] - here[1])
        near = old & (distance <= config.loop_candidate_radius)
        if not near.any():
            return False
        started = time.perf_counter()
        self.n_searches += 1
        self._next_search = self._path + config.loop_search_spacing
        # The nearest old node (argmin: the lowest id among equals) and the submap that has
        # it nearest its middle.
        candidate = int(np.argmin(np.where(near, distance, np.inf)))
        submap, shift = self._submap(candidate, old, poses)
        drift = min(self._path - paths[candidate], self._path - self._tied_path)
        xy_window = min(
            config.loop_window_xy + config.loop_window_per_m * drift, config.loop_window_xy_max
        )
        angle_window = min(
            config.loop_window_angle + config.loop_window_angle_per_m * drift,
            config.loop_window_angle_max,
        )
        result = match_loop(
            submap,
            self.scans[self._node_scan[node]],
            self.max_range,
            here - shift,
            xy_window,
            angle_window,
            config,
            self.matcher,
        )
        matched = result.pose + shift
        matched[2] = wrap_scalar(float(matched[2]))
        result = replace(result, pose=matched)
        searched = time.perf_counter() - started
        edge = None
        optimization = None
        optimize_seconds = 0.0
        chi2 = math.nan
        if result.accepted:
            measurement = compose(inverse(poses[candidate]), matched)
            match_covariance = np.asarray(
                np.linalg.inv(result.information + 1e-9 * np.eye(3)), dtype=np.float64
            )
            covariance = _in_frame(match_covariance, float(matched[2]))
            covariance += np.diag(
                [config.loop_xy_std**2, config.loop_xy_std**2, config.loop_angle_std**2]
            )
            information = np.linalg.inv(covariance)
            edge = self.graph.add_edge(candidate, node, measurement, information, "loop")
            unsnapped = 0
            if self._path - paths[candidate] >= config.snap_path_gap:
                unsnapped = self._unsnap(node)
            error = self.graph.errors()[edge]
            chi2 = float(error @ information @ error)
            if chi2 > config.optimize_min_chi2 or unsnapped > 0:
                started = time.perf_counter()
                kernel: RobustKernel = config.robust  # type: ignore[assignment]
                optimization = self.graph.optimize(
                    robust=kernel,
                    robust_width=config.robust_width,
                    max_iterations=config.max_iterations,
                    tolerance=config.tolerance,
                )
                optimize_seconds = time.perf_counter() - started
                self._optimized = True
            self._tied_path = self._path
            self._next_search = self._path + config.loop_closure_spacing
        self.closures.append(
            Closure(
                node=node,
                candidate=candidate,
                candidate_pose=poses[candidate].copy(),
                match=result,
                chi2=chi2,
                edge=edge,
                optimization=optimization,
                seconds=searched,
                optimize_seconds=optimize_seconds,
            )
        )
        return edge is not None


class LocalChain:
    """The graph's odometry where the front end may pull itself onto an old map: scans
    matched against a local map of the newest scans only (module docstring).

    Each scan is predicted from the last one by the front end's own motion between them
    and, while asked to (in a snap window: old parts of the map came into range), matched
    in a small window (``local_window_*``) against the local map: where the front end
    pulled the scan onto an old part of its map, the local match takes the pull out again.
    Otherwise the prediction is the pose (the chain follows the front end) and there is no
    local map. The chain keeps a scan every ``node_translation`` / ``node_rotation``, the
    ``local_map_scans`` newest of them; the local map is drawn from those when a window
    opens and then holds between half and all of that many newest scans, but the last
    :data:`LOCAL_LAG` (as the front end's matched map lags): once it holds half a window a
    next one starts, and once that one holds half a window it takes over. The chain's
    frame drifts freely: only relative poses leave it.
    """

    def __init__(self, config: SlamConfig, max_range: float) -> None:
        graph = config.pose_graph
        xy, angle = graph.local_window_xy, graph.local_window_angle
        self.matcher = replace(
            config.matcher,
            xy_window_base=xy,
            xy_window_per_m=0.0,
            xy_window_per_rad=0.0,
            xy_window_max=xy,
            angle_window_base=angle,
            angle_window_per_m=0.0,
            angle_window_per_rad=0.0,
            angle_window_max=angle,
            prior_xy_std_base=xy,
            prior_xy_std_per_m=0.0,
            prior_angle_std_base=angle,
            prior_angle_std_per_rad=0.0,
        )
        self.grid_config = config.grid
        self.spacing = (graph.node_translation, graph.node_rotation)
        self.half = max(1, graph.local_map_scans // 2)
        self.max_range = float(max_range)
        # The kept scans, newest last: (local pose, ranges, normals); the first len - lag
        # of them are in the local map while there is one.
        self._kept: deque[tuple[Pose, FloatArray, FloatArray | None]] = deque(maxlen=2 * self.half)
        self.map: OccupancyGrid | None = None
        self._next: OccupancyGrid | None = None
        self._counts = [0, 0]
        self._pose: Pose | None = None
        self._drawn: Pose = (0.0, 0.0, 0.0)

    def add(
        self, drawn: Pose, scan: FloatArray, normals: FloatArray | None, active: bool
    ) -> tuple[Pose, MatchResult | None]:
        """The local pose of a scan the front end integrated at ``drawn``, and the local
        match (None if not matched: the first scan, or not ``active``)."""
        result = None
        if self._pose is None:
            pose = drawn
        else:
            motion = _relative(self._drawn, drawn)
            pose = _compose(self._pose, motion)
            if not active:
                self.map = self._next = None
            else:
                if self.map is None:
                    self._draw()
                assert self.map is not None
                result = match_scan(
                    self.map,
                    scan,
                    self.max_range,
                    np.array(pose),
                    math.hypot(motion[0], motion[1]),
                    abs(motion[2]),
                    self.matcher,
                    normals,
                )
                pose = (float(result.pose[0]), float(result.pose[1]), float(result.pose[2]))
        self._pose, self._drawn = pose, drawn
        if self._kept:
            moved = _relative(self._kept[-1][0], pose)
            if math.hypot(moved[0], moved[1]) < self.spacing[0] and abs(moved[2]) < self.spacing[1]:
                return pose, result
        self._kept.append((pose, np.array(scan, dtype=np.float64), normals))
        if self.map is not None and len(self._kept) > LOCAL_LAG:
            self._integrate(*self._kept[-1 - LOCAL_LAG])
        return pose, result

    def _draw(self) -> None:
        """A local map of the kept scans but the last :data:`LOCAL_LAG`."""
        pose = self._kept[-1][0]
        self.map = self._grid_around(pose)
        self._next = None
        self._counts = [0, 0]
        for kept in list(self._kept)[: max(0, len(self._kept) - LOCAL_LAG)]:
            self._integrate(*kept)

    def _grid_around(self, pose: Pose) -> OccupancyGrid:
        grid = OccupancyGrid(self.grid_config, around=(pose[0], pose[1]))
        reach = self.max_range
        grid.ensure_contains(pose[0] - reach, pose[1] - reach, pose[0] + reach, pose[1] + reach)
        return grid

    def _integrate(self, pose: Pose, scan: FloatArray, normals: FloatArray | None) -> None:
        assert self.map is not None
        if normals is None:
            normals = normals_of(scan, self.max_range, self.grid_config.min_range)
        if self._next is not None and self._counts[1] >= self.half:
            self.map, self._next = self._next, None
            self._counts = [self._counts[1], 0]
        if self._next is None and self._counts[0] >= self.half:
            self._next = self._grid_around(pose)
        self.map.integrate_scan(pose, scan, self.max_range, normals)
        self._counts[0] += 1
        if self._next is not None:
            self._next.integrate_scan(pose, scan, self.max_range, normals)
            self._counts[1] += 1
