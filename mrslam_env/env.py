"""MultiRobotSlam: lidar robots exploring a 2-D world with an unknown relative pose.

=====================  ===========================================================
Import                 ``from mrslam_env import parallel_env`` (AEC: ``mrslam_env.env()``)
PettingZoo id          ``"mrslam/MultiRobotSlam-v0"`` (registered on import of
                       ``mrslam_env.env``; ``pettingzoo.make("parallel", ...)``)
Gymnasium id           ``"mrslam/SingleRobot-v0"`` (robot_0 learns, teammates scripted;
                       :mod:`mrslam_env.wrappers`)
Actions                Continuous
Parallel API           Yes (AEC through :func:`env`)
State                  ``state()`` / ``state_space`` (all robots' flat observations)
Agents                 ``robot_0 ... robot_{n-1}`` (default n = 2)
Action shape           (2,)
Action values          [-1, 1]
Observation            ``Dict`` (below), or a flat normalised ``Box``
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

One robot (``n_robots=1``: single-robot SLAM, no teammates) is supported: its ``peer`` is
an empty ``(0, 4)`` array and its ``comm`` an empty int8 vector, whose space is
``Box(0, 1, (0,), int8)`` (Gymnasium's ``MultiBinary`` cannot be empty); the flat
observation then has no peer or comm entries.

``EnvConfig(flat_observation=True)`` replaces the ``Dict`` by one float32 vector per robot,
every entry in [0, 1] or [-1, 1]: scan / max_range, odom (positions /
``flat_length_scale``, clipped; heading / pi), peer (detected, range / detect_range,
angles / pi), comm, pose, local_map as 0/1; the order and slices are in
:mod:`mrslam_env.wrappers` (``ObservationFlattener.layout()``). ``state()`` is that vector
for every robot, concatenated in ``possible_agents`` order (for centralised critics; no
privileged data), whatever the observation setting.

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
this step for the first time in the episode ``+ team_novelty_weight *`` the area the robot
covered this step that no robot had covered before it ``- collision_penalty`` on steps
with a contact. Each cell pays once: one that drifts back to unknown and is known again
pays nothing, so the reward is never negative without a collision. With
``config.slam = None`` the own area is what the robot's scan observed for the first time
from its true pose, counted on a world-frame grid of ``coverage_resolution``. Team novelty
(default weight 0) is counted on that common world-frame grid, with the robots' maps
placed by their true start poses: it uses privileged data to shape the reward, never the
observation. Cells that two robots cover first in the same step pay both.

Episode end
-----------
No termination; truncation of all robots after ``max_cycles`` steps.

Episodes
--------
``reset(seed, options)`` takes ``options={"scenario": name or WorldSpec}`` (switch worlds
from this episode on) and ``{"randomize_starts": True}`` (robot 0 at a random start cell
of the scenario's region, random heading; the others automatic). ``EnvConfig`` switches
``randomize_starts`` and ``randomize_world`` (a parametric family such as ``"procedural"``:
a fresh layout every reset) do that for every episode. All draws come from the reset's
seed: the same seed gives the same episode. Any other key raises ``ValueError`` naming it
and the known ones (``RESET_OPTIONS``), so a misspelling such as ``"randomise_starts"``
cannot pass unnoticed; only ``"options"`` is accepted and ignored, the probe PettingZoo's
API tests reset with. The single-robot env passes its options through, with the same
check.

Infos (per robot)
-----------------
``collision`` (bool); ``observed_area`` (m², so far: the known area of the robot's map, or
with SLAM off the area seen from the true poses); ``new_area`` (m², this step's own area
reward before weighting). Flat numbers only, so that RL libraries that turn infos into
tensors (TorchRL's ``PettingZooWrapper`` adds them to its observation spec) take them as
they are.

Ground truth only when asked for: with ``privileged=True`` (keyword or
``EnvConfig.privileged``) each robot's infos also hold ``privileged``, a dict of
ground-truth figures for evaluation only, never for a policy that claims not to know
them: ``true_pose`` (3,) world-frame pose, ``covered_area`` / ``team_covered_area`` (m²
of the common world-frame grid covered by the robot / by any robot), ``coverage`` /
``team_coverage`` (those over ``observable_area``) and ``team_new_area`` (m², this step's
team novelty); and ``true_pose`` at the top level, the same pose. (A nested dict: for
evaluation code, not for a library that turns infos into tensors.) Ground truth is never
part of an observation, its space or ``state()``; the team-novelty reward uses it either
way.

Arguments
---------
``parallel_env(scenario="office", n_robots=2, seed=None, render_mode=None, config=None,
max_cycles=None, privileged=None)``: ``scenario`` is a name (``mrslam scenarios`` lists them;
``"procedural-7"`` picks a layout seed) or a :class:`~mrslam_env.sim.world.WorldSpec` (e.g.
from a ROS map); ``seed`` seeds the first ``reset`` when it is given none; ``render_mode``
is ``None``, ``"rgb_array"`` or ``"human"`` (the frame in a matplotlib window; without a
display or matplotlib it warns once and draws nothing; ``render()`` returns None);
``config`` an :class:`~mrslam_env.config.EnvConfig`; ``max_cycles`` and ``privileged``
override ``config.max_cycles`` and ``config.privileged``. ``env(...)`` takes the same
arguments; any other keyword raises ``TypeError`` naming it and the known ones.

Pickling
--------
Supported (``pickle``, ``copy.deepcopy``): a restored env continues the same run bit for
bit. (pymunk does not pickle its contact cache, so pickling re-creates the original's
physics space the same way; the original's next steps are unchanged otherwise.)

Version history
---------------
* v0: initial release; onboard SLAM (``pose``, ``local_map``, map-based reward) added
  before the first tagged version; then (still v0) flat observations, ``state()``,
  ``max_cycles`` keyword, ``"human"`` rendering, once-per-cell area reward with team
  novelty, ``privileged`` infos, varying episodes; ground-truth infos only with
  ``privileged=True``.
"""

