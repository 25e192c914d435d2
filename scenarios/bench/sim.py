"""Benchmarks behind ``mrslam bench``: medians over repeats, side by side with a peer.

``mrslam bench sim`` times env steps (two robots with 360-beam lidars, random-ish driving)
on every scenario, with onboard SLAM off (the simulator alone) and on, and the simulator's
work in IR-SIM in the same run. ``mrslam bench sim --rl`` times the configurations a
training run uses (:func:`bench_rl`): agent-steps/s of the parallel env (``Dict`` or flat
observation, SLAM off or on), of the single-robot env with a scripted teammate, of two of
those in a Gymnasium ``AsyncVectorEnv``, and the frontier teammate's own time per step.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.sim.world import WorldSpec

__all__ = [
    "RLBenchRow",
    "SimBenchRow",
    "TeammateTiming",
    "bench_rl",
    "bench_sim",
    "driving_commands",
    "env_steps_per_second",
    "single_robot_steps_per_second",
    "teammate_timing",
    "vector_steps_per_second",
]


@dataclass(frozen=True, slots=True)
class SimBenchRow:
    scenario: str
    mrslam_steps_per_s: float
    """Env steps/s with onboard SLAM off (``EnvConfig.slam = None``): the simulator alone,
    the work IR-SIM does."""
    irsim_steps_per_s: float | None
    with_slam_steps_per_s: float | None = None
    """Env steps/s with onboard SLAM on for both robots (the env's default)."""

    @property
    def ratio(self) -> float | None:
        if self.irsim_steps_per_s is None or self.irsim_steps_per_s <= 0:
            return None
        return self.mrslam_steps_per_s / self.irsim_steps_per_s

    def as_dict(self) -> dict[str, object]:
        return {
            "scenario": self.scenario,
            "mrslam_steps_per_s": round(self.mrslam_steps_per_s, 1),
            "with_slam_steps_per_s": None
            if self.with_slam_steps_per_s is None
            else round(self.with_slam_steps_per_s, 1),
            "irsim_steps_per_s": None
            if self.irsim_steps_per_s is None
            else round(self.irsim_steps_per_s, 1),
        }


def driving_commands(n_steps: int, n_robots: int, seed: int = 0) -> np.ndarray:
    """A fixed, smooth command sequence (n_steps, n_robots, 2): mostly forward, weaving."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_steps)[:, None] * 0.1
    phase = rng.uniform(0, 2 * math.pi, (1, n_robots))
    speed = 0.8 + 0.2 * np.sin(0.3 * t + phase)
    turn = 0.6 * np.sin(0.5 * t + 2 * phase)
    return np.stack([speed, turn], axis=-1)


def env_steps_per_second(
    world: WorldSpec, *, n_steps: int = 1000, repeats: int = 3, config: EnvConfig | None = None
) -> float:
    """Median env steps per second over ``repeats`` episodes of ``n_steps`` (2 robots)."""
    config = config if config is not None else EnvConfig()
    config = replace(config, max_cycles=n_steps + 1)
    env = MultiRobotSlamEnv(scenario=world, seed=0, config=config)
    commands = driving_commands(n_steps, len(env.possible_agents))
    # An untimed warm-up: loads the compiled numba kernels and warms the caches.
    env.reset(seed=repeats)
    for k in range(min(n_steps, 100)):
        env.step({agent: commands[k, i] for i, agent in enumerate(env.possible_agents)})
    rates = []
    for repeat in range(repeats):
        env.reset(seed=repeat)
        agents = env.possible_agents
        started = time.perf_counter()
        for k in range(n_steps):
            env.step({agent: commands[k, i] for i, agent in enumerate(agents)})
        rates.append(n_steps / (time.perf_counter() - started))
    return statistics.median(rates)


def bench_sim(
    worlds: dict[str, WorldSpec], *, n_steps: int = 1000, repeats: int = 3, irsim: bool = True
) -> list[SimBenchRow]:
    """One row per world: our env steps/s without and with onboard SLAM and, if ``irsim``,
    IR-SIM's on the same world."""
    rows = []
    for name, world in worlds.items():
        ours = env_steps_per_second(
            world, n_steps=n_steps, repeats=repeats, config=EnvConfig(slam=None)
        )
        with_slam = env_steps_per_second(world, n_steps=n_steps, repeats=repeats)
        theirs = None
        if irsim:
            from scenarios.bench.irsim import irsim_steps_per_second

            theirs = irsim_steps_per_second(world, n_steps=max(n_steps // 5, 50), repeats=repeats)
        rows.append(SimBenchRow(name, ours, theirs, with_slam))
    return rows


# --- the RL configurations -------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RLBenchRow:
    """Throughput of one RL configuration: agent-steps/s (one learner action each) and env
    steps/s, medians over repeats."""

    configuration: str
    agent_steps_per_s: float
    env_steps_per_s: float

    def as_dict(self) -> dict[str, object]:
        return {
            "configuration": self.configuration,
            "agent_steps_per_s": round(self.agent_steps_per_s, 1),
            "env_steps_per_s": round(self.env_steps_per_s, 1),
        }


@dataclass(frozen=True, slots=True)
class TeammateTiming:
    """The frontier explorer as a scripted teammate: its own time per step
    (``ExplorerPolicy.act``) and the time to read its SLAM map (``env.robot_map``), ms,
    medians over repeats."""

    explorer_ms_per_step: float
    robot_map_ms_per_step: float
    replans_per_100_steps: float

    def as_dict(self) -> dict[str, object]:
        return {
            "explorer_ms_per_step": round(self.explorer_ms_per_step, 3),
            "robot_map_ms_per_step": round(self.robot_map_ms_per_step, 3),
            "replans_per_100_steps": round(self.replans_per_100_steps, 2),
        }


def single_robot_steps_per_second(
    scenario: str, *, teammates: str = "frontier", n_steps: int = 1000, repeats: int = 3
) -> float:
    """Median steps/s of the single-robot Gymnasium env (``robot_0`` driven by
    :func:`driving_commands`, one scripted teammate, onboard SLAM on)."""
    from agents.single_robot import SingleRobotEnv

    env = SingleRobotEnv(scenario=scenario, teammates=teammates, max_cycles=n_steps + 101)
    commands = driving_commands(n_steps, 1)[:, 0].astype(np.float32)
    return _median_rate(env, commands, n_steps, repeats, learners=1)


def vector_steps_per_second(
    scenario: str, *, processes: int = 2, n_steps: int = 500, repeats: int = 3
) -> float:
    """Median learner steps/s (summed over the sub-envs) of a Gymnasium ``AsyncVectorEnv``
    of ``processes`` single-robot envs, each with one frontier teammate."""
    import functools

    import gymnasium

    from mrslam_env.wrappers import SINGLE_ROBOT_ID

    make = functools.partial(
        gymnasium.make,
        SINGLE_ROBOT_ID,
        scenario=scenario,
        teammates="frontier",
        max_cycles=n_steps + 101,
        disable_env_checker=True,
    )
    vector = gymnasium.vector.AsyncVectorEnv([make] * processes)
    commands = driving_commands(n_steps, processes).astype(np.float32)
    return _median_rate(vector, commands, n_steps, repeats, learners=processes)


def _median_rate(
    env: Any, commands: NDArray[np.float32], n_steps: int, repeats: int, *, learners: int
) -> float:
    """Median learner steps/s of ``env`` (a Gymnasium env or vector env, closed after):
    up to 100 warm-up steps, then ``repeats`` timed runs of ``n_steps`` from resets seeded
    0, 1, ..."""
    env.reset(seed=repeats)
    for k in range(min(n_steps, 100)):
        env.step(commands[k])
    rates = []
    for repeat in range(repeats):
        env.reset(seed=repeat)
        started = time.perf_counter()
        for k in range(n_steps):
            env.step(commands[k])
        rates.append(learners * n_steps / (time.perf_counter() - started))
    env.close()
    return statistics.median(rates)


def teammate_timing(scenario: str, *, n_steps: int = 1000, repeats: int = 3) -> TeammateTiming:
    """Time :class:`agents.explorer.ExplorerPolicy` as ``robot_1``'s scripted policy while
    ``robot_0`` follows :func:`driving_commands` (onboard SLAM on): the work the
    single-robot env's frontier teammate does each step."""
    from agents.explorer import ExplorerPolicy

    config = replace(EnvConfig(), max_cycles=n_steps + 1)
    env = MultiRobotSlamEnv(scenario=scenario, config=config)
    commands = driving_commands(n_steps, 1)[:, 0]
    explorer_ms, map_ms, replans = [], [], []
    for repeat in range(repeats + 1):  # the first is a warm-up
        observations, _ = env.reset(seed=repeat)
        explorer = ExplorerPolicy.for_env(env.config, np.random.default_rng(repeat))
        acting = reading = 0.0
        for k in range(n_steps):
            started = time.perf_counter()
            robot_map = env.robot_map("robot_1")
            read = time.perf_counter()
            action = explorer.act(observations["robot_1"], robot_map)
            reading += read - started
            acting += time.perf_counter() - read
            observations, *_ = env.step({"robot_0": commands[k], "robot_1": action})
        if repeat:
            explorer_ms.append(1000 * acting / n_steps)
            map_ms.append(1000 * reading / n_steps)
            replans.append(100 * explorer.replans / n_steps)
    return TeammateTiming(
        statistics.median(explorer_ms), statistics.median(map_ms), statistics.median(replans)
    )


def bench_rl(
    scenario: str = "office",
    *,
    n_steps: int = 1000,
    repeats: int = 3,
) -> tuple[list[RLBenchRow], TeammateTiming]:
    """Agent-steps/s of the RL configurations on one scenario (two robots, 360 beams).

    Rows: the parallel env with the ``Dict`` or the flat observation, onboard SLAM off or
    on (an agent-step is one robot's action: env steps/s x 2); the single-robot env with
    one idle and with one frontier teammate (SLAM on; the learner's steps); two
    single-robot envs with frontier teammates in a Gymnasium ``AsyncVectorEnv`` of two
    processes (learner steps summed). Plus the frontier teammate's own time per step.
    """
    from mrslam_env.registry import build_world

    world = build_world(scenario)
    rows = []
    for label, config in (
        ("parallel, Dict, SLAM off", EnvConfig(slam=None)),
        ("parallel, Dict, SLAM on", EnvConfig()),
        ("parallel, flat, SLAM off", EnvConfig(slam=None, flat_observation=True)),
        ("parallel, flat, SLAM on", EnvConfig(flat_observation=True)),
    ):
        rate = env_steps_per_second(world, n_steps=n_steps, repeats=repeats, config=config)
        rows.append(RLBenchRow(label, 2 * rate, rate))
    for teammates in ("idle", "frontier"):
        rate = single_robot_steps_per_second(
            scenario, teammates=teammates, n_steps=n_steps, repeats=repeats
        )
        rows.append(RLBenchRow(f"single-robot env, 1 {teammates} teammate, SLAM on", rate, rate))
    rate = vector_steps_per_second(scenario, n_steps=max(n_steps // 2, 1), repeats=repeats)
    rows.append(RLBenchRow("AsyncVectorEnv, 2 processes x single-robot env (frontier)", rate, rate))
    return rows, teammate_timing(scenario, n_steps=n_steps, repeats=repeats)
