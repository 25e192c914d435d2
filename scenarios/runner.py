"""The experiment runner behind ``mrslam run``.

For now (foundation): robots wander with :class:`agents.wander.WanderPolicy` and the run is
recorded; the full experiment (SLAM, map merging, rendezvous, coordinated exploration)
replaces the policy in later issues.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.wander import WanderPolicy
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.mapio import load_map
from mrslam_env.recording import Recorder
from mrslam_env.sim.mapworld import world_from_map
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from mrslam_env.worlds import build_world

__all__ = ["RunConfig", "resolve_world", "run_experiment"]


@dataclass(frozen=True, slots=True, kw_only=True)
class RunConfig:
    """One ``mrslam run``."""

    scenario: str = "office"
    """Scenario name; ignored when ``map_path`` is given."""
    map_path: Path | None = None
    """A ROS map YAML to build the world from."""
    seed: int = 0
    max_steps: int = 2000
    """Env steps (0.1 s each by default)."""
    out: Path = Path("runs")
    """Parent folder of the run folder."""
    name: str | None = None
    """Run folder name; defaults to ``<scenario>-seed<seed>``."""
    record: bool = True
    """Write ``recording.rrd``."""
    scan_every: int = 5
    """Log lidar scans every this many steps (poses are logged every step)."""
    progress: bool = True

    def __post_init__(self) -> None:
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.scan_every < 1:
            raise ValueError(f"scan_every must be >= 1, got {self.scan_every}")


def resolve_world(scenario: str, map_path: Path | None, seed: int = 0) -> WorldSpec:
    """The world of a scenario name, or of a ROS map file when one is given."""
    if map_path is None:
        return build_world(scenario)
    grid = load_map(map_path)
    return world_from_map(grid, name=f"map:{Path(map_path).name}", rng=np.random.default_rng(seed))


@contextmanager
def _progress(total: int, enabled: bool) -> Iterator[Any]:
    from tqdm import tqdm

    bar = tqdm(total=total, disable=not enabled, unit="step", desc="mrslam run", leave=False)
    try:
        yield bar
    finally:
        bar.close()


def run_experiment(config: RunConfig) -> dict[str, Any]:
    """Run one experiment, write its outputs, return the report (also ``report.json``)."""
    world = resolve_world(config.scenario, config.map_path, config.seed)
    name = config.name or f"{world.name.replace(':', '_')}-seed{config.seed}"
    run_dir = Path(config.out) / name
    run_dir.mkdir(parents=True, exist_ok=True)
    env_config = EnvConfig(max_cycles=config.max_steps)
    env = MultiRobotSlamEnv(scenario=world, seed=config.seed, config=env_config)
    observations, infos = env.reset()
    agents = list(env.possible_agents)
    policies = {
        agent: WanderPolicy(env_config.lidar.n_beams, np.random.default_rng([config.seed, i]))
        for i, agent in enumerate(agents)
    }
    recorder = Recorder(run_dir / "recording.rrd", n_robots=len(agents)) if config.record else None
    started = time.perf_counter()
    collisions = dict.fromkeys(agents, 0)
    distance = dict.fromkeys(agents, 0.0)
    comm_steps = 0
    last_link: bool | None = None
    last_seen = dict.fromkeys(agents, False)
    steps = 0
    if recorder is not None:
        recorder.log_ground_truth(world, ground_truth_map(world, 0.05))
        recorder.log_event(
            f"run {name}: world {world.name}, {len(agents)} robots, seed {config.seed}"
        )
    previous = {agent: infos[agent]["true_pose"] for agent in agents}
    with _progress(config.max_steps, config.progress) as bar:
        while env.agents:
            actions = {
                agent: policies[agent].act(observations[agent]["scan"]) for agent in env.agents
            }
            observations, _rewards, _terms, _truncs, infos = env.step(actions)
            steps += 1
            bar.update(1)
            link = bool(observations[agents[0]]["comm"].any()) if len(agents) > 1 else False
            comm_steps += link
            for agent in agents:
                pose = infos[agent]["true_pose"]
                distance[agent] += float(np.hypot(*(pose[:2] - previous[agent][:2])))
                previous[agent] = pose
                collisions[agent] += infos[agent]["collision"]
            if recorder is None:
                continue
            recorder.set_time(steps, steps * env_config.dt)
            if link != last_link and len(agents) > 1:
                recorder.log_event(f"comm link robot_0 <-> robot_1 {'up' if link else 'down'}")
                last_link = link
            for i, agent in enumerate(agents):
                recorder.log_true_pose(i, infos[agent]["true_pose"])
                if steps % config.scan_every == 0:
                    recorder.log_scan(
                        i,
                        infos[agent]["true_pose"],
                        observations[agent]["scan"],
                        env.simulator.beam_angles,
                        env_config.lidar.max_range,
                    )
                seen = bool(observations[agent]["peer"][:, 0].any())
                if seen and not last_seen[agent]:
                    recorder.log_event(f"{agent} detects another robot")
                last_seen[agent] = seen
                recorder.log_scalar(
                    f"coverage/{agent}", infos[agent]["observed_area"] / env.observable_area
                )
    wall_time = time.perf_counter() - started
    report: dict[str, Any] = {
        "scenario": world.name,
        "seed": config.seed,
        "steps": steps,
        "sim_time": round(steps * env_config.dt, 6),
        "wall_time": round(wall_time, 3),
        "observable_area": round(env.observable_area, 3),
        "comm_up_fraction": round(comm_steps / max(steps, 1), 4),
        "robots": {
            agent: {
                "observed_area": round(infos[agent]["observed_area"], 3),
                "coverage": round(infos[agent]["observed_area"] / env.observable_area, 4),
                "collision_steps": int(collisions[agent]),
                "distance": round(distance[agent], 3),
            }
            for agent in agents
        },
        "outputs": {"run_dir": str(run_dir)},
    }
    if recorder is not None:
        recorder.log_event(f"run finished after {steps} steps")
        recorder.close()
        report["outputs"]["recording"] = str(run_dir / "recording.rrd")
    (run_dir / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