from __future__ import annotations

import functools
import inspect
import os
import sys
import types
from collections.abc import Iterable, Mapping
from dataclasses import replace
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
from mrslam_env.registry import available_scenarios, build_world
from mrslam_env.sim.simulator import SimState, Simulator
from mrslam_env.sim.starts import world_start_points
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from mrslam_env.slam.grid import mark_newly_known
from mrslam_env.slam.local_map import local_map
from mrslam_env.slam.raycast import mark_scan_observed
from mrslam_env.slam.scan import mask_returns_near, sighted_positions
from mrslam_env.slam.slam import RobotSlam
from mrslam_env.wrappers import ObservationFlattener

__all__ = ["RESET_OPTIONS", "MultiRobotSlamEnv", "env", "parallel_env"]

AgentID = str
ObsDict = dict[str, NDArray[Any]]

PEER_MASK_MARGIN = 0.15
"""Beyond the robot radius (m): covers the peer sensor's noise."""

RESET_OPTIONS = ("scenario", "randomize_starts")
"""The keys ``reset(options=...)`` takes (module notes, Episodes); others raise."""

PETTINGZOO_PROBE_OPTION = "options"
"""The one other key accepted, and ignored: PettingZoo's ``api_test`` and
``parallel_api_test`` reset with ``options={"options": 1}`` to check that ``reset`` takes
options at all."""

ROBOT_COLOURS = [(31, 119, 180), (214, 39, 40), (44, 160, 44), (148, 103, 189), (255, 127, 14)]


