"""The single-robot Gymnasium env: ``robot_0`` of the multi-robot env learns, its
teammates run a scripted policy (registered as ``"mrslam/SingleRobot-v0"`` by
:mod:`mrslam_env.wrappers`; the flat observation is documented there)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from agents.explorer import ExplorerPolicy
from agents.wander import WanderPolicy
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.sim.world import WorldSpec
from mrslam_env.wrappers import TEAMMATES, ObservationFlattener

__all__ = ["SingleRobotEnv"]

Float32Array = NDArray[np.float32]


TeammateAct = Callable[[dict[str, NDArray[Any]]], NDArray[np.float32]]


def _teammate(
    kind: str, env: MultiRobotSlamEnv, agent: str, rng: np.random.Generator
) -> TeammateAct:
    """One scripted teammate: ``act(observation) -> action``."""
    if kind == "idle":
        return lambda observation: np.zeros(2, dtype=np.float32)
    if kind == "wander":
        wander = WanderPolicy.for_env(env.config, rng)
        return lambda observation: wander.act(observation["scan"])
    explorer = ExplorerPolicy.for_env(env.config, rng)
    if env.config.slam is not None:
        return lambda observation: explorer.act(observation, env.robot_map(agent))
    return _own_slam_explorer(explorer, env)


def _own_slam_explorer(explorer: Any, env: MultiRobotSlamEnv) -> TeammateAct:
    """A frontier teammate for an env with onboard SLAM off: it runs its own
    :class:`~mrslam_env.slam.slam.RobotSlam` (default :class:`SlamConfig`) on its ``odom``
    and ``scan`` observations (peer returns masked, as the env does), and explores that
    map from that pose. No ground truth is involved."""
    from mrslam_env.env import PEER_MASK_MARGIN
    from mrslam_env.slam.config import SlamConfig
    from mrslam_env.slam.scan import mask_returns_near, sighted_positions
    from mrslam_env.slam.slam import RobotSlam

    lidar = env.config.lidar
    slam = RobotSlam(SlamConfig(), lidar.n_beams, lidar.max_range)
    radius = env.config.robot.radius + PEER_MASK_MARGIN

    def act(observation: dict[str, NDArray[Any]]) -> NDArray[np.float32]:
        scan = np.asarray(observation["scan"], dtype=np.float64)
        points = sighted_positions(observation["peer"])
        if len(points):
            scan = mask_returns_near(scan, points, radius, lidar.max_range)
        slam.update(observation["odom"], scan)
        mine = dict(observation, pose=slam.pose)
        return np.asarray(explorer.act(mine, slam.grid.to_gridmap()), dtype=np.float32)

    return act


class SingleRobotEnv(gymnasium.Env[Float32Array, Float32Array]):
    """``robot_0`` of :class:`~mrslam_env.env.MultiRobotSlamEnv` as a Gymnasium env.

    Parameters
    ----------
    scenario, n_robots, config, max_cycles, privileged
        As :class:`~mrslam_env.env.MultiRobotSlamEnv` (``config.flat_observation`` is
        ignored: the teammates need the ``Dict`` observation, the learner gets the flat
        one; ground truth is in the infos only with ``privileged=True``).
    teammates : {"frontier", "wander", "idle"}
        The scripted policy of ``robot_1 ... robot_{n-1}``.
    render_mode : None or "rgb_array"

    Raises
    ------
    ValueError
        For an unknown ``teammates``.

    A ``"frontier"`` teammate explores its onboard-SLAM map (``env.robot_map``); with
    onboard SLAM off (``config.slam = None``) it runs a SLAM of its own on its ``odom``
    and ``scan`` observations, so it never sees ground truth either way.

    Observation ``Box`` of the flat layout (module notes), action ``Box(-1, 1, (2,))``,
    reward and infos those of ``robot_0``; never terminates, truncates after
    ``max_cycles`` steps. Deterministic for a given ``reset`` seed (teammates included).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}  # noqa: RUF012

    def __init__(
        self,
        scenario: str | WorldSpec = "office",
        n_robots: int = 2,
        teammates: str = "wander",
        config: EnvConfig | None = None,
        max_cycles: int | None = None,
        render_mode: str | None = None,
        privileged: bool | None = None,
    ) -> None:
        if teammates not in TEAMMATES:
            raise ValueError(f"teammates must be one of {TEAMMATES}, got {teammates!r}")
        config = config if config is not None else EnvConfig()
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        self.multi = MultiRobotSlamEnv(
            scenario=scenario,
            n_robots=n_robots,
            render_mode=render_mode,
            config=replace(config, flat_observation=False),
            max_cycles=max_cycles,
            privileged=privileged,
        )
        self.teammates = teammates
        self.render_mode = render_mode
        self.agent = self.multi.possible_agents[0]
        # No scripted teammate reads its egocentric crop: the env skips it.
        self.multi.omit_local_map(self.multi.possible_agents[1:])
        self.flattener = ObservationFlattener(self.multi.config, n_robots)
        self.observation_space = self.flattener.space
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._policies: dict[str, TeammateAct] = {}
        self._observations: dict[str, dict[str, NDArray[Any]]] = {}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Float32Array, dict[str, Any]]:
        super().reset(seed=seed)
        inner_seed = int(self.np_random.integers(2**31))
        observations, infos = self.multi.reset(seed=inner_seed, options=options)
        rngs = np.random.default_rng(inner_seed).spawn(len(self.multi.possible_agents))
        self._policies = {
            agent: _teammate(self.teammates, self.multi, agent, rng)
            for agent, rng in zip(self.multi.possible_agents[1:], rngs[1:], strict=True)
        }
        self._observations = observations
        return self.flattener(observations[self.agent]), infos[self.agent]

    def step(self, action: Float32Array) -> tuple[Float32Array, float, bool, bool, dict[str, Any]]:
        if not self._observations:
            raise RuntimeError("step() called before reset() or after the episode ended")
        actions: dict[str, Any] = {self.agent: action}
        for agent, act in self._policies.items():
            actions[agent] = act(self._observations[agent])
        observations, rewards, terminations, truncations, infos = self.multi.step(actions)
        self._observations = observations
        done = truncations[self.agent] or terminations[self.agent]
        flat = self.flattener(observations[self.agent])
        if done:
            self._observations = {}
        return (
            flat,
            rewards[self.agent],
            terminations[self.agent],
            truncations[self.agent],
            (infos[self.agent]),
        )

    def render(self) -> Any:  # the frame (H, W, 3) uint8, or None (Gymnasium's RenderFrame)
        return self.multi.render()

    def close(self) -> None:
        self.multi.close()
