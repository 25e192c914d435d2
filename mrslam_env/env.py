"""MultiRobotSlam: lidar robots exploring a 2-D world with an unknown relative pose.

=====================  ===========================================================
Import                 ``from mrslam_env import parallel_env``
PettingZoo id          ``"mrslam/MultiRobotSlam-v0"`` (registered on import of
                       ``mrslam_env.env``; ``pettingzoo.make("parallel", ...)``)
Actions                Continuous
Parallel API           Yes (AEC through :func:`env`)
Agents                 ``robot_0 ... robot_{n-1}`` (default n = 2)
Action shape           (2,)
Action values          [-1, 1]
Observation            ``Dict`` (below)
=====================  ===========================================================

Two (or N) differential-drive robots with 360° lidars move in a static 2-D world simulated
with pymunk. Each robot starts at a pose nobody tells the others: its odometry and, later,
its map are in its own frame. They can detect each other (peer sensor) and talk (comm link)
only when close; see docs/design.md for the whole research setting.

Actions
-------
``Box(-1, 1, (2,), float32)`` per robot: ``(v, omega)`` normalised; ``v = a[0] *
max_speed`` (m/s, negative drives backwards), ``omega = a[1] * max_turn_rate`` (rad/s,
counter-clockwise). Values outside [-1, 1] are clipped; NaN or inf raise ``ValueError``
naming the agent. The robot follows the command within its acceleration limits.

Observations (per robot)
------------------------
==========  =====================  =======================================================
key         space                  meaning
==========  =====================  =======================================================
scan        Box(0, R, (N,), f32)   lidar ranges (m), beam i at ``-pi + i 2pi/N`` from the
                                   heading, counter-clockwise; ``R = max_range`` = no return
odom        Box((3,), f64)         dead-reckoning pose ``(x, y, theta)`` in the robot's own
                                   odom frame (origin = its start pose); drifts
peer        Box((n-1, 4), f64)     per other robot (index order, self skipped):
                                   ``(detected, range m, bearing rad, relative heading
                                   rad)``; zeros when not detected (out of
                                   ``detect_range`` or no line of sight)
comm        MultiBinary(n-1)       1 when the link to that robot is up this step
pose        Box((3,), f64)         the robot's onboard-SLAM pose ``(x, y, theta)`` in its
                                   own map frame (origin = its start pose)
local_map   Box(0, 1, (2, S, S),   egocentric crop of the robot's own map, centred on it
            uint8)                 and turned with it (it looks along +x = increasing
                                   column; row 0 = lowest local y); channel 0 = free,
                                   channel 1 = occupied, both 0 = unknown;
                                   ``S = local_map.cells`` (64) of ``cell_size`` (0.1 m)
==========  =====================  =======================================================

``pose`` and ``local_map`` exist when onboard SLAM is on (``config.slam``, the default).
Each robot runs :class:`~mrslam_env.slam.slam.RobotSlam` on its own ``odom`` and ``scan``
(minus the returns from robots its peer sensor detects: they are not part of the map)
(mode ``slam``, ``odometry`` or ``ground_truth`` per ``config.slam.mode``);
``env.unwrapped.robot_map(agent)`` returns its current map (a
:class:`~mrslam_env.gridmap.GridMap` in its map frame) and ``robot_slam(agent)`` the SLAM
object itself (trajectory, grid).

Rewards
-------
``area_weight *`` the area (m²) that became known (FREE or OCCUPIED) in the robot's own map
this step ``- collision_penalty`` on steps with a contact. With ``config.slam = None`` the
area is what the robot's scan observed for the first time from its true pose, counted on a
world-frame grid of ``coverage_resolution``.

Episode end
-----------
No termination; truncation of all robots after ``config.max_cycles`` steps.

Infos (per robot)
-----------------
``true_pose`` (3,) world-frame pose: **privileged**, for evaluation only, never for a
policy that claims not to know it; ``collision`` (bool); ``observed_area`` (m², so far:
the known area of the robot's map, or with SLAM off the area seen from the true poses).

Arguments
---------
``parallel_env(scenario="office", n_robots=2, seed=None, render_mode=None, config=None)``:
``scenario`` is a name (``mrslam scenarios`` lists them; ``"procedural-7"`` picks a layout
seed) or a :class:`~mrslam_env.sim.world.WorldSpec` (e.g. from a ROS map);
``seed`` seeds the first ``reset`` when it is given none; ``render_mode`` is ``None`` or
``"rgb_array"``; ``config`` an :class:`~mrslam_env.config.EnvConfig`.

Pickling
--------
Supported (``pickle``, ``copy.deepcopy``): a restored env continues the same run bit for
bit. (pymunk does not pickle its contact cache, so pickling re-creates the original's
physics space the same way; the original's next steps are unchanged otherwise.)

Version history
---------------
* v0: initial release; onboard SLAM (``pose``, ``local_map``, map-based reward) added
  before the first tagged version.
"""