class MultiRobotSlamEnv(pettingzoo.ParallelEnv[AgentID, ObsDict, NDArray[np.float32]]):
    """PettingZoo ``ParallelEnv``; see the module docstring for the full card."""

    metadata: ClassVar[dict[str, Any]] = {
        "name": "mrslam_v0",
        "render_modes": ["human", "rgb_array"],
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
        max_cycles: int | None = None,
        privileged: bool | None = None,
    ) -> None:
        if not isinstance(n_robots, int) or isinstance(n_robots, bool) or n_robots < 1:
            raise ValueError(f"n_robots must be an int >= 1, got {n_robots!r}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        if not isinstance(scenario, str | WorldSpec):
            raise ValueError(f"scenario must be a scenario name or a WorldSpec, got {scenario!r}")
        self.scenario = scenario
        self.world = scenario if isinstance(scenario, WorldSpec) else build_world(scenario)
        self.config = config if config is not None else EnvConfig()
        if max_cycles is not None:
            self.config = replace(self.config, max_cycles=max_cycles)
        if privileged is not None:
            self.config = replace(self.config, privileged=privileged)  # checked by EnvConfig
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
        self._window: Any = None
        self._flattener = ObservationFlattener(self.config, n_robots)
        if self.config.randomize_world and parametric_family(scenario) is None:
            raise ValueError(
                "EnvConfig.randomize_world needs a parametric scenario family by name "
                f"(e.g. 'procedural'), got {scenario!r}"
            )
        self._dict_observations: dict[AgentID, ObsDict] = {}
        self._unread_local_maps: frozenset[AgentID] = frozenset()

    def omit_local_map(self, agents: Iterable[AgentID]) -> None:
        """Leave ``local_map`` out of these robots' ``Dict`` observations from the next
        :meth:`reset` or :meth:`step` on, for robots whose policy never reads it (a
        scripted teammate of :class:`agents.single_robot.SingleRobotEnv`): the crop is a
        good part of an observation's cost. Their observations then no longer match
        :meth:`observation_space`; :meth:`state` and the flat observation still hold
        their crops (computed when asked for), and every other entry is unchanged.

        Raises
        ------
        ValueError
            For an agent that is not one of ``possible_agents``.
        """
        agents = frozenset(agents)
        unknown = agents - set(self.possible_agents)
        if unknown:
            raise ValueError(f"unknown agents {sorted(unknown)}; agents are {self.possible_agents}")
        self._unread_local_maps = agents

    # --- spaces -------------------------------------------------------------------------

    @functools.cache  # noqa: B019 - one space object per agent, as the API expects
    def observation_space(self, agent: AgentID) -> spaces.Space[Any]:
        if self.config.flat_observation:
            return self._flattener.space
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
            # Gymnasium's MultiBinary needs n >= 1: one robot's empty link vector is a Box.
            "comm": spaces.MultiBinary(others) if others else spaces.Box(0, 1, (0,), np.int8),
        }
        if self.config.slam is not None:
            side = self.config.local_map.cells
            entries["pose"] = planar_pose
            entries["local_map"] = spaces.Box(0, 1, (2, side, side), np.uint8)
        return spaces.Dict(entries)

    @functools.cache  # noqa: B019
    def action_space(self, agent: AgentID) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (2,), np.float32)

    @functools.cached_property
    def state_space(self) -> spaces.Box:
        """The :meth:`state` space: the flat observation space, once per robot."""
        n = len(self.possible_agents)
        flat = self._flattener.space
        return spaces.Box(np.tile(flat.low, n), np.tile(flat.high, n), dtype=np.float32)

    def state(self) -> NDArray[np.float32]:
        """Global state for centralised critics: every robot's flat observation
        (:mod:`mrslam_env.wrappers` layout) concatenated in ``possible_agents`` order,
        whatever ``config.flat_observation`` is. No privileged data."""
        if self._sim is None:
            raise RuntimeError("state() called before reset()")
        parts = []
        for i, agent in enumerate(self.possible_agents):
            observation = self._dict_observations[agent]
            if self._slams and "local_map" not in observation:  # omitted: the crop now
                observation = dict(observation, local_map=self._local_map(i))
            parts.append(self._flattener(observation))
        return np.concatenate(parts)

    # --- the episode --------------------------------------------------------------------

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[AgentID, ObsDict], dict[AgentID, dict[str, Any]]]:
        seed = checked_seed(seed)
        if seed is None and self._sim is None:
            seed = self._initial_seed
        if seed is not None:
            self.np_random, self.np_random_seed = seeding.np_random(seed)
        options = checked_options(options)
        if "scenario" in options:
            scenario = options["scenario"]
            if not isinstance(scenario, str | WorldSpec):
                raise ValueError(
                    f"scenario must be a scenario name or a WorldSpec, got {scenario!r}"
                )
            if self.config.randomize_world and parametric_family(scenario) is None:
                raise ValueError(
                    "EnvConfig.randomize_world needs a parametric scenario family by name "
                    f"(e.g. 'procedural'), got {scenario!r}"
                )
            self._set_world(scenario)
        elif self.config.randomize_world:
            family = parametric_family(self.scenario)
            assert family is not None  # checked by the constructor
            self._set_world(f"{family}-{int(self.np_random.integers(1_000_000))}", keep=True)
        config = self.config
        if options.get("randomize_starts", config.randomize_starts):
            config = replace(config, starts=random_starts(self.world, config, self.np_random))
        self.agents = list(self.possible_agents)
        self._sim = Simulator(self.world, len(self.possible_agents), config, self.np_random)
        # Cells outside the robots' enclosure count as seen from the start: a no-return
        # beam (reported at max range) passes through walls and must not earn area there.
        observable = observable_cells(self._coverage_template, self._sim.starts)
        self._observed = [~observable for _ in self.possible_agents]
        self._team_observed = ~observable
        self._unobservable_cells = int((~observable).sum())
        self._ever_known: list[tuple[tuple[int, int], NDArray[np.bool_]]] = []
        self._new_area = np.zeros(len(self.possible_agents))
        self._team_new_area = np.zeros(len(self.possible_agents))
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
                + reward_config.team_novelty_weight * self._team_new_area[i]
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
        """Update what each robot has seen; the area (m²) it knows for the first time.

        Also updates the common world-frame coverage grid (``coverage_resolution``): each
        robot's covered cells (``self._observed``), the team's (``self._team_observed``)
        and ``self._team_new_area``, the area each robot covered that no robot had
        covered before this step.
        """
        grid = self._coverage_template
        # The cells each robot covers for the first time, as flat indices of the grid.
        newly_covered = []
        if self._slams:
            area = self._update_slam(state)
            cols = grid.shape[1]
            for i, cells in enumerate(self._newly_known_world_cells):
                observed = self._observed[i].reshape(-1)  # a view
                flat = np.unique(cells[:, 0] * cols + cells[:, 1])
                flat = flat[~observed[flat]]
                observed[flat] = True
                newly_covered.append(flat)
        else:
            area = np.zeros(len(self.possible_agents))
            for i, (pose, scan) in enumerate(zip(state.true_poses, state.scans, strict=True)):
                before = self._observed[i].copy()
                new_cells = mark_scan_observed(
                    self._observed[i],
                    grid.origin[0],
                    grid.origin[1],
                    grid.resolution,
                    pose[0],
                    pose[1],
                    pose[2],
                    scan,
                )
                area[i] = new_cells * grid.resolution**2
                newly_covered.append(np.flatnonzero(self._observed[i] & ~before))
            self._observed_area += area
        cell_area = grid.resolution**2
        team = self._team_observed.reshape(-1)  # a view
        team_before = [team[flat] for flat in newly_covered]  # before any robot's update
        for i, (flat, known) in enumerate(zip(newly_covered, team_before, strict=True)):
            self._team_new_area[i] = float(len(flat) - np.count_nonzero(known)) * cell_area
            team[flat] = True
        self._new_area = area
        return area

    def _update_slam(self, state: SimState) -> NDArray[np.float64]:
        """One SLAM update per robot; the area (m²) of the cells of its map that are known
        (FREE or OCCUPIED) for the first time this episode. A cell that turns back to
        unknown (log-odds drifting back over the thresholds) and known again pays once,
        so the reward is never negative without a collision."""
        assert self._sim is not None
        ground_truth = self.config.slam is not None and self.config.slam.mode == "ground_truth"
        area = np.zeros(len(self._slams))
        self._newly_known_world_cells = []
        for i, slam in enumerate(self._slams):
            grid = slam.grid
            true_pose_in_map = None
            if ground_truth:
                true_pose_in_map = compose(inverse(self._sim.starts[i]), state.true_poses[i])
            integrated = slam.n_integrated
            slam.update(state.odometry[i], self._scan_without_peers(state, i), true_pose_in_map)
            if slam.n_integrated == integrated:  # no scan integrated: the map is as it was
                self._newly_known_world_cells.append(np.empty((0, 2), dtype=np.int64))
                continue
            ever = self._ever_known_aligned(i, slam.grid)
            config = grid.config
            # ``ever`` holds every cell known before this scan: only the cells it wrote
            # can be new.
            candidates = slam.grid.last_written if slam.n_integrated == integrated + 1 else None
            cells = mark_newly_known(
                slam.grid.log_odds,
                ever,
                config.free_threshold,
                config.occupied_threshold,
                candidates,
            )
            grid = slam.grid
            area[i] = len(cells) * grid.resolution**2
            self._observed_area[i] = grid.known_cells * grid.resolution**2
            self._newly_known_world_cells.append(self._map_cells_to_coverage(i, grid, cells))
        return area

    def _ever_known_aligned(self, i: int, grid: Any) -> NDArray[np.bool_]:
        """Robot ``i``'s 'ever known' mask, grown with its SLAM grid (same shape and
        origin)."""
        origin = (
            round(grid.origin[1] / grid.resolution),
            round(grid.origin[0] / grid.resolution),
        )
        if i == len(self._ever_known):
            self._ever_known.append((origin, np.zeros(grid.shape, dtype=bool)))
        old_origin, mask = self._ever_known[i]
        if old_origin != origin or mask.shape != grid.shape:
            grown = np.zeros(grid.shape, dtype=bool)
            dy, dx = old_origin[0] - origin[0], old_origin[1] - origin[1]
            grown[dy : dy + mask.shape[0], dx : dx + mask.shape[1]] = mask
            mask = grown
            self._ever_known[i] = (origin, mask)
        return mask

    def _map_cells_to_coverage(
        self, i: int, grid: Any, cells: NDArray[np.int64]
    ) -> NDArray[np.int64]:
        """Cells ``(k, 2)`` of robot ``i``'s map as cells of the world-frame coverage grid
        (through its true start pose: privileged), those outside dropped."""
        assert self._sim is not None
        if len(cells) == 0:
            return np.empty((0, 2), dtype=np.int64)
        points = grid.cell_to_world(cells)
        x, y, theta = self._sim.starts[i]
        c, s = np.cos(theta), np.sin(theta)
        world = np.column_stack(
            [x + c * points[:, 0] - s * points[:, 1], y + s * points[:, 0] + c * points[:, 1]]
        )
        coverage = self._coverage_template
        out = coverage.world_to_cell(world)
        return np.asarray(out[coverage.contains(out)], dtype=np.int64)

    def _scan_without_peers(self, state: SimState, robot: int) -> NDArray[np.float64]:
        """The scan SLAM integrates: returns from the robots the peer sensor detects are
        dropped (a robot is not part of the static map, and touching robots would pull
        the scan match). The ``scan`` observation itself is left whole."""
        points = sighted_positions(state.peers[robot])
        if len(points) == 0:
            return state.scans[robot]
        radius = self.config.robot.radius + PEER_MASK_MARGIN
        return mask_returns_near(state.scans[robot], points, radius, self.config.lidar.max_range)

    def _observations(self, state: SimState) -> dict[AgentID, Any]:
        """Every live robot's observation; the ``Dict`` ones of all robots are kept for
        :meth:`state`."""
        observations: dict[AgentID, ObsDict] = {}
        flat = self.config.flat_observation
        for i, agent in enumerate(self.possible_agents):
            observation = {
                "scan": state.scans[i].astype(np.float32),
                "odom": state.odometry[i].copy(),
                "peer": state.peers[i].copy(),
                "comm": state.comm[i].astype(np.int8),
            }
            if self._slams:
                observation["pose"] = self._slams[i].pose
                if flat or agent not in self._unread_local_maps:
                    observation["local_map"] = self._local_map(i)
            observations[agent] = observation
        self._dict_observations = observations
        live = [agent for agent in self.possible_agents if agent in self.agents]
        if self.config.flat_observation:
            return {agent: self._flattener(observations[agent]) for agent in live}
        return {agent: observations[agent] for agent in live}

    def _local_map(self, i: int) -> NDArray[np.uint8]:
        """Robot ``i``'s ``local_map`` observation: the crop of its SLAM map at its pose."""
        slam = self._slams[i]
        crop = self.config.local_map
        return local_map(slam.grid, slam.pose, crop.cells, crop.cell_size)

    def _infos(self, state: SimState) -> dict[AgentID, dict[str, Any]]:
        cell_area = self._coverage_template.resolution**2
        observable = max(self._observable_area, 1e-12)
        team_area = (float(self._team_observed.sum()) - self._unobservable_cells) * cell_area
        infos = {}
        for i, agent in enumerate(self.possible_agents):
            if agent not in self.agents:
                continue
            info: dict[str, Any] = {
                "collision": bool(state.collisions[i]),
                "observed_area": float(self._observed_area[i]),
                "new_area": float(self._new_area[i]),
            }
            if self.config.privileged:  # ground truth only when asked for
                own_area = (float(self._observed[i].sum()) - self._unobservable_cells) * cell_area
                true_pose = state.true_poses[i].copy()
                privileged = {
                    "true_pose": true_pose.copy(),
                    "covered_area": own_area,
                    "coverage": own_area / observable,
                    "team_covered_area": team_area,
                    "team_coverage": team_area / observable,
                    "team_new_area": float(self._team_new_area[i]),
                }
                info = {"true_pose": true_pose, **info, "privileged": privileged}
            infos[agent] = info
        return infos

    def _set_world(self, scenario: str | WorldSpec, keep: bool = False) -> None:
        """Switch to another world (for the next episodes); ``keep`` leaves
        ``self.scenario`` (the family a random layout is drawn from) as it is."""
        if not keep:
            self.scenario = scenario
        self.world = scenario if isinstance(scenario, WorldSpec) else build_world(scenario)
        self._coverage_template = ground_truth_map(
            self.world, self.config.reward.coverage_resolution, margin=1.0
        )
        self._render_base = None

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

    def render(self, render_mode: str | None = None) -> NDArray[np.uint8] | None:
        """``"rgb_array"``: a top-down ``(H, W, 3)`` uint8 image (y up) of walls, robots
        and scans. ``"human"``: the same image in a matplotlib window (returns None);
        without a display or matplotlib it warns once and draws nothing.

        ``render_mode`` is there for RLlib's ``ParallelPettingZooEnv.render``, which
        passes its own (None): None or the env's mode; the env's mode is used either way.

        Raises
        ------
        ValueError
            For another ``render_mode`` (the mode is chosen when the env is made).
        """
        if render_mode not in (None, self.render_mode):
            raise ValueError(
                f"render_mode is chosen when the env is made ({self.render_mode!r}), "
                f"got {render_mode!r}"
            )
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; returning None")
            return None
        if self._sim is None:
            raise RuntimeError("render() called before reset()")
        frame = self._frame()
        if self.render_mode == "human":
            self._show(frame)
            return None
        return frame

    def _show(self, frame: NDArray[np.uint8]) -> None:
        if self._window is None:
            self._window = False
            has_display = sys.platform in ("darwin", "win32") or bool(
                os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
            )
            try:
                if not has_display:
                    raise ImportError("no display")
                import matplotlib.pyplot as plt

                plt.ion()
                figure, axes = plt.subplots()
                axes.set_axis_off()
                self._window = (plt, figure, axes.imshow(frame))
            except Exception as error:  # no display, no matplotlib, no GUI backend
                gymnasium.logger.warn(f"render_mode='human' cannot open a window ({error})")
        if self._window:
            plt, figure, image = self._window
            image.set_data(frame)
            figure.canvas.draw_idle()
            plt.pause(1.0 / self.metadata["render_fps"])

    def _frame(self) -> NDArray[np.uint8]:
        assert self._sim is not None
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
        if self._window:
            plt, figure, _ = self._window
            plt.close(figure)
        self._window = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_window"] = None  # a GUI window does not pickle
        return state


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


