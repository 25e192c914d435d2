"""``mrslam bench soak``: one long run of the env with onboard SLAM and the team.

The team explores, merges and coordinates as in ``mrslam run``, then keeps acting after the
building is mapped, for ``steps`` env steps in all (the episode's ``max_cycles``). Every
``every`` steps it reports the speed over the last stretch and the process's resident
memory: once the maps stop growing the memory must level off (a leak shows as a steady
climb). A benchmark, not a test: its figures go to docs/benchmarks.md.
"""

from __future__ import annotations

import resource
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mrslam_env.config import EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.registry import build_world
from scenarios.experiment import MapCache, RunConfig, build_team

__all__ = ["format_soak_table", "resident_mb", "run_soak"]


def resident_mb() -> float:
    """The process's resident memory now, MB (Linux ``/proc``; elsewhere the peak)."""
    statm = Path("/proc/self/statm")
    if statm.exists():
        pages = int(statm.read_text().split()[1])
        return pages * resource.getpagesize() / 1e6
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KB on Linux, B on macOS
    return peak / (1e6 if sys.platform == "darwin" else 1e3)


def run_soak(
    scenario: str = "office",
    steps: int = 100_000,
    every: int = 10_000,
    seed: int = 0,
    progress: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Run the soak; one row per ``every`` steps: ``step``, ``steps_per_s`` (over the last
    stretch), ``rss_mb``, ``known_m2`` (the robots' maps' known area, summed)."""
    if steps < 1 or every < 1:
        raise ValueError(f"steps and every must be >= 1, got {steps} and {every}")
    env = MultiRobotSlamEnv(
        scenario=build_world(scenario), seed=seed, config=EnvConfig(max_cycles=steps)
    )
    observations, _ = env.reset()
    agents = list(env.possible_agents)
    team = build_team(RunConfig(seed=seed, max_steps=steps), env.config)
    maps = MapCache(env)
    rows: list[dict[str, Any]] = []
    stretch_started = time.perf_counter()
    for step in range(1, steps + 1):
        actions = team.act([observations[a] for a in agents], maps)
        observations, *_ = env.step({agent: actions[i] for i, agent in enumerate(agents)})
        team.pop_decisions()
        if step % every == 0 or step == steps:
            now = time.perf_counter()
            done = step - (rows[-1]["step"] if rows else 0)
            known = sum(
                float((~maps(i).unknown).sum()) * maps(i).resolution ** 2
                for i in range(len(agents))
            )
            row = {
                "step": step,
                "steps_per_s": round(done / (now - stretch_started), 1),
                "rss_mb": round(resident_mb(), 1),
                "known_m2": round(known, 1),
                "team_state": str(team.state),
            }
            rows.append(row)
            if progress is not None:
                progress(row)
            stretch_started = time.perf_counter()
    return rows


def format_soak_table(rows: list[dict[str, Any]]) -> str:
    lines = [f"{'step':>8} {'steps/s':>8} {'RSS MB':>8} {'known m²':>9}  team state"]
    lines += [
        f"{r['step']:>8} {r['steps_per_s']:>8.1f} {r['rss_mb']:>8.1f} {r['known_m2']:>9.1f}"
        f"  {r['team_state']}"
        for r in rows
    ]
    return "\n".join(lines)