from __future__ import annotations

import functools
from typing import Any, ClassVar

import gymnasium
import numpy as np
import pettingzoo
from gymnasium import spaces
from gymnasium.utils import seeding
from numpy.typing import NDArray
from pettingzoo.utils import conversions
from PIL import Image, ImageDraw
from scipy import ndimage

from mrslam_env import ENV_ID
from mrslam_env.config import EnvConfig
from mrslam_env.geometry import compose, inverse
from mrslam_env.gridmap import GridMap
from mrslam_env.registry import build_world
from mrslam_env.sim.simulator import SimState, Simulator
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from mrslam_env.slam.local_map import local_map
from mrslam_env.slam.raycast import mark_scan_observed
from mrslam_env.slam.scan import mask_returns_near, sighted_positions
from mrslam_env.slam.slam import RobotSlam

__all__ = ["MultiRobotSlamEnv", "env", "parallel_env"]

AgentID = str
ObsDict = dict[str, NDArray[Any]]

PEER_MASK_MARGIN = 0.15
"""Beyond the robot radius (m): covers the peer sensor's noise."""

ROBOT_COLOURS = [(31, 119, 180), (214, 39, 40), (44, 160, 44), (148, 103, 189), (255, 127, 14)]


class MultiRobotSlamEnv(pettingzoo.ParallelEnv[AgentID, ObsDict, NDArray[np.float32]]):
    """PettingZoo ``ParallelEnv``; see the module docstring for the full card."""

    metadata: ClassVar[dict[str, Any]] = {
        "name": "mrslam_v0",
        "render_modes": ["rgb_array"],
        "render_fps": 10,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str | WorldSpec = "office",
        n_robots: int = 2,
        seed: int | None = None,
        render_mode: str | None = None,
        config: EnvConfig | None = None,
    ) -> None:
        if not isinstance(n_robots, int) or n_robots < 1:
            raise ValueError(f"n_robots must be an int >= 1, got {n_robots!r}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        if not isinstance(scenario, str | WorldSpec):
            raise ValueError(f"scenario must be a scenario name or a WorldSpec, got {scenario!r}")
        self.world = scenario if isinstance(scenario, WorldSpec) else build_world(scenario)
        self.config = config if config is not None else EnvConfig()
        self.render_mode = render_mode
        self.possible_agents = [f"robot_{i}" for i in range(n_robots)]
        self.agents = list(self.possible_agents)
        self._initial_seed = checked_seed(seed)
        self._coverage_template = ground_truth_map(
            self.world, self.config.reward.coverage_resolution, margin=1.0
        )
        self.np_random, self.np_random_seed = seeding.np_random(self._initial_seed)
        self._sim: Simulator | None = None
        self._slams: list[RobotSlam] = []
        self._render_base: NDArray[np.uint8] | None = None

    # --- spaces -------------------------------------------------------------------------

    @functools.cache  # noqa: B019 - one space object per agent, as the API expects
    def observation_space(self, agent: AgentID) -> spaces.Dict:
        lidar, peer = self.config.lidar, self.config.peer
        others = len(self.possible_agents) - 1
        inf = np.inf
        planar_pose = spaces.Box(
            np.array([-inf, -inf, -np.pi]), np.array([inf, inf, np.pi]), dtype=np.float64
        )
        entries: dict[str, spaces.Space[Any]] = {
            "scan": spaces.Box(0.0, lidar.max_range, (lidar.n_beams,), np.float32),
            "odom": planar_pose,
            "peer": spaces.Box(
                np.tile([0.0, 0.0, -np.pi, -np.pi], (others, 1)),
                np.tile([1.0, peer.detect_range, np.pi, np.pi], (others, 1)),
                dtype=np.float64,
            ),
            "comm": spaces.MultiBinary(others),
        }
        if self.config.slam is not None:
            side = self.config.local_map.cells
            entries["pose"] = planar_pose
            entries["local_map"] = spaces.Box(0, 1, (2, side, side), np.uint8)
        return spaces.Dict(entries)

    @functools.cache  # noqa: B019
    def action_space(self, agent: AgentID) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (2,), np.float32)

    # --- the episode --------------------------------------------------------------------

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[AgentID, ObsDict], dict[AgentID, dict[str, Any]]]:
        seed = checked_seed(seed)
        if seed is None and self._sim is None:
            seed = self._initial_seed
        if seed is not None:
            self.np_random, self.np_random_seed = seeding.np_random(seed)
        self.agents = list(self.possible_agents)
        self._sim = Simulator(self.world, len(self.possible_agents), self.config, self.np_random)
        # Cells outside the robots' enclosure count as seen from the start: a no-return
        # beam (reported at max range) passes through walls and must not earn area there.
        observable = observable_cells(self._coverage_template, self._sim.starts)
        self._observed = [~observable for _ in self.possible_agents]
        self._observable_area = float(observable.sum()) * self._coverage_template.resolution**2
        self._observed_area = np.zeros(len(self.possible_agents))
        self.steps = 0
        state = self._sim.state
        self._slams = []  # a fresh map for every robot
        if self.config.slam is not None:
            lidar = self.config.lidar
            self._slams = [
                RobotSlam(self.config.slam, lidar.n_beams, lidar.max_range)
                for _ in self.possible_agents
            ]
        self._count_new_area(state)
        return self._observations(state), self._infos(state)

    def step(
        self, actions: dict[AgentID, Any]
    ) -> tuple[
        dict[AgentID, ObsDict],
        dict[AgentID, float],
        dict[AgentID, bool],
        dict[AgentID, bool],
        dict[AgentID, dict[str, Any]],
    ]:
        if self._sim is None:
            raise RuntimeError("step() called before reset()")
        if not self.agents:
            raise RuntimeError("step() called after the episode ended; call reset()")
        commands = self._commands(actions)
        state = self._sim.step(commands)
        self.steps += 1
        new_area = self._count_new_area(state)
        reward_config = self.config.reward
        rewards = {
            agent: float(
                reward_config.area_weight * new_area[i]
                - reward_config.collision_penalty * state.collisions[i]
            )
            for i, agent in enumerate(self.possible_agents)
        }
        truncated = self.steps >= self.config.max_cycles
        terminations = dict.fromkeys(self.agents, False)
        truncations = dict.fromkeys(self.agents, truncated)
        observations, infos = self._observations(state), self._infos(state)
        if truncated:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def _commands(self, actions: dict[AgentID, Any]) -> NDArray[np.float64]:
        unknown = set(actions) - set(self.possible_agents)
        if unknown:
            raise ValueError(
                f"actions for unknown agents {sorted(unknown)}; agents are {self.agents}"
            )
        commands = np.zeros((len(self.possible_agents), 2))
        for i, agent in enumerate(self.possible_agents):
            if agent not in actions:
                raise ValueError(f"missing action for {agent}")
            raw = np.asarray(actions[agent])
            if raw.dtype.kind not in "iuf":  # not bool, complex, str or object
                raise ValueError(
                    f"action for {agent} must be real numbers, got {raw.dtype} {actions[agent]!r}"
                )
            action = raw.astype(np.float64)
            if action.shape != (2,):
                raise ValueError(f"action for {agent} must have shape (2,), got {action.shape}")
            if not np.all(np.isfinite(action)):
                raise ValueError(f"action for {agent} is not finite: {action.tolist()}")
            commands[i] = action
        return commands

    def _count_new_area(self, state: SimState) -> NDArray[np.float64]:
        """Update what each robot has seen; the area (m²) it saw for the first time."""
        if self._slams:
            return self._update_slam(state)
        grid = self._coverage_template
        new_cells = np.array(
            [
                mark_scan_observed(
                    self._observed[i],
                    grid.origin[0],
                    grid.origin[1],
                    grid.resolution,
                    pose[0],
                    pose[1],
                    pose[2],
                    scan,
                )
                for i, (pose, scan) in enumerate(zip(state.true_poses, state.scans, strict=True))
            ],
            dtype=np.float64,
        )
        area = new_cells * grid.resolution**2
        self._observed_area += area
        return area

    def _update_slam(self, state: SimState) -> NDArray[np.float64]:
        """One SLAM update per robot; the growth of each robot's mapped area (m²)."""
        assert self._sim is not None
        ground_truth = self.config.slam is not None and self.config.slam.mode == "ground_truth"
        area = np.zeros(len(self._slams))
        for i, slam in enumerate(self._slams):
            grid = slam.grid
            known_before = grid.known_cells
            true_pose_in_map = None
            if ground_truth:
                true_pose_in_map = compose(inverse(self._sim.starts[i]), state.true_poses[i])
            slam.update(state.odometry[i], self._scan_without_peers(state, i), true_pose_in_map)
            area[i] = (grid.known_cells - known_before) * grid.resolution**2
            self._observed_area[i] = grid.known_cells * grid.resolution**2
        return area

    def _scan_without_peers(self, state: SimState, robot: int) -> NDArray[np.float64]:
        """The scan SLAM integrates: returns from the robots the peer sensor detects are
        dropped (a robot is not part of the static map, and touching robots would pull
        the scan match). The ``scan`` observation itself is left whole."""
        points = sighted_positions(state.peers[robot])
        if len(points) == 0:
            return state.scans[robot]
        radius = self.config.robot.radius + PEER_MASK_MARGIN
        return mask_returns_near(state.scans[robot], points, radius, self.config.lidar.max_range)

    def _observations(self, state: SimState) -> dict[AgentID, ObsDict]:
        observations: dict[AgentID, ObsDict] = {}
        crop = self.config.local_map
        for i, agent in enumerate(self.possible_agents):
            if agent not in self.agents:
                continue
            observation = {
                "scan": state.scans[i].astype(np.float32),
                "odom": state.odometry[i].copy(),
                "peer": state.peers[i].copy(),
                "comm": state.comm[i].astype(np.int8),
            }
            if self._slams:
                slam = self._slams[i]
                observation["pose"] = slam.pose
                observation["local_map"] = local_map(
                    slam.grid, slam.pose, crop.cells, crop.cell_size
                )
            observations[agent] = observation
        return observations

    def _infos(self, state: SimState) -> dict[AgentID, dict[str, Any]]:
        return {
            agent: {
                "true_pose": state.true_poses[i].copy(),
                "collision": bool(state.collisions[i]),
                "observed_area": float(self._observed_area[i]),
            }
            for i, agent in enumerate(self.possible_agents)
            if agent in self.agents
        }

    # --- access for agents, evaluation and recording ---------------------------------------

    def robot_slam(self, agent: AgentID) -> RobotSlam:
        """The onboard SLAM of ``agent`` (its grid, pose and trajectory in its map frame);
        read it, do not update it."""
        if self._sim is None:
            raise RuntimeError("the environment has not been reset yet")
        if not self._slams:
            raise RuntimeError("onboard SLAM is off (EnvConfig.slam is None)")
        if agent not in self.possible_agents:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}")
        return self._slams[self.possible_agents.index(agent)]

    def robot_map(self, agent: AgentID) -> GridMap:
        """``agent``'s current map: the trinary view of its SLAM grid, in its map frame
        (its start pose)."""
        return self.robot_slam(agent).grid.to_gridmap()

    @property
    def observable_area(self) -> float:
        """Area (m²) a robot could ever observe: free space connected to the starts and
        the walls bounding it; ``observed_area / observable_area`` is a robot's coverage."""
        if self._sim is None:
            raise RuntimeError("the environment has not been reset yet")
        return self._observable_area

    @property
    def simulator(self) -> Simulator:
        """The simulator (privileged: ground truth lives here)."""
        if self._sim is None:
            raise RuntimeError("the environment has not been reset yet")
        return self._sim

    # --- rendering ----------------------------------------------------------------------

    def render(self) -> NDArray[np.uint8] | None:
        """Top-down ``(H, W, 3)`` uint8 image (y up) of walls, robots and scans."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; returning None")
            return None
        if self._sim is None:
            raise RuntimeError("render() called before reset()")
        xmin, ymin, xmax, ymax = self.world.bounds
        resolution = max(0.025, max(xmax - xmin, ymax - ymin) / 640.0)
        if self._render_base is None:
            grid = ground_truth_map(self.world, resolution, margin=0.5)
            base = np.where(grid.occupied[..., None], 40, 235).astype(np.uint8)
            self._render_base = np.repeat(base, 3, axis=2)
            self._render_grid = grid
        grid = self._render_grid
        image = Image.fromarray(self._render_base[::-1].copy())
        draw = ImageDraw.Draw(image)
        rows = grid.shape[0]

        def to_pixel(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[Any, Any]:
            return (x - grid.origin[0]) / resolution, rows - (y - grid.origin[1]) / resolution

        state = self._sim.state
        lidar = self.config.lidar
        angles = self._sim.beam_angles
        radius = self.config.robot.radius / resolution
        for i, (pose, scan) in enumerate(zip(state.true_poses, state.scans, strict=True)):
            colour = ROBOT_COLOURS[i % len(ROBOT_COLOURS)]
            tint = tuple(int(0.25 * c + 0.75 * 235) for c in colour)
            cx, cy = to_pixel(np.array(pose[0]), np.array(pose[1]))
            # The fan shows what returned; a no-return beam says nothing, so it draws nothing.
            hit = scan < lidar.max_range
            shown = np.where(hit, scan, 0.0)
            a = pose[2] + angles
            px, py = to_pixel(pose[0] + shown * np.cos(a), pose[1] + shown * np.sin(a))
            draw.polygon(list(zip(px.tolist(), py.tolist(), strict=True)), fill=tint)
            for x, y in zip(px[hit].tolist(), py[hit].tolist(), strict=True):
                draw.rectangle([x - 1, y - 1, x + 1, y + 1], fill=colour)
            draw.ellipse([cx - radius, cy - radius, cx + radius, cy + radius], fill=colour)
            hx, hy = to_pixel(
                np.array(pose[0] + 1.5 * self.config.robot.radius * np.cos(pose[2])),
                np.array(pose[1] + 1.5 * self.config.robot.radius * np.sin(pose[2])),
            )
            draw.line([(float(cx), float(cy)), (float(hx), float(hy))], fill=(0, 0, 0), width=2)
        return np.asarray(image, dtype=np.uint8)

    def close(self) -> None:
        self._render_base = None


def checked_seed(seed: Any) -> int | None:
    """``seed`` as a plain int (numpy integers accepted), or None.

    Raises
    ------
    ValueError
        For a negative number or anything that is not an integer (bools included).
    """
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
    return int(seed)


def observable_cells(grid: GridMap, starts: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Cells a robot could ever observe: the free space connected to any start, plus the
    wall cells bordering it (8-connected)."""
    labels, _ = ndimage.label(grid.free)
    cells = grid.world_to_cell(starts[:, :2])
    inside = grid.contains(cells)
    start_labels = labels[cells[inside, 0], cells[inside, 1]]
    region = np.isin(labels, start_labels[start_labels > 0])
    return ndimage.binary_dilation(region, structure=np.ones((3, 3), dtype=bool))


def parallel_env(**kwargs: Any) -> MultiRobotSlamEnv:
    """Create the parallel environment; arguments as :class:`MultiRobotSlamEnv`."""
    return MultiRobotSlamEnv(**kwargs)


def env(**kwargs: Any) -> pettingzoo.AECEnv[AgentID, ObsDict, NDArray[np.float32]]:
    """The same environment through PettingZoo's AEC interface."""
    return conversions.parallel_to_aec(parallel_env(**kwargs))


if ENV_ID not in pettingzoo.parallel_registry:
    pettingzoo.register("parallel", ENV_ID, entry_point="mrslam_env.env:parallel_env")
    pettingzoo.register("aec", ENV_ID, entry_point="mrslam_env.env:env")