def checked_options(options: Any) -> dict[str, Any]:
    """``reset``'s ``options`` (any mapping: a dict, ``types.MappingProxyType``, ...) as a
    dict of the :data:`RESET_OPTIONS` keys.

    Raises
    ------
    ValueError
        For a key that is not one of :data:`RESET_OPTIONS` (a misspelled option would
        otherwise change nothing, silently), or options that are not a mapping.
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise ValueError(f"reset options must be a mapping or None, got {options!r}")
    unknown = [key for key in options if key not in (*RESET_OPTIONS, PETTINGZOO_PROBE_OPTION)]
    if unknown:
        raise ValueError(
            f"unknown reset option {', '.join(repr(key) for key in unknown)}; "
            f"the options are {', '.join(repr(key) for key in RESET_OPTIONS)}"
        )
    return {key: value for key, value in options.items() if key in RESET_OPTIONS}


def observable_cells(grid: GridMap, starts: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Cells a robot could ever observe: the free space connected to any start, plus the
    wall cells bordering it (8-connected)."""
    labels, _ = ndimage.label(grid.free)
    cells = grid.world_to_cell(starts[:, :2])
    inside = grid.contains(cells)
    start_labels = labels[cells[inside, 0], cells[inside, 1]]
    region = np.isin(labels, start_labels[start_labels > 0])
    return ndimage.binary_dilation(region, structure=np.ones((3, 3), dtype=bool))


