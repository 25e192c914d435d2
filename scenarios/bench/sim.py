"""Benchmarks behind ``mrslam bench``: medians over repeats, side by side with a peer.

``mrslam bench sim`` times env steps (two robots with 360-beam lidars, random-ish driving)
on every scenario, with onboard SLAM off (the simulator alone) and on, and the simulator's
work in IR-SIM in the same run.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, replace

import numpy as np

from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.sim.world import WorldSpec

__all__ = ["SimBenchRow", "bench_sim", "driving_commands", "env_steps_per_second"]


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
