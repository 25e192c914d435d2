"""Configuration as data: frozen dataclasses, one field per knob, unit and meaning stated.

Every class validates itself in ``__post_init__`` and names the offending field and value.
Change a value with :func:`dataclasses.replace`, e.g.
``replace(EnvConfig(), lidar=replace(LidarConfig(), n_beams=180))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from mrslam_env.slam.config import SlamConfig
from mrslam_env.validation import check_fields, require

__all__ = [
    "CommConfig",
    "EnvConfig",
    "LidarConfig",
    "LocalMapConfig",
    "OdometryConfig",
    "PeerSensorConfig",
    "RewardConfig",
    "RobotConfig",
]


def _require_probability(config: object, name: str) -> None:
    """A field that is a probability: a number in [0, 1]."""
    value = getattr(config, name)
    ok = isinstance(value, int | float) and 0.0 <= value <= 1.0
    require(type(config).__name__, name, value, ok, "a number in [0, 1]")


@dataclass(frozen=True, slots=True, kw_only=True)
class RobotConfig:
    """A differential-drive robot with a circular footprint."""

    radius: float = 0.2
    """Footprint radius, m."""
    mass: float = 10.0
    """kg."""
    max_speed: float = 1.0
    """Linear speed at action 1.0, m/s (actions in [-1, 1] scale to [-max, max])."""
    max_turn_rate: float = 2.0
    """Angular speed at action 1.0, rad/s."""
    max_acceleration: float = 2.0
    """Limit on the change of the commanded linear speed, m/s^2."""
    max_angular_acceleration: float = 6.0
    """Limit on the change of the commanded angular speed, rad/s^2."""

    def __post_init__(self) -> None:
        check_fields(self, positive=tuple(f.name for f in fields(self)))


@dataclass(frozen=True, slots=True, kw_only=True)
class LidarConfig:
    """A 360° planar lidar, beam i at ``-pi + i * 2 pi / n_beams`` from the heading."""

    n_beams: int = 360
    """Number of beams over the full circle."""
    max_range: float = 8.0
    """Maximum range, m; reported for beams with no return."""
    range_noise_std: float = 0.01
    """Standard deviation of the Gaussian range noise, m (0 turns it off)."""
    dropout_probability: float = 0.01
    """Probability that a beam returns nothing (reported as ``max_range``)."""

    def __post_init__(self) -> None:
        n_beams = self.n_beams
        ok = isinstance(n_beams, int) and not isinstance(n_beams, bool) and n_beams >= 4
        require("LidarConfig", "n_beams", n_beams, ok, "an int >= 4")
        check_fields(self, positive=("max_range",), non_negative=("range_noise_std",))
        _require_probability(self, "dropout_probability")


@dataclass(frozen=True, slots=True, kw_only=True)
class OdometryConfig:
    """Odometry motion noise, the four-alpha model (Thrun et al., Probabilistic Robotics,
    table 5.6): the motion between steps is split into rotation, translation, rotation, each
    perturbed with a variance that grows with the motion."""

    alpha1: float = 0.05
    """Rotation variance per squared rotation, rad^2/rad^2."""
    alpha2: float = 0.005
    """Rotation variance per squared translation, rad^2/m^2."""
    alpha3: float = 0.02
    """Translation variance per squared translation, m^2/m^2."""
    alpha4: float = 0.005
    """Translation variance per squared rotation, m^2/rad^2."""

    def __post_init__(self) -> None:
        check_fields(self, non_negative=("alpha1", "alpha2", "alpha3", "alpha4"))


@dataclass(frozen=True, slots=True, kw_only=True)
class PeerSensorConfig:
    """The rendezvous sensor: a noisy relative pose of another robot in line of sight."""

    detect_range: float = 5.0
    """Maximum detection distance, m."""
    range_noise_std: float = 0.05
    """m."""
    bearing_noise_std: float = 0.02
    """rad."""
    heading_noise_std: float = 0.05
    """rad."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=("detect_range",),
            non_negative=("range_noise_std", "bearing_noise_std", "heading_noise_std"),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class CommConfig:
    """The radio link between two robots."""

    comm_range: float = 12.0
    """Maximum link distance, m."""
    blocked_by_walls: bool = False
    """If true, the link also needs line of sight."""
    packet_loss: float = 0.0
    """Probability that an otherwise-up link is down on a given step."""

    def __post_init__(self) -> None:
        check_fields(self, positive=("comm_range",))
        _require_probability(self, "packet_loss")

    @property
    def exact(self) -> bool:
        """Whether the link is up exactly while the robots are within ``comm_range`` (not
        blocked by walls, no packet loss): then a link down says they are further apart."""
        return not self.blocked_by_walls and not self.packet_loss


