"""The onboard-SLAM benchmark behind ``mrslam bench slam``.

Per scenario: one seeded run of the env (two robots driven by
:class:`agents.wander.WanderPolicy`) with onboard SLAM in ``slam`` mode; afterwards each
robot's recorded ``odom`` and ``scan`` are replayed through a
:class:`~mrslam_env.slam.slam.RobotSlam` in ``odometry`` mode (dead reckoning on the same
data) and through one in ``slam`` mode to time single updates. Reported (means over the
robots, per-robot values alongside):

==================  ==============================================================
``ate_slam``        absolute trajectory error of SLAM, m (RMSE of positions; the map
                    frame is put in the world by the robot's true start pose)
``ate_odometry``    the same for dead reckoning
``ratio``           ``ate_slam / ate_odometry``
``map_agreement``   :func:`~mrslam_env.evaluation.map_agreement` of the SLAM map
                    with the ground-truth raster at the map's resolution
``update_ms``       median time of one SLAM update (one robot, one step), ms; also
                    ``update_mean_ms``
``steps_per_s``     env steps per second with onboard SLAM on for both robots (the env's
                    default): ``env.step`` is timed, which includes the SLAM updates and
                    the ``local_map`` crops (not the policy)
==================  ==============================================================

Targets (the SLAM issue): ``ate_slam <= 0.10`` m, ``ratio <= 1/3``, ``map_agreement >=
0.97``, ``steps_per_s >= 500``; on the real buildings (:data:`REAL_BUILDINGS`, rows of the
default run), ``ate_slam <= 0.05`` m and ``map_agreement >= 0.98``.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from agents.wander import WanderPolicy
from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.evaluation import absolute_trajectory_error, map_agreement
from mrslam_env.registry import build_world
from mrslam_env.sim.lidar import cast_scan
from mrslam_env.sim.world import box, ground_truth_map, polygon_edges
from mrslam_env.slam.config import SlamConfig
from mrslam_env.slam.slam import RobotSlam
from scenarios.worlds import real

__all__ = [
    "BUILT_IN_SCENARIOS",
    "DEFAULT_SCENARIOS",
    "REAL_BUILDINGS",
    "format_slam_table",
    "run_slam_benchmark",
    "warm_up",
]

BUILT_IN_SCENARIOS = ("office", "warehouse", "maze", "twin_wings", "procedural-0")
REAL_BUILDINGS = tuple(real.REAL_BUILDINGS)
"""Real buildings (maps of published simulation worlds)."""
DEFAULT_SCENARIOS = BUILT_IN_SCENARIOS + REAL_BUILDINGS


def warm_up(config: SlamConfig | None = None) -> None:
    """Run every SLAM kernel once (loading or compiling them) so that timings that follow
    measure work, not numba."""
    walls = [box(-3, -3, 3, -2.9), box(-3, 2.9, 3, 3), box(-3, -3, -2.9, 3), box(2.9, -3, 3, 3)]
    segments = polygon_edges(np.stack(walls))
    slam = RobotSlam(config, 360, 8.0)
    for k in range(3):
        x = 0.1 * k
        slam.update([x, 0.0, 0.0], cast_scan(x, 0.0, 0.0, 360, 8.0, segments, np.zeros((0, 3))))


def run_slam_benchmark(
    scenarios: Sequence[str] = DEFAULT_SCENARIOS,
    steps: int = 3000,
    seed: int = 0,
    *,
    config: SlamConfig | None = None,
    progress: Callable[[str, int], None] | None = None,
) -> list[dict[str, Any]]:
    """Benchmark onboard SLAM on each scenario; one row (dict) per scenario.

    Parameters
    ----------
    scenarios : sequence of str
        Scenario names (:func:`mrslam_env.registry.build_world`).
    steps : int
        Env steps per run.
    seed : int
        Seeds the env and the policies (``default_rng([seed, i])`` for robot i).
    config : SlamConfig, optional
        SLAM settings (its ``mode`` is overridden: ``slam`` and ``odometry`` both run).
    progress : callable (scenario, step) -> None, optional
        Called every 100 steps.

    Returns
    -------
    list of dict
        Keys as in the module docstring, plus ``scenario``, ``steps``, ``seed`` and the
        per-robot lists ``ate_slam_per_robot``, ``ate_odometry_per_robot``,
        ``map_agreement_per_robot``, ``rejected_matches``.
    """
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    base = config if config is not None else SlamConfig()
    slam_config = replace(base, mode="slam")
    odometry_config = replace(base, mode="odometry")
    warm_up(slam_config)
    return [
        _benchmark_scenario(name, steps, seed, slam_config, odometry_config, progress)
        for name in scenarios
    ]


def _benchmark_scenario(
    name: str,
    steps: int,
    seed: int,
    slam_config: SlamConfig,
    odometry_config: SlamConfig,
    progress: Callable[[str, int], None] | None,
) -> dict[str, Any]:
    """One row of :func:`run_slam_benchmark`: the env runs SLAM on board; the recorded
    odometry and scans are replayed afterwards to time single updates and to run the
    ``odometry`` mode on the same data."""
    world = build_world(name)
    config = EnvConfig(max_cycles=steps, slam=slam_config)
    env = MultiRobotSlamEnv(scenario=world, seed=seed, config=config, privileged=True)  # for ATE
    lidar = env.config.lidar
    observations, infos = env.reset(seed=seed)
    agents = list(env.possible_agents)
    policies = {
        agent: WanderPolicy(lidar.n_beams, np.random.default_rng([seed, i]))
        for i, agent in enumerate(agents)
    }
    recorded: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {agent: [] for agent in agents}
    truth: dict[str, list[np.ndarray]] = {agent: [] for agent in agents}
    stepping = 0.0
    for k in range(steps + 1):
        if k > 0:
            actions = {agent: policies[agent].act(observations[agent]["scan"]) for agent in agents}
            started = time.perf_counter()
            observations, _, _, _, infos = env.step(actions)
            stepping += time.perf_counter() - started
        for agent in agents:
            recorded[agent].append((observations[agent]["odom"], observations[agent]["scan"]))
            truth[agent].append(infos[agent]["true_pose"])
        if progress is not None and k > 0 and k % 100 == 0:
            progress(name, k)
    update_seconds: list[float] = []
    raster = ground_truth_map(world, slam_config.grid.resolution, margin=1.0)
    ate_slam, ate_odometry, agreement, rejected = [], [], [], []
    ate_graph, ate_graph_optimised, agreement_graph, closures = [], [], [], []
    graph_config = replace(slam_config, mode="pose_graph")
    for agent in agents:
        timed = RobotSlam(slam_config, lidar.n_beams, lidar.max_range)
        dead_reckoning = RobotSlam(odometry_config, lidar.n_beams, lidar.max_range)
        graph = RobotSlam(graph_config, lidar.n_beams, lidar.max_range)
        for k, (odom, scan) in enumerate(recorded[agent]):
            before = time.perf_counter()
            timed.update(odom, scan)
            if k > 0:
                update_seconds.append(time.perf_counter() - before)
            dead_reckoning.update(odom, scan)
            graph.update(odom, scan)
        slam = env.robot_slam(agent)
        true_poses = np.array(truth[agent])
        world_from_map = true_poses[0]
        ate_slam.append(absolute_trajectory_error(slam.trajectory, true_poses, world_from_map))
        ate_odometry.append(
            absolute_trajectory_error(dead_reckoning.trajectory, true_poses, world_from_map)
        )
        agreement.append(map_agreement(env.robot_map(agent), world_from_map, raster))
        rejected.append(slam.n_rejected)
        ate_graph.append(absolute_trajectory_error(graph.trajectory, true_poses, world_from_map))
        ate_graph_optimised.append(
            absolute_trajectory_error(graph.optimized_trajectory, true_poses, world_from_map)
        )
        agreement_graph.append(map_agreement(graph.grid.to_gridmap(), world_from_map, raster))
        closures.append(0 if graph.backend is None else graph.backend.n_closures)
    mean_slam, mean_odometry = float(np.mean(ate_slam)), float(np.mean(ate_odometry))
    return {
        "scenario": name,
        "steps": steps,
        "seed": seed,
        "ate_slam": mean_slam,
        "ate_odometry": mean_odometry,
        "ratio": mean_slam / mean_odometry if mean_odometry > 0 else math.nan,
        "map_agreement": float(np.mean(agreement)),
        "update_ms": 1e3 * statistics.median(update_seconds),
        "update_mean_ms": 1e3 * statistics.fmean(update_seconds),
        "steps_per_s": steps / stepping,
        "ate_slam_per_robot": ate_slam,
        "ate_odometry_per_robot": ate_odometry,
        "map_agreement_per_robot": agreement,
        "rejected_matches": rejected,
        "ate_pose_graph": float(np.mean(ate_graph)),
        "ate_pose_graph_optimised": float(np.mean(ate_graph_optimised)),
        "map_agreement_pose_graph": float(np.mean(agreement_graph)),
        "ate_pose_graph_per_robot": ate_graph,
        "loop_closures_per_robot": closures,
    }


def format_slam_table(rows: Sequence[dict[str, Any]]) -> str:
    """The benchmark rows as a fixed-width text table."""
    header = (
        f"{'scenario':<22}{'ATE slam m':>11}{'ATE odom m':>11}{'ratio':>7}"
        f"{'agreement':>10}{'update ms':>10}{'mean ms':>9}{'steps/s':>9}"
        f"{'ATE graph m':>12}{'optimised':>10}{'agreement':>10}{'closures':>9}"
    )
    lines = [header, "-" * len(header)]
    for row in rows:
        lines.append(
            f"{row['scenario']:<22}{row['ate_slam']:>11.3f}{row['ate_odometry']:>11.3f}"
            f"{row['ratio']:>7.3f}{row['map_agreement']:>10.4f}{row['update_ms']:>10.3f}"
            f"{row['update_mean_ms']:>9.3f}{row['steps_per_s']:>9.0f}"
            f"{row['ate_pose_graph']:>12.3f}{row['ate_pose_graph_optimised']:>10.3f}"
            f"{row['map_agreement_pose_graph']:>10.4f}{sum(row['loop_closures_per_robot']):>9d}"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    print(format_slam_table(run_slam_benchmark()))
