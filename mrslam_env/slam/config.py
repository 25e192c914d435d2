"""Configuration of the onboard SLAM: frozen dataclasses, unit and meaning per field.

Four parts, as in :mod:`mrslam_env.config`: :class:`GridConfig` (the occupancy grid and
its log-odds update), :class:`MatcherConfig` (scan-to-map matching), :class:`PoseGraphConfig`
(the pose graph and its loop closures, mode ``pose_graph``) and :class:`SlamConfig` (mode,
motion filter, and the three above). Change a value with :func:`dataclasses.replace`, e.g.
``replace(SlamConfig(), mode="odometry")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, get_args

from mrslam_env.validation import check_fields, require

__all__ = [
    "SLAM_MODES",
    "GridConfig",
    "MatcherConfig",
    "PoseGraphConfig",
    "SlamConfig",
    "SlamMode",
]

SlamMode = Literal["slam", "pose_graph", "odometry", "ground_truth"]
SLAM_MODES: tuple[str, ...] = get_args(SlamMode)


@dataclass(frozen=True, slots=True, kw_only=True)
class GridConfig:
    """The growing log-odds occupancy grid and how a scan updates it.

    The grid also keeps the matcher's two likelihood fields (Gaussian blurs of the
    occupied cells) current, so their widths live here.
    """

    resolution: float = 0.05
    """Cell edge length, m."""
    log_odds_hit: float = 0.85
    """Log-odds added to the cell a beam ends in (> 0)."""
    log_odds_miss: float = -0.4
    """Log-odds added to every cell a beam passes before its end (< 0)."""
    log_odds_miss_held: float | None = -0.1
    """Log-odds the map (not the likelihood fields' surface layer) adds to a cell that a
    returning beam passes near its end (``held_reach``) when some beam has ended in that
    cell since it was last clamped at ``log_odds_min`` (< 0, at most as strong as
    ``log_odds_miss``; None: the same as ``log_odds_miss``). A wall seen along its length
    at a grazing angle is hit now and then in the cells of its face and passed several
    times as often by the beams that end further along it; with the full miss those
    passes erase the face (FREE where the wall is). With -0.1 against +0.85 a cell stays
    OCCUPIED while its hits are more than about a tenth of the beams through it: the
    ratio model of Karto (slam_toolbox; occupancy threshold 0.1) and, less lenient, of
    gmapping (``occ_thresh`` 0.25)."""
    log_odds_min: float = -2.0
    """Lower clamp of a cell's log-odds (< 0): bounds how long a free cell takes to turn."""
    log_odds_max: float = 3.5
    """Upper clamp of a cell's log-odds (> 0)."""
    occupied_threshold: float = 0.5
    """A cell is OCCUPIED when its log-odds exceed this (>= 0); such cells feed the
    likelihood fields."""
    free_threshold: float = -0.3
    """A cell is FREE when its log-odds are below this (<= 0); in between, UNKNOWN. Above
    ``log_odds_miss``, so that one beam through a cell shows it free, as in gmapping."""
    no_return_clear_distance: float = 3.0
    """How far a beam with no return (range == max range) clears free space, m; 0 turns
    it off. Clearing stops at the first cell already OCCUPIED (a dropout in front of a
    known wall must not erase it)."""
    min_range: float = 0.05
    """Returns shorter than this are ignored, m."""
    surface_margin: float = 0.1
    """The likelihood fields' surface layer ignores a returning beam's misses within this
    distance of the surface it ends on, m (0: off); the map itself takes them. Range noise
    splits the hits on a wall that lies near a cell edge between two rows of cells, and the
    beams clear the front row; without its kernel, the back row's mean hit point (the
    noise's far half) would sit millimetres behind the surface, and the scan matcher would
    drift (see :mod:`mrslam_env.slam.grid`)."""
    held_reach: float = 1.0
    """How far back along a returning beam from its end ``log_odds_miss_held`` applies, m:
    the cells within ``surface_margin`` of the surface the beam ends on (across it, from
    the return's normal; a return without one is a grazing one and gets the whole reach).
    Further back, and on beams with no return, a cell that holds hits takes the full
    ``log_odds_miss``, so that the hits of a passing robot seen from afar (which the peer
    sensor does not mask) do not linger in open space. 1 m covers a wall grazed at 3° a
    cell in front of it."""
    growth_chunk: int = 64
    """The grid grows by whole multiples of this many cells per side."""
    fine_sigma: float = 0.1
    """Standard deviation of the fine likelihood field's Gaussian blur, m. Two cells: the
    ridge of a wall then averages its position over more cells than one, and the heading
    random-walks several times less under 1 cm range noise than with one cell (0.05 m)."""
    coarse_sigma: float = 0.12
    """Standard deviation of the coarse likelihood field's Gaussian blur, m."""

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_fields(
            self,
            positive=(
                "resolution",
                "log_odds_hit",
                "log_odds_max",
                "fine_sigma",
                "coarse_sigma",
            ),
            non_negative=(
                "occupied_threshold",
                "no_return_clear_distance",
                "min_range",
                "surface_margin",
                "held_reach",
            ),
        )
        for attr in ("log_odds_miss", "log_odds_min"):
            value = getattr(self, attr)
            require(name, attr, value, math.isfinite(value) and value < 0, "a finite number < 0")
        if self.log_odds_miss_held is not None:
            value = self.log_odds_miss_held
            require(
                name,
                "log_odds_miss_held",
                value,
                math.isfinite(value) and self.log_odds_miss <= value < 0,
                f"a finite number in [log_odds_miss ({self.log_odds_miss}), 0) or None",
            )
        value = self.free_threshold
        require(name, "free_threshold", value, math.isfinite(value) and value <= 0, "<= 0")
        require(
            name,
            "occupied_threshold",
            self.occupied_threshold,
            self.occupied_threshold < self.log_odds_max,
            f"< log_odds_max ({self.log_odds_max})",
        )
        require(
            name,
            "free_threshold",
            self.free_threshold,
            self.free_threshold > self.log_odds_min,
            f"> log_odds_min ({self.log_odds_min})",
        )
        check_fields(self, counts=("growth_chunk",))
        require(
            name,
            "growth_chunk",
            self.growth_chunk,
            self.growth_chunk % 2 == 0,
            "even",
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class MatcherConfig:
    """Scan-to-map matching: correlative search, Gauss–Newton refinement, acceptance.

    The search window grows with the odometry motion since the last matched scan:
    ``angle_window = angle_window_base + angle_window_per_rad * |dtheta| +
    angle_window_per_m * distance`` (capped at ``angle_window_max``), likewise for x, y.
    The defaults cover the simulator's four-alpha odometry noise: turning on the spot its
    heading error can approach the whole turn. The same motion sets the odometry prior's
    standard deviations (``prior_*``).
    """

    coarse_angle_step: float = math.radians(1.0)
    """Heading step of the coarse search, rad."""
    fine_angle_step: float = math.radians(0.25)
    """Heading step of the fine search, rad."""
    coarse_xy_step: float = 0.10
    """Translation step of the coarse search, m (rounded to whole cells)."""
    angle_window_base: float = 0.1
    """Half-width of the heading window with no motion, rad."""
    angle_window_per_rad: float = 1.2
    """Heading window growth per radian turned, rad/rad."""
    angle_window_per_m: float = 0.5
    """Heading window growth per metre driven, rad/m."""
    angle_window_max: float = 0.45
    """Cap on the heading half-window, rad."""
    xy_window_base: float = 0.05
    """Half-width of the x and y windows with no motion, m."""
    xy_window_per_m: float = 0.4
    """x, y window growth per metre driven, m/m."""
    xy_window_per_rad: float = 0.1
    """x, y window growth per radian turned, m/rad."""
    xy_window_max: float = 0.4
    """Cap on the x, y half-window, m."""
    fine_search_cells: int = 1
    """Half-width of the fine search in cells around the coarse winner (0: no fine search,
    the refinement starts from the coarse winner)."""
    coarse_point_stride: int = 2
    """The coarse search uses every this-many-th scan point."""
    refine_iterations: int = 8
    """Maximum Gauss–Newton iterations."""
    residual_std: float = 0.02
    """Standard deviation of a scan point's distance to the mapped wall, m (range noise
    plus map error); weighs the match against the odometry prior in the refinement."""
    prior_xy_std_base: float = 0.02
    """Odometry prior std on x, y with no motion, m."""
    prior_xy_std_per_m: float = 0.2
    """Odometry prior std growth per metre driven, m/m."""
    prior_angle_std_base: float = 0.02
    """Odometry prior std on heading with no motion, rad."""
    prior_angle_std_per_rad: float = 0.3
    """Odometry prior std growth per radian turned, rad/rad."""
    prior_weight: float = 0.002
    """Weight of the odometry prior in the correlative search score (per point and per
    unit squared Mahalanobis distance): breaks ties towards the prediction."""
    min_points: int = 40
    """Fewer scan returns than this: fall back to odometry."""
    min_score: float = 0.35
    """Mean likelihood (0..1) of the matched scan below this: fall back to odometry."""
    degenerate_ratio: float = 0.02
    """When the smallest / largest eigenvalue of the translational information is below
    this, the scan does not constrain that direction: the correction along it is
    dropped (odometry is kept there)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=(
                "coarse_angle_step",
                "fine_angle_step",
                "coarse_xy_step",
                "angle_window_max",
                "xy_window_max",
                "residual_std",
                "prior_xy_std_base",
                "prior_angle_std_base",
            ),
            non_negative=(
                "angle_window_base",
                "angle_window_per_rad",
                "angle_window_per_m",
                "xy_window_base",
                "xy_window_per_m",
                "xy_window_per_rad",
                "prior_xy_std_per_m",
                "prior_angle_std_per_rad",
                "prior_weight",
                "min_score",
                "fine_search_cells",
                "degenerate_ratio",
            ),
            counts=(
                "coarse_point_stride",
                "refine_iterations",
                "min_points",
            ),
        )
        name = type(self).__name__
        require(
            name,
            "fine_angle_step",
            self.fine_angle_step,
            self.fine_angle_step <= self.coarse_angle_step,
            f"<= coarse_angle_step ({self.coarse_angle_step})",
        )
        require(name, "min_score", self.min_score, self.min_score <= 1.0, "<= 1")
        require(
            name, "degenerate_ratio", self.degenerate_ratio, self.degenerate_ratio <= 1.0, "<= 1"
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseGraphConfig:
    """The pose graph of mode ``pose_graph`` (:mod:`mrslam_env.slam.backend`): its nodes,
    the noise of its edges, the loop-closure search and its acceptance, the optimiser and
    when the map is redrawn.

    The values were chosen on replays of the odometry and scans of recorded team runs
    (``mrslam run``, 2 robots, 3,000 steps, seeds 0-2) of ``procedural_large-0..2``, and
    checked on ``office``, ``warehouse`` and ``maze`` runs and on ``mrslam bench slam``-like
    wander runs (docs/decisions.md, "Pose graph").
    """

    node_translation: float = 0.25
    """A new graph node once the robot has moved this far since the last node, m ...; the
    scans integrated in between hang off the last node at the relative pose the front end
    gave them (they move with it). About 950 nodes per 3,000 steps: an optimisation takes
    10-40 ms; with every integrated scan a node (~3,000 nodes) about 4 times as long
    (sparse LU of 9,000 unknowns, ~11 ms per Gauss–Newton step)."""
    node_rotation: float = math.radians(10.0)
    """... or turned this much, rad."""
    local_map_scans: int = 50
    """The local chain (:class:`~mrslam_env.slam.backend.LocalChain`) matches against a
    local map of at most this many of the newest scans taken a node's spacing apart (at
    least half as many): 50 is about 12 m of path, longer than a snap window."""
    snap_path_gap: float = 30.0
    """A loop at least this long (m of path) may have been closed by the front end before
    the closure search found it: matching against the whole map, a robot coming back to
    an old part of it pulls its scans onto it over a few metres once it is in range, so
    that the loop's error sits in the odometry edges of those metres. When such a loop
    closes, those edges (``snap_window``) take the local chain's measurement, which has
    no such pull. Shorter loops drift too little to matter (replays: 1-3 cm per 30 m) and
    keep the front end's, which is anchored on the whole map, not just the newest scans
    (the local chain's relative poses drift more over tens of metres)."""
    snap_radius: float = 6.0
    """Old parts of the map count as in range within this distance of a node, m (the
    lidar reaches 8 m, but through walls it sees nothing; on the replays the front end's
    pull began 5-6 m from the old path)."""
    snap_window: float = 10.0
    """How far back from such a closure, m of path, edges may take the local chain's
    measurement (while old parts of the map were within the lidar's range): the replays'
    front end took 5-8 m to pull itself onto an old map."""
    local_window_xy: float = 0.05
    """Half-width of the local match's x and y windows around the front end's motion, m
    (also its prior's standard deviation): a pull moves the front end's scans by
    millimetres each, a few centimetres in all (replays: 4-13 cm over 5-8 m)."""
    local_window_angle: float = math.radians(1.0)
    """Half-width of the local match's heading window, rad (and its prior's)."""
    odometry_xy_std: float = 0.001
    """Standard deviation of the relative position of two consecutive nodes, m, plus
    ``odometry_xy_std_per_m`` per metre between them (1.5 mm for nodes 0.25 m apart).
    Chosen for long loops, where the graph's job is: on the replays, the relative
    position of nodes 20 m and 80 m apart was off by 7-9 and 20-23 mm (robust standard
    deviation per axis), about sqrt(n) times this over n edges. Nodes next to each other
    are off by more (1.3-1.8 mm), but those errors do not add up: scan-to-map matching
    keeps neighbours consistent."""
    odometry_xy_std_per_m: float = 0.002
    """Growth of ``odometry_xy_std`` per metre between the nodes, m/m."""
    odometry_angle_std: float = math.radians(0.008)
    """Standard deviation of the relative heading of two consecutive nodes, rad, plus
    ``odometry_angle_std_per_m`` per metre (0.013° for nodes 0.25 m apart): the replays'
    headings 20 m and 80 m apart were off by 0.075-0.09° and 0.11-0.14°, about sqrt(n)
    times this (0.035° between neighbours)."""
    odometry_angle_std_per_m: float = math.radians(0.02)
    """Growth of ``odometry_angle_std`` per metre between the nodes, rad/m."""
    slip_std_per_m: float = 0.1
    """Where a match could not measure a direction (a corridor: the correction along it
    was dropped), the position along it is dead reckoning: this standard deviation per
    metre driven is added along it, m/m (replays: 3 cm per 0.34 m along corridors, and
    the simulator's odometry drifts 0.14 m per metre at its 2-sigma). A rejected match
    that was integrated adds its odometry prior instead."""
    loop_search_spacing: float = 1.0
    """Metres driven between two loop-closure searches (a search runs when a node is added
    and there are candidates) ..."""
    loop_closure_spacing: float = 5.0
    """... and after an accepted closure, m: the graph is tied here already. Against 0.5 m
    and 2 m, the replays' graphs were about as accurate (mean ATE of the optimised
    trajectories 0.035 against 0.033 m) at a third of the searches; at 2 m and 10 m they
    lost a few closures that mattered (0.037 m). With these, env steps/s with SLAM stay at
    71-79 % of mode ``slam``'s in wander runs (a search costs 1-30 ms, most of it drawing
    a submap that is not kept from an earlier search)."""
    loop_min_path_gap: float = 10.0
    """A candidate node lies at least this far back along the robot's path, m: the front
    end's matched map (20 scans behind) and its neighbours tie nearer ones."""
    loop_candidate_radius: float = 3.5
    """A candidate node lies within this distance of the current node's estimate, m: its
    scans then overlap the current one. At 6 m (searching earlier, before the front end
    pulls itself onto an old map) most matches had too little overlap to be accepted."""
    submap_half_path: float = 3.0
    """Submaps hold the scans of the nodes along twice this much path, m, overlapping by
    half (old nodes only); a scan is matched against the one with the candidate nearest
    its middle."""
    loop_window_xy: float = 0.3
    """Half-width of the closure search's x and y windows, m, plus ``loop_window_per_m``
    per metre driven since the current node was last tied to an older one (by a closure)
    ..."""
    loop_window_per_m: float = 0.005
    """... m/m ..."""
    loop_window_xy_max: float = 1.0
    """... up to this, m."""
    loop_window_angle: float = math.radians(3.0)
    """Half-width of the closure search's heading window, rad, plus
    ``loop_window_angle_per_m`` per metre driven as above ..."""
    loop_window_angle_per_m: float = math.radians(0.03)
    """... rad/m ..."""
    loop_window_angle_max: float = math.radians(8.0)
    """... up to this, rad."""
    loop_min_points: int = 100
    """A scan with fewer returns is not matched for a closure."""
    loop_min_score: float = 0.65
    """Mean likelihood (0..1) of the matched scan in the submap below this: no closure.
    With ``loop_min_condition`` chosen on the 1,494 closure matches of the replays (their
    true error known): at 0.55 / 0.1, 4.3 % of the accepted ones were more than 2 cm or
    0.3° off; at 0.65 / 0.3, 1.6 % (half as many accepted). Confirmed on a fresh replay
    with the final search spacing: 214 of 936 matches accepted, 5 off by 2-3 cm or
    0.3°, none by more than 5 cm or 1°."""
    loop_max_peak_ratio: float = 0.85
    """The best score of the coarse search must be at least ``1 / loop_max_peak_ratio``
    times the best one farther than ``loop_peak_separation`` from it (a unique best: not a
    corridor or a repeated structure). The matches it refused on the replays were off by
    1.2 cm (median) and 19 cm at the 90th percentile; a featureless corridor scores
    0.95-1."""
    loop_peak_separation: float = 0.3
    """Distance from the best lattice pose beyond which a pose is a distinct peak, m: past
    the coarse field's blur (0.12 m) on either side of the peak."""
    loop_min_condition: float = 0.3
    """Smallest / largest eigenvalue of the match's translational information below this:
    no closure (the scan does not pin down some direction; see ``loop_min_score``)."""
    loop_xy_std: float = 0.01
    """Added to the closure match's own position uncertainty, m: the accepted closures of
    the replays were 2 mm off (median), 5 mm at the 90th percentile, 3-4 cm at worst."""
    loop_angle_std: float = math.radians(0.1)
    """Added to the closure match's heading uncertainty, rad (replays: 0.024° median,
    0.06° at the 90th percentile)."""
    optimize_min_chi2: float = 3.0
    """An accepted closure whose squared Mahalanobis error in the graph as it is does not
    exceed this (and that took no edge's local measurement) is added without optimising:
    the graph agrees with it already (it counts in the next optimisation). Four in five
    closures of the replays were such (40 optimisations for 214 closures)."""
    robust: str = "switchable"
    """The loop edges' robust kernel (:mod:`mrslam_env.slam.posegraph`): ``"switchable"``,
    ``"huber"`` or ``"none"``. Switchable: a false closure 1.5 m off switched itself off
    and left a 10 m square within 1 cm of where its true closure put it, where Huber's
    bounded pull still bent it by 0.3 m (tests/test_slam_posegraph.py)."""
    robust_width: float = 9.0
    """The kernel's width in units of chi^2 (3 degrees of freedom: a consistent closure
    stays below ~8 at the 95th percentile)."""
    max_iterations: int = 20
    """Gauss–Newton steps per optimisation phase (the replays' took 2-6)."""
    tolerance: float = 1e-5
    """An optimisation ends once no node moves more than this in a step, m and rad."""
    rerender_translation: float = 0.01
    """After an optimisation, the maps are redrawn from the scans at their new poses once
    a node has moved this far from where its scans were drawn, m ...; below it the maps
    (and the front end, which matches against them) stay as they are. A redraw costs
    about 0.5 ms per scan (1.5 s at 3,000 scans); the replays redrew 0-3 times per robot
    and run. A fifth of a cell: the map agreement counts a wall a cell off as right."""
    rerender_rotation: float = math.radians(0.1)
    """... or turned this much, rad (0.1° moves a point 8 m away by 1.4 cm)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=(
                "node_translation",
                "node_rotation",
                "local_window_xy",
                "local_window_angle",
                "odometry_xy_std",
                "odometry_angle_std",
                "loop_candidate_radius",
                "loop_window_xy",
                "loop_window_xy_max",
                "loop_window_angle",
                "loop_window_angle_max",
                "loop_peak_separation",
                "loop_xy_std",
                "loop_angle_std",
                "robust_width",
                "tolerance",
                "rerender_translation",
                "rerender_rotation",
            ),
            non_negative=(
                "odometry_xy_std_per_m",
                "odometry_angle_std_per_m",
                "slip_std_per_m",
                "loop_search_spacing",
                "loop_closure_spacing",
                "loop_min_path_gap",
                "snap_path_gap",
                "snap_window",
                "snap_radius",
                "submap_half_path",
                "loop_window_per_m",
                "loop_window_angle_per_m",
                "loop_min_score",
                "loop_max_peak_ratio",
                "loop_min_condition",
                "optimize_min_chi2",
            ),
            counts=("local_map_scans", "loop_min_points", "max_iterations"),
        )
        name = type(self).__name__
        for attr in ("loop_min_score", "loop_max_peak_ratio", "loop_min_condition"):
            value = getattr(self, attr)
            require(name, attr, value, value <= 1.0, "<= 1")
        require(
            name,
            "robust",
            self.robust,
            self.robust in ("switchable", "huber", "none"),
            "one of ('switchable', 'huber', 'none')",
        )
        for attr, base in (
            ("loop_window_xy_max", "loop_window_xy"),
            ("loop_window_angle_max", "loop_window_angle"),
        ):
            require(
                name,
                attr,
                getattr(self, attr),
                getattr(self, attr) >= getattr(self, base),
                f">= {base} ({getattr(self, base)})",
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class SlamConfig:
    """One robot's SLAM.

    ``mode``: ``"slam"`` matches each scan to the map, seeded by odometry; ``"pose_graph"``
    does the same and keeps a pose graph of the scans with loop closures, redrawing the map
    when they move it (``pose_graph``); ``"odometry"`` maps with dead-reckoning poses;
    ``"ground_truth"`` maps with the true poses (given to
    :meth:`~mrslam_env.slam.slam.RobotSlam.update` in the map frame), for ablations.
    """

    mode: SlamMode = "slam"
    """``"slam"``, ``"pose_graph"``, ``"odometry"`` or ``"ground_truth"``."""
    grid: GridConfig = field(default_factory=GridConfig)
    """The occupancy grid and its update."""
    matcher: MatcherConfig = field(default_factory=MatcherConfig)
    """Scan-to-map matching (used in ``slam`` and ``pose_graph`` modes)."""
    pose_graph: PoseGraphConfig = field(default_factory=PoseGraphConfig)
    """The pose graph and its loop closures (used in ``pose_graph`` mode)."""
    min_translation: float = 0.05
    """Motion filter: a scan is matched at all only after the robot has moved
    this far since the last matched scan, m ..."""
    min_rotation: float = math.radians(2.0)
    """... or turned this much, rad; in between, the pose follows odometry."""
    map_update_translation: float = 0.05
    """A matched scan is integrated into the map only once the robot has moved this far
    since the last integrated scan, m ...; scans in between are matched (they give the
    pose) but leave the map alone. Every integration adds its pose error to the map, which
    later matches inherit. The default equals ``min_translation``: every matched scan is
    integrated (0.4 m / 15° cut the heading random walk in SLAM-only runs but measured
    worse end to end, with the SLAM before its field fixes; not re-measured since)."""
    map_update_rotation: float = math.radians(2.0)
    """... or turned this much, rad."""
    match_lag: int = 20
    """Scans are matched against the map as it was this many integrated scans ago (0: the
    current map); the map itself (:attr:`~mrslam_env.slam.slam.RobotSlam.grid`) takes
    every scan at once, so each scan is integrated twice (into the map now, into the
    matched map later). A rejected match lets the waiting scans into the matched map at
    once (e.g. the robot has driven past what the matched map covers). Against the
    current map each scan inherits the last scans' heading errors and passes them on;
    against a map 20 scans old, 20 scans in a row are placed independently and their
    errors average out in the map. 20 (1 m at the motion filter's 5 cm): chosen on the
    replays of two team runs whose maps were 0.2-0.3 degrees off (10 less good, 40 let the
    matched map fall behind the robot and matches failed; docs/decisions.md)."""
    integrate_rejected_after: int = 10
    """A scan whose match is rejected is not integrated (the pose follows odometry), unless
    this many matches in a row have been rejected: then it is integrated at the odometry
    pose, so that mapping goes on where matching cannot."""

    def __post_init__(self) -> None:
        require(
            type(self).__name__, "mode", self.mode, self.mode in SLAM_MODES, f"one of {SLAM_MODES}"
        )
        check_fields(
            self,
            non_negative=(
                "min_translation",
                "min_rotation",
                "map_update_translation",
                "map_update_rotation",
            ),
            counts=("integrate_rejected_after",),
            whole=("match_lag",),
        )
        for name, cls in (
            ("grid", GridConfig),
            ("matcher", MatcherConfig),
            ("pose_graph", PoseGraphConfig),
        ):
            value = getattr(self, name)
            require(type(self).__name__, name, value, isinstance(value, cls), f"a {cls.__name__}")