@dataclass(frozen=True, slots=True, kw_only=True)
class RewardConfig:
    """Per-step reward: newly observed area (own, plus optionally team novelty) minus a
    collision penalty."""

    area_weight: float = 1.0
    """Reward per square metre the robot knows for the first time this episode (in its own
    map with SLAM on; never negative: a cell that turns back to unknown and known again
    pays once)."""
    team_novelty_weight: float = 0.0
    """Reward per square metre of the common world-frame coverage grid
    (``coverage_resolution``) that the robot covered this step and no robot had covered
    before it (privileged: the env projects maps with the true start poses)."""
    collision_penalty: float = 1.0
    """Subtracted on each step in which the robot touches a wall or another robot."""
    coverage_resolution: float = 0.2
    """Cell size (m) of the world-frame grid on which the area a robot has seen is
    counted from its true poses (for ``EnvConfig.slam = None``, and for the env's
    ``observable_area``)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            non_negative=("area_weight", "team_novelty_weight", "collision_penalty"),
            positive=("coverage_resolution",),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class LocalMapConfig:
    """The ``local_map`` observation: an egocentric crop of the robot's own map
    (:mod:`mrslam_env.slam.local_map`)."""

    cells: int = 64
    """Side of the square crop, cells."""
    cell_size: float = 0.1
    """Edge of one crop cell, m (the default crop spans 6.4 m)."""

    def __post_init__(self) -> None:
        check_fields(self, positive=("cell_size",), counts=("cells",))


@dataclass(frozen=True, slots=True, kw_only=True)
class EnvConfig:
    """Everything the environment needs besides the world."""

    robot: RobotConfig = field(default_factory=RobotConfig)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    peer: PeerSensorConfig = field(default_factory=PeerSensorConfig)
    comm: CommConfig = field(default_factory=CommConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    slam: SlamConfig | None = field(default_factory=SlamConfig)
    """Each robot's onboard SLAM (mode ``slam``, ``odometry`` or ``ground_truth``). ``None``
    turns onboard SLAM off: no ``pose`` or ``local_map`` observations, and the reward
    counts area seen from the true poses (the raw simulator, for speed)."""
    local_map: LocalMapConfig = field(default_factory=LocalMapConfig)
    dt: float = 0.1
    """Env step (control and sensor period), s."""
    physics_substeps: int = 2
    """Physics steps per env step. pymunk has no continuous collision detection: keep the
    travel per substep, ``max_speed * dt / substeps`` (5 cm by default), well below the
    robot radius plus half the thinnest wall, so that no contact can be stepped over."""
    max_cycles: int = 2000
    """Steps before truncation."""
    starts: tuple[tuple[float, float, float], ...] | None = None
    """Start poses (world frame) overriding the scenario's; robots beyond them get
    automatic starts."""
    randomize_starts: bool = False
    """If true, every ``reset`` draws fresh start poses (robot 0 anywhere a robot can start
    in the region of the scenario's first start, the others as automatic starts), from
    the reset's seed; ``starts`` is then ignored."""
    randomize_world: bool = False
    """If true and the scenario is a parametric family given by name (``"procedural"``,
    ``"procedural-7"``), every ``reset`` builds a fresh layout ``<family>-<k>`` with ``k``
    drawn from the reset's seed."""
    flat_observation: bool = False
    """If true, each robot's observation is one normalised float32 vector instead of the
    ``Dict`` (layout in :mod:`mrslam_env.wrappers`)."""
    flat_length_scale: float = 50.0
    """Length (m) that divides the ``odom`` and ``pose`` positions in the flat
    observation (clipped to [-1, 1])."""
    privileged: bool = False
    """If true, each robot's infos also hold ground truth (``true_pose`` and the
    ``privileged`` dict: world-frame pose and coverage), for evaluation only; never part of
    an observation either way."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=("dt", "flat_length_scale"),
            counts=("physics_substeps", "max_cycles"),
        )
        for name in ("randomize_starts", "randomize_world", "flat_observation", "privileged"):
            value = getattr(self, name)
            require("EnvConfig", name, value, isinstance(value, bool), "a bool")
        if self.starts is not None:
            require("EnvConfig", "starts", self.starts, len(self.starts) > 0, "None or non-empty")
            for i, start in enumerate(self.starts):
                ok = len(start) == 3 and all(math.isfinite(v) for v in start)
                require("EnvConfig", f"starts[{i}]", start, ok, "a finite (x, y, theta)")
