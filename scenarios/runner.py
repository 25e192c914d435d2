"""The experiment runner behind ``mrslam run``.

For now: robots wander with :class:`agents.wander.WanderPolicy`, each mapping with its
onboard SLAM; the run is recorded and each robot's final map saved as a ROS map file. The
full experiment (map merging, rendezvous, coordinated exploration) replaces the policy in
later issues.
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
from mrslam_env.geometry import transform_points
from mrslam_env.mapio import load_map, save_map
from mrslam_env.recording import Recorder
from mrslam_env.sim.mapworld import world_from_map
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from mrslam_env.slam.evaluation import map_agreement
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
    map_every: int = 10
    """Log a robot's map (when it changed), path and ATE every this many steps."""
    progress: bool = True

    def __post_init__(self) -> None:
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        for name in ("scan_every", "map_every"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")


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


def _squared_error(world_from_map: np.ndarray, pose_in_map: np.ndarray, true_pose) -> float:
    """Squared position error (m²) of a SLAM pose against the truth."""
    estimate = transform_points(world_from_map, pose_in_map[None, :2])[0]
    return float(np.sum((estimate - np.asarray(true_pose)[:2]) ** 2))


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
    recorder = (
        Recorder(run_dir / "recording.rrd", n_robots=len(agents), map_every=config.map_every)
        if config.record
        else None
    )
    # The map frame of robot i is its start pose: that is how its SLAM is judged.
    world_from_maps = env.simulator.starts.copy()
    squared_errors = np.zeros(len(agents))
    logged_scans = [-1] * len(agents)
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
    for i, agent in enumerate(agents):
        squared_errors[i] += _squared_error(
            world_from_maps[i], observations[agent]["pose"], infos[agent]["true_pose"]
        )
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
            for i, agent in enumerate(agents):
                pose = infos[agent]["true_pose"]
                distance[agent] += float(np.hypot(*(pose[:2] - previous[agent][:2])))
                previous[agent] = pose
                collisions[agent] += infos[agent]["collision"]
                squared_errors[i] += _squared_error(
                    world_from_maps[i], observations[agent]["pose"], pose
                )
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
                recorder.log_robot_pose(i, observations[agent]["pose"])
                if recorder.map_due or not env.agents:
                    slam = env.robot_slam(agent)
                    recorder.log_robot_path(i, slam.trajectory)
                    recorder.log_scalar(f"ate/{agent}", np.sqrt(squared_errors[i] / (steps + 1)))
                    if slam.n_integrated != logged_scans[i]:
                        recorder.log_grid(f"{agent}/map", env.robot_map(agent))
                        logged_scans[i] = slam.n_integrated
    wall_time = time.perf_counter() - started
    maps = {agent: run_dir / f"{agent}.yaml" for agent in agents}
    for agent, path in maps.items():
        save_map(path, env.robot_map(agent))
    truth = ground_truth_map(world, env.robot_map(agents[0]).resolution)
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
        "slam": {
            agent: {
                "ate": round(float(np.sqrt(squared_errors[i] / (steps + 1))), 4),
                "map_agreement": round(
                    map_agreement(env.robot_map(agent), world_from_maps[i], truth), 4
                ),
            }
            for i, agent in enumerate(agents)
        },
        "outputs": {"run_dir": str(run_dir), "maps": {a: str(p) for a, p in maps.items()}},
    }
    if recorder is not None:
        recorder.log_event(f"run finished after {steps} steps")
        recorder.close()
        report["outputs"]["recording"] = str(run_dir / "recording.rrd")
    (run_dir / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    return report