def parametric_family(scenario: str | WorldSpec) -> str | None:
    """The parametric scenario family a name belongs to (``"procedural-7"`` ->
    ``"procedural"``), or None."""
    if not isinstance(scenario, str):
        return None
    catalogue = available_scenarios()
    family, _, suffix = scenario.rpartition("-")
    for name in (scenario, family if suffix.isdigit() else ""):
        if name in catalogue and catalogue[name].parametric:
            return name
    return None


def random_starts(
    world: WorldSpec, config: EnvConfig, rng: np.random.Generator
) -> tuple[tuple[float, float, float], ...]:
    """A random start for robot 0 (a start cell reachable from the world's first start,
    uniform heading); the others are then automatic starts."""
    candidates = world_start_points(world, config.robot.radius, world.starts[0][:2])
    if len(candidates) == 0:
        x, y, theta = (float(v) for v in world.starts[0])
        return ((x, y, theta),)
    x, y = candidates[int(rng.integers(len(candidates)))]
    return ((float(x), float(y), float(rng.uniform(-np.pi, np.pi))),)


def checked_env_options(options: Mapping[str, Any]) -> None:
    """Refuse constructor keywords that :class:`MultiRobotSlamEnv` does not take, all of
    them named in one line with the known ones (a misspelling such as ``privilaged``
    would otherwise be Python's error naming only the first).

    Raises
    ------
    TypeError
        As Python does for an unexpected keyword argument.
    """
    known = list(inspect.signature(MultiRobotSlamEnv.__init__).parameters)[1:]
    unknown = [key for key in options if key not in known]
    if unknown:
        raise TypeError(
            f"unknown env option {', '.join(repr(key) for key in unknown)}; "
            f"the options are {', '.join(repr(key) for key in known)}"
        )


