"""Configuration of the onboard SLAM: frozen dataclasses, unit and meaning per field.

Three layers, as in :mod:`mrslam_env.config`: :class:`GridConfig` (the occupancy grid and
its log-odds update), :class:`MatcherConfig` (scan-to-map matching) and :class:`SlamConfig`
(mode, motion filter, and the two above). Change a value with :func:`dataclasses.replace`,
e.g. ``replace(SlamConfig(), mode="odometry")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, get_args

from mrslam_env.validation import check_fields, require

__all__ = ["SLAM_MODES", "GridConfig", "MatcherConfig", "SlamConfig", "SlamMode"]

SlamMode = Literal["slam", "odometry", "ground_truth"]
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
class SlamConfig:
    """One robot's SLAM.

    ``mode``: ``"slam"`` matches each scan to the map, seeded by odometry; ``"odometry"``
    maps with dead-reckoning poses; ``"ground_truth"`` maps with the true poses (given to
    :meth:`~mrslam_env.slam.slam.RobotSlam.update` in the map frame), for ablations.
    """

    mode: SlamMode = "slam"
    """``"slam"``, ``"odometry"`` or ``"ground_truth"``."""
    grid: GridConfig = field(default_factory=GridConfig)
    """The occupancy grid and its update."""
    matcher: MatcherConfig = field(default_factory=MatcherConfig)
    """Scan-to-map matching (used in ``slam`` mode)."""
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
        for name, cls in (("grid", GridConfig), ("matcher", MatcherConfig)):
            value = getattr(self, name)
            require(type(self).__name__, name, value, isinstance(value, cls), f"a {cls.__name__}")