def parallel_env(**kwargs: Any) -> MultiRobotSlamEnv:
    """Create the parallel environment; arguments as :class:`MultiRobotSlamEnv`."""
    checked_env_options(kwargs)
    return MultiRobotSlamEnv(**kwargs)


def env(**kwargs: Any) -> pettingzoo.AECEnv[AgentID, ObsDict, NDArray[np.float32]]:
    """The same environment through PettingZoo's AEC interface."""
    return conversions.parallel_to_aec(parallel_env(**kwargs))


if ENV_ID not in pettingzoo.parallel_registry:
    pettingzoo.register("parallel", ENV_ID, entry_point="mrslam_env.env:parallel_env")
    pettingzoo.register("aec", ENV_ID, entry_point="mrslam_env.env:env")


class _CallableModule(types.ModuleType):
    """``mrslam_env.env`` is both this module and the AEC constructor: once the module is
    imported, ``from mrslam_env import env`` finds the module (Python sets the package
    attribute), and calling it builds the AEC env (as PettingZoo's ``max_cycles_test``
    and ``api_test`` expect of ``mrslam_env.env(...)``)."""

    def __call__(self, **kwargs: Any) -> pettingzoo.AECEnv[AgentID, ObsDict, NDArray[np.float32]]:
        return env(**kwargs)


sys.modules[__name__].__class__ = _CallableModule
