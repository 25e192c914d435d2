"""The experiment runner behind ``mrslam run`` (docs/design.md §6, §8).

Two robots start at poses neither knows of the other. Each maps with its onboard SLAM and
explores its own frontiers; when they can talk, the team coordinator
(:class:`agents.team.TeamCoordinator`) merges their maps by virtual robot motion, sends
them to a rendezvous to verify the best hypothesis with the peer sensor, refines the
accepted one and lets them explore the merged map together. The run stops when the
robots' maps together cover ``target_coverage`` of the free area (evaluated against the
ground truth, which the robots never see) or after ``max_steps``.

Each robot explores with an exploration policy (``policy``, a ``module:factory`` spec,
:mod:`agents.policy`; the frontier explorer by default); the team around it is the same
whatever the policy, and the report names the policy that ran.

Outputs in ``<out>/<name>/``: ``recording.rrd``, ``report.json``, ``robot_0.yaml``/``.pgm``
and ``robot_1.yaml``/``.pgm`` (each robot's map in its own frame), ``merged.yaml``/``.pgm``
(in robot 0's frame, when merged) and ``figure.png`` (ground truth, m1, m2, merge with the
preliminary estimate, merge after refinement). Every file is written under a temporary
name and renamed into place.

**The run folder** and **run names**: :mod:`scenarios.run_folder` (a run claims a new
folder, holds it with a marker, and ``--overwrite`` never deletes an input).

**A failed recording** (e.g. a full disk: rerun's writer stops) never stops the run from
writing its other outputs: the partial recording is always deleted, ``report.json`` is
written without ``outputs.recording`` and with the failure in ``errors`` (one line naming
the file and the cause, ``[]`` when none), and then the run raises that failure, a
:class:`mrslam_env.recording.RecordingError` (an ``OSError``: ``mrslam run`` exits 2).
Any other failure while the outputs are written is raised as it is, after the recording
is closed and its partial file deleted.

**Interrupted runs.** SIGINT (Ctrl-C), SIGTERM and SIGHUP (the terminal or ssh session
closed) only note the signal (:mod:`scenarios.interrupts`); the run looks at the note
between setup phases and between steps, never inside one. A signal before the run folder
is claimed (while the world, the env and its kernels load) ends the run with nothing
written (:class:`RunInterrupted`); once the folder exists, the run stops stepping and
writes the outputs of the steps done, with ``"complete": false`` and ``"interrupted":
"SIGINT"`` (or ``"SIGTERM"``, ``"SIGHUP"``) in ``report.json``, and the recording closed so
that it verifies. A signal while the outputs are written lets them finish and marks the
report the same way: every run folder gets a ``report.json``, and no signal is lost (what
a Python caller then sees: :func:`run_experiment`).

**Too large a world** is refused before the world is built
(:func:`mrslam_env.sim.mapworld.check_world_extent`: the world's extent at the SLAM
resolution, at most 25 M cells): a map's extent is checked as soon as the map file is read
(:func:`resolve_world`), so nothing of the world's size is allocated but the map's own
cells (which :mod:`mrslam_env.mapio` bounds).

**The report** (``report.json``). Quantities carry their unit in the key: ``sim_time_s``,
``wall_time_s``, ``t90_s``, ``ate_m``, ``translation_error_m``, ``rotation_error_deg``
(angles in degrees); counts of steps are named ``steps`` or ``step_*``; coverage and map
agreement are fractions. A transform is ``{x, y, theta}`` (m, m, rad: the format of
``mrslam merge --json``), ``map0_from_map<k>``. ``merge.robots`` has one entry per robot
but robot 0: ``joined`` (a verified merge brought it into robot 0's frame),
``step_joined``, ``transform`` (refined), ``verified_transform`` (as verified, before
refinement), ``true_transform``, ``translation_error_m``, ``rotation_error_deg``. The top
of ``merge`` summarises them: ``verified`` (some robot joined), ``joined``,
``all_joined``, ``step_first_joined``, ``step_all_joined``, ``worst_translation_error_m``,
``worst_rotation_error_deg``, and the team's counts (hypotheses tested, rendezvous, …).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.policy import build_policy, load_policy_factory, policy_label
from agents.rendezvous import judge_sighting, sighting_pose
from agents.team import MergeAttempt, TeamConfig, TeamCoordinator
from mrslam_env.atomic import atomic_path, write_text_atomic
from mrslam_env.config import CommConfig, EnvConfig
from mrslam_env.env import MultiRobotSlamEnv
from mrslam_env.evaluation import (
    CoverageEvaluator,
    absolute_trajectory_error,
    map_agreement,
    relative_transform_error,
)
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import GridMap
from mrslam_env.mapio import load_map, save_map
from mrslam_env.merge.fuse import fuse_all
from mrslam_env.recording import Recorder, RecordingError, source_words
from mrslam_env.registry import build_world
from mrslam_env.sim.mapworld import check_world_extent, world_from_map
from mrslam_env.sim.world import WorldSpec, ground_truth_map
from mrslam_env.slam.config import SLAM_MODES, SlamConfig, SlamMode
from scenarios.figure import no_merge_reason, summary_figure
from scenarios.interrupts import RunInterrupted, noting_signals, raise_if_received, received
from scenarios.run_folder import (
    check_inputs_outside,
    check_out,
    check_run_name,
    input_files,
    partial_recording,
    prepare_run_dir,
    release_run_dir,
)

__all__ = ["RunConfig", "RunInterrupted", "resolve_world", "run_experiment"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True)
class RunConfig:
    """One ``mrslam run``."""

    scenario: str = "office"
    """Scenario name; ignored when ``map_path`` is given."""
    map_path: Path | None = None
    """A ROS map YAML to build the world from."""
    seed: int = 0
    max_steps: int | None = None
    """Env steps (0.1 s each by default); None: :func:`step_budget` of the world's
    reachable floor and the team size."""
    out: Path = Path("runs")
    """Parent folder of the run folder."""
    name: str | None = None
    """Run folder name; defaults to ``<scenario>-seed<seed>``."""
    record: bool = True
    """Write ``recording.rrd``."""
    figure: bool = True
    """Write ``figure.png``."""
    scan_every: int = 5
    """Log lidar scans every this many steps (poses are logged every step)."""
    map_every: int = 10
    """Log a robot's map (when it changed), path, plan and frontiers every this many steps."""
    interaction: bool = True
    """False: the robots never interact (independent exploration, the baseline)."""
    comm: bool = True
    """False: the radio link never comes up."""
    oracle: bool = False
    """True: the team knows the robots' relative pose from step 0 (the true
    ``map0_from_map1``, from the env's start poses) and explores coordinated from the
    start, as after a verified merge: the benchmark's upper bound for coordination."""
    given_at: int | None = None
    """The late oracle: the robots explore independently until this step, when the team
    is given ``given_transforms`` and coordinates from then on as the oracle does (the
    benchmark gives a team run's own transforms at its own verification step, so the
    time the verification costs is measured)."""
    given_transforms: tuple[tuple[float, float, float], ...] | None = None
    """``map0_from_map_i`` for i = 1 ... robots-1, given at ``given_at``."""
    single: bool = False
    """True: robot 0 explores alone; robot 1 stays where it started and its map does not
    count towards coverage (the one-robot baseline; ``t90`` is for the whole floor)."""
    robots: int = 2
    """Team size, 2 to 8 (starts beyond the world's own are chosen by the simulator)."""
    slam_mode: SlamMode = "slam"
    """Each robot's onboard SLAM (:data:`mrslam_env.slam.config.SLAM_MODES`): ``"slam"``,
    ``"pose_graph"`` (with loop closure), ``"odometry"`` or ``"ground_truth"``."""
    policy: str | None = None
    """The robots' exploration policy as ``module:factory`` (or ``path/file.py:factory``,
    :func:`agents.policy.load_policy_factory`); None: the frontier explorer."""
    target_coverage: float = 0.95
    """Stop once the robots' maps together cover this fraction of the free area."""
    until_merged: bool = True
    """A team run (interaction, not oracle, not single) that reaches ``target_coverage``
    (or whose robots have nothing left to explore) before every robot joined robot 0's
    frame runs on until they did, until the team has had no merge under way
    (:attr:`agents.team.TeamCoordinator.merge_pending`) for ``until_merged_idle`` steps,
    or until ``max_steps``: the team's product is a merged map. ``t90`` means the same
    either way; the report gives ``coverage_step`` and ``steps_after_coverage``."""
    until_merged_idle: int = 300
    """Steps without a merge under way after which a run kept on by ``until_merged``
    stops (the hypotheses have run out)."""
    coverage_every: int = 20
    """Steps between coverage evaluations."""
    progress: bool = True
    overwrite: bool = False
    """Reuse ``<out>/<name>`` (deleting the earlier run's outputs) instead of the next free
    numbered folder."""

    def __post_init__(self) -> None:
        if self.max_steps is not None and self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        for name in ("scan_every", "map_every", "coverage_every", "until_merged_idle"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if not 0 < self.target_coverage <= 1:
            raise ValueError(f"target_coverage must be in (0, 1], got {self.target_coverage}")
        if self.oracle and (self.single or not self.interaction):
            raise ValueError("oracle needs interaction and two robots (not single)")
        self._check_given()
        if self.slam_mode not in SLAM_MODES:
            raise ValueError(f"slam_mode must be one of {SLAM_MODES}, got {self.slam_mode!r}")
        robots = self.robots
        if not isinstance(robots, int) or isinstance(robots, bool) or not 2 <= robots <= 8:
            raise ValueError(f"robots must be an integer from 2 to 8, got {robots!r}")
        if self.name is not None:
            check_run_name(self.name)

    def _check_given(self) -> None:
        given, transforms = self.given_at, self.given_transforms
        if (given is None) != (transforms is None):
            raise ValueError("given_at and given_transforms go together")
        if given is None or transforms is None:
            return
        if not isinstance(given, int) or isinstance(given, bool) or given < 1:
            raise ValueError(f"given_at must be a step >= 1, got {given!r}")
        if self.oracle or self.single or not self.interaction:
            raise ValueError("given transforms need interaction (not oracle, not single)")
        shape = np.asarray(transforms, dtype=np.float64).shape
        if shape != (self.robots - 1, 3) or not np.all(np.isfinite(transforms)):
            raise ValueError(
                f"given_transforms must be {self.robots - 1} finite (x, y, theta), got "
                f"{transforms!r}"
            )


MIN_STEPS = 3000
"""The smallest default step budget (5 minutes of 0.1 s steps): time for a team to meet
and verify a merge whatever the building's size."""
ROBOT_STEPS_PER_M2 = 20.0
"""The default budget per m² of reachable floor, in robot-steps (docs/decisions.md,
"Step budget"): a team of n robots gets ``ROBOT_STEPS_PER_M2 * area / n`` steps."""


def step_budget(free_area: float, robots: int) -> int:
    """The default step budget of a run: the larger of :data:`MIN_STEPS` and
    :data:`ROBOT_STEPS_PER_M2` ``* free_area / robots`` (``free_area`` in m² of floor the
    robots can reach), so that a big building can be explored to the target coverage."""
    return max(MIN_STEPS, math.ceil(ROBOT_STEPS_PER_M2 * free_area / robots))


def resolve_world(
    scenario: str, map_path: Path | None, seed: int = 0, *, resolution: float = 0.05
) -> WorldSpec:
    """The world of a scenario name, or of a ROS map file when one is given.

    A map's extent at ``resolution`` (m/cell: the finest grid the run makes of its world)
    is checked (:func:`mrslam_env.sim.mapworld.check_world_extent`) as soon as the map is
    read, before its world is built: too large a world is refused (``ValueError``) before
    anything of its size but the map's own cells is allocated."""
    if map_path is None:
        return build_world(scenario)
    grid = load_map(map_path)
    # The world's bounds are the grid's extent grown by one cell on every side.
    rows, cols = grid.cells.shape
    x0, y0 = grid.origin[0] - grid.resolution, grid.origin[1] - grid.resolution
    bounds = (x0, y0, x0 + (cols + 2) * grid.resolution, y0 + (rows + 2) * grid.resolution)
    check_world_extent(bounds, resolution)
    return world_from_map(grid, name=f"map:{Path(map_path).name}", rng=np.random.default_rng(seed))


class MapCache:
    """Each robot's own map, rebuilt only when its SLAM integrated a new scan."""

    def __init__(self, env: MultiRobotSlamEnv) -> None:
        self.env = env
        self.agents = list(env.possible_agents)
        self._maps: dict[int, tuple[int, GridMap]] = {}

    def __call__(self, robot: int) -> GridMap:
        agent = self.agents[robot]
        version = self.env.robot_slam(agent).n_integrated
        cached = self._maps.get(robot)
        if cached is None or cached[0] != version:
            cached = (version, self.env.robot_map(agent))
            self._maps[robot] = cached
        return cached[1]


def build_team(config: RunConfig, env_config: EnvConfig) -> TeamCoordinator:
    """The run's team, planning for the env's robots and sensors (``env_config`` is the
    env's own config: its robot radius, speeds, control period and peer sensor range)."""
    team_config = TeamConfig.for_env(
        env_config,
        interaction=config.interaction and not config.single and config.given_at is None,
        keep_merges=config.record,
    )
    factory = None if config.policy is None else load_policy_factory(config.policy)
    return TeamCoordinator.for_env(
        env_config,
        rng=np.random.default_rng(config.seed),
        config=team_config,
        n_robots=config.robots,
        policy_factory=factory,
    )


def check_policy(spec: str | None, env_config: EnvConfig) -> None:
    """Refuse a bad policy spec before any work: ``ValueError`` with one line when the
    module or factory cannot be loaded or what it builds is no exploration policy."""
    if spec is not None:
        build_policy(load_policy_factory(spec), env_config, np.random.default_rng(0), spec)


@contextmanager
def _progress(total: int, enabled: bool) -> Iterator[Any]:
    """A step counter to ``total``; a run that finishes early (coverage reached, nothing
    left to explore) ends the bar at 100 % of the steps it took."""
    from tqdm import tqdm

    bar = tqdm(total=total, disable=not enabled, unit="step", desc="mrslam run", leave=False)
    try:
        yield bar
        if not bar.disable and bar.n < bar.total:
            bar.total = bar.n
            bar.refresh()
    finally:
        bar.close()


def _pose_dict(pose: FloatArray) -> dict[str, float]:
    return {
        "x": round(float(pose[0]), 4),
        "y": round(float(pose[1]), 4),
        "theta": round(float(pose[2]), 5),
    }


def _grid_resolution(env_config: EnvConfig) -> float:
    """The finest grid a run makes of its world: the SLAM's cells, and the ground truth's
    0.05 m (the recording, the figure and the coverage reach)."""
    slam = env_config.slam
    return min(0.05, slam.grid.resolution) if slam is not None else 0.05


def run_experiment(config: RunConfig) -> dict[str, Any]:
    """Run one experiment, write its outputs, return the report (also ``report.json``).

    SIGINT, SIGTERM and SIGHUP are noted, not raised, while it runs (main thread only; the
    module docstring's interrupted runs). Called from Python in the main thread (not from
    the CLI, not inside another :func:`scenarios.interrupts.noting_signals` block), a
    signal noted is sent again once the run has ended and the caller's handlers are back
    (:func:`scenarios.interrupts.noting_signals` with ``redeliver``), whether the run
    returned or raised:

    - SIGINT under Python's own handler raises ``KeyboardInterrupt`` in the caller, after
      the run (it replaces the run's exception, if any: a :class:`RunInterrupted`, or e.g.
      an ``OSError`` while the outputs were written, which is its ``__context__``);
    - a signal whose handler is ``SIG_DFL`` (SIGTERM's and SIGHUP's default) ends the
      process by that signal, after the outputs are written (none when it came before
      the run folder was claimed): the caller sees no exception and no return;
    - a handler of the caller's is called; when it returns, the run's report is returned
      (or its exception raised, e.g. :class:`RunInterrupted`).

    In a worker thread, or inside the CLI or another noting block, nothing is sent again:
    the run returns its report marked ``"interrupted"``, or raises :class:`RunInterrupted`.

    Raises
    ------
    RunInterrupted
        A signal came before the run folder was claimed (nothing was written) and was not
        sent again, or its handler (the caller's) returned.
    ValueError
        Bad input: an unknown scenario, an unreadable map, too large a world, an input
        ``--overwrite`` would delete, a folder another run holds.
    """
    with noting_signals(redeliver=True):
        return _run_experiment(config)


def _run_experiment(config: RunConfig) -> dict[str, Any]:
    comm = CommConfig() if config.comm else CommConfig(comm_range=1e-9)
    env_config = EnvConfig(comm=comm, slam=SlamConfig(mode=config.slam_mode))
    resolution = _grid_resolution(env_config)
    check_out(Path(config.out))
    world = resolve_world(config.scenario, config.map_path, config.seed, resolution=resolution)
    stem = world.name if config.map_path is None else Path(config.map_path).stem
    name = config.name or f"{stem}-seed{config.seed}"
    check_run_name(name)
    inputs = input_files(config.map_path)
    if config.overwrite:  # bad input is refused before any work
        check_inputs_outside(Path(config.out) / name, inputs)
    check_world_extent(world.bounds, resolution)  # a scenario's world, too
    check_policy(config.policy, env_config)
    max_steps = config.max_steps
    if max_steps is None:
        floor = CoverageEvaluator(world, world.starts, radius=env_config.robot.radius)
        max_steps = step_budget(floor.area, config.robots)
    env_config = replace(env_config, max_cycles=max_steps)
    # Setup, phase by phase; a signal noted in one ends the run before the next, with no
    # folder claimed (the kernels load here: a signal waits for the kernel to return).
    raise_if_received()
    # Ground truth in the infos: the runs are judged (ATE) and drawn against it.
    env = MultiRobotSlamEnv(
        scenario=world, n_robots=config.robots, seed=config.seed, config=env_config, privileged=True
    )
    raise_if_received()
    observations, infos = env.reset()
    raise_if_received()
    agents = list(env.possible_agents)
    team = build_team(config, env.config)
    maps = MapCache(env)
    # Robot i's map frame is its start pose: how its SLAM and the merge are judged.
    world_from_maps = [env.simulator.starts[i].copy() for i in range(len(agents))]
    # The true map0_from_map_i: what the team's transforms are judged against.
    true_transforms = [compose(inverse(world_from_maps[0]), w) for w in world_from_maps]
    evaluator = CoverageEvaluator(world, env.simulator.starts, radius=env.config.robot.radius)
    if config.oracle:
        team.start_coordinated(np.array(true_transforms[1:]), maps)
    # The robots whose maps count towards coverage (single: robot 0 alone).
    counted = [0] if config.single else list(range(len(agents)))
    idle = np.zeros(2, dtype=np.float32)
    raise_if_received()
    # From here on the run holds its folder, and the folder always gets a report
    # (prepare_run_dir lets go of the folder itself when it fails).
    recorder: Recorder | None = None
    run_dir = prepare_run_dir(Path(config.out), name, overwrite=config.overwrite, inputs=inputs)
    recording_part = partial_recording(run_dir)  # a name only
    try:
        # Each robot's SLAM poses (map frame) and true poses (world), every step, for its ATE.
        slam_poses: list[list[FloatArray]] = [[observations[a]["pose"]] for a in agents]
        true_poses: list[list[FloatArray]] = [[infos[a]["true_pose"]] for a in agents]

        def ate(i: int) -> float:
            return absolute_trajectory_error(slam_poses[i], true_poses[i], world_from_maps[i])

        logged_scans = [-1] * len(agents)
        drawn = _DrawnRendezvous()
        merge_view = _MergeView()
        shown_transforms: list[FloatArray | None] = [None] * len(agents)
        collisions = dict.fromkeys(agents, 0)
        state = team.state
        coverage_curve: list[tuple[int, float]] = []
        t90: float | None = None
        # Where target coverage was reached, and the steps the team last had a merge
        # under way (``until_merged``).
        coverage_step: int | None = None
        events: list[str] = []  # the team's decisions, "STEP TEXT"
        last_pending = 0
        keep_on = config.until_merged and config.interaction
        keep_on = keep_on and not (config.oracle or config.single or config.given_at)
        steps = 0
        interrupted: str | None = None
        failed: OSError | None = None  # the recording's failure (the module docstring)
        started = time.perf_counter()
        try:
            if config.record:
                try:
                    recorder = Recorder(
                        recording_part, n_robots=len(agents), map_every=config.map_every
                    )
                except (RuntimeError, OSError) as error:  # e.g. a full disk: run on without
                    recording_part.unlink(missing_ok=True)
                    failed = RecordingError.of(recording_part, error)
            if recorder is not None:
                recorder.log_ground_truth(world, ground_truth_map(world, 0.05))
                recorder.log_event(
                    f"run {name}: world {world.name}, {len(agents)} robots, seed {config.seed}"
                )
                recorder.log_text("team/state", str(team.state))
            with _progress(max_steps, config.progress) as bar:
                while env.agents and received() is None:
                    if steps + 1 == config.given_at and config.given_transforms is not None:
                        # The late oracle: from this step on the team coordinates.
                        team.start_coordinated(np.array(config.given_transforms), maps)
                    if config.single:
                        actions = [team.act_alone(0, observations[agents[0]], maps(0))]
                        actions += [idle] * (len(agents) - 1)
                    else:
                        actions = team.act([observations[a] for a in agents], maps)
                    observations, _rewards, _terms, _truncs, infos = env.step(
                        {agent: actions[i] for i, agent in enumerate(agents)}
                    )
                    steps += 1
                    bar.update(1)
                    for i, agent in enumerate(agents):
                        collisions[agent] += infos[agent]["collision"]
                        slam_poses[i].append(observations[agent]["pose"])
                        true_poses[i].append(infos[agent]["true_pose"])
                    decisions = team.pop_decisions()
                    if recorder is not None:
                        recorder.set_time(steps, steps * env_config.dt)
                        attempts = team.pop_merge_attempts()
                        pending = list(attempts)
                        for decision in decisions:
                            if "rendezvous" in decision.text or "hypothesis #" in decision.text:
                                recorder.log_text("rendezvous/status", decision.text)
                            if pending and decision.text.endswith("to verify by rendezvous"):
                                # The attempt's event says it, with the attempt's verdict.
                                _log_attempts(recorder, team, pending, merge_view)
                                pending = []
                            else:
                                recorder.log_event(decision.text)
                        _log_attempts(recorder, team, pending, merge_view)
                        moved = []
                        for k in range(1, len(agents)):
                            frame = team.frames[k] if team.roots[k] == 0 else None
                            if frame is not None and frame is not shown_transforms[k]:
                                recorder.set_team_transform(k, frame)
                                shown_transforms[k] = frame
                                moved.append(k)
                        _record_merge(recorder, team, maps, merge_view, decisions, moved)
                        if team.state is not state:
                            recorder.log_text("team/state", str(team.state))
                        _record_step(
                            recorder,
                            env,
                            team,
                            maps,
                            observations,
                            infos,
                            config,
                            logged_scans,
                            drawn,
                        )
                        if recorder.map_due:
                            for i, agent in enumerate(agents):
                                recorder.log_scalar(f"ate/{agent}", ate(i))
                    events += [f"{decision.step} {decision.text}" for decision in decisions]
                    state = team.state
                    if team.merge_pending:
                        last_pending = steps
                    if steps % config.coverage_every == 0 or not env.agents:
                        covered = evaluator.coverage(
                            [maps(i) for i in counted], [world_from_maps[i] for i in counted]
                        )
                        coverage_curve.append((steps, covered))
                        if recorder is not None:
                            recorder.log_scalar("coverage/team", covered)
                        if t90 is None and covered >= 0.9:
                            t90 = steps * env_config.dt
                        finished = covered >= config.target_coverage
                        if finished or all(team.done(i) for i in counted):
                            if coverage_step is None:
                                coverage_step = steps
                            all_joined = len(team.members) == len(agents)
                            waited = steps - max(last_pending, coverage_step)
                            if not keep_on or all_joined or waited >= config.until_merged_idle:
                                break
        except KeyboardInterrupt as stop:  # raised by code (e.g. a caller's own handler)
            interrupted = getattr(stop, "signal_name", "SIGINT")
        # The outputs of the steps done are written whole: a signal from here on is noted
        # and marks the report (checked last, just before report.json is written).
        interrupted = interrupted or received()
        wall_time = time.perf_counter() - started

        own_maps = [maps(i) for i in range(len(agents))]
        for agent, grid in zip(agents, own_maps, strict=True):
            save_map(run_dir / f"{agent}.yaml", grid)
        outputs: dict[str, Any] = {
            "run_dir": str(run_dir),
            "maps": {agent: str(run_dir / f"{agent}.yaml") for agent in agents},
        }
        truth = ground_truth_map(world, own_maps[0].resolution)
        merged = preliminary = None
        # The robots in robot 0's frame (a verified transform reaches them), with their
        # transforms as refined and as verified.
        joined = [k for k in range(1, len(agents)) if team.roots[k] == 0]
        robots = {
            agents[k]: _robot_merge(team, k, true_transforms[k]) for k in range(1, len(agents))
        }
        entries = [robots[agents[k]] for k in joined]
        steps_joined = [entry["step_joined"] for entry in entries]
        merge_report: dict[str, Any] = {
            "verified": bool(joined),
            "joined": len(joined),
            "all_joined": len(joined) == len(agents) - 1,
            "step_first_joined": min(steps_joined, default=None),
            "step_all_joined": max(steps_joined) if len(joined) == len(agents) - 1 else None,
            "worst_translation_error_m": max(
                (entry["translation_error_m"] for entry in entries), default=None
            ),
            "worst_rotation_error_deg": max(
                (entry["rotation_error_deg"] for entry in entries), default=None
            ),
            "hypotheses_tested": team.hypotheses_tested,
            "seeking_steps": sum(team.seeking_steps),
            "sighting_hypotheses": team.sighting_hypotheses,
            "first_hypothesis_step": team.first_hypothesis_step,
            "first_rendezvous_step": team.first_rendezvous_step,
            "rendezvous_steps": team.rendezvous_steps,
            "radio_rejections": team.radio_rejections,
            "robots": robots,
        }
        if joined:
            merged = _fuse_all(own_maps, {k: team.frames[k] for k in joined})
            preliminary = _fuse_all(own_maps, {k: team.verified[k] for k in joined})
            save_map(run_dir / "merged.yaml", merged)
            outputs["merged_map"] = str(run_dir / "merged.yaml")
        apart = [i for i in counted if i != 0 and i not in joined]
        coverage = {
            "merged": round(
                evaluator.coverage(
                    [merged, *(own_maps[i] for i in apart)],
                    [world_from_maps[0], *(world_from_maps[i] for i in apart)],
                )
                if merged is not None
                else evaluator.coverage(
                    [own_maps[i] for i in counted], [world_from_maps[i] for i in counted]
                ),
                4,
            ),
            **{
                agent: round(evaluator.coverage([own_maps[i]], [world_from_maps[i]]), 4)
                for i, agent in enumerate(agents)
            },
        }
        if config.figure:
            n = len(agents)
            with atomic_path(run_dir / "figure.png") as figure:
                summary_figure(
                    figure,
                    truth,
                    own_maps[0],
                    own_maps[1],
                    preliminary,
                    merged,
                    more_maps=own_maps[2:],
                    world_from_maps=world_from_maps,
                    verified=[team.verified[k] if k in joined else None for k in range(1, n)],
                    transforms=[team.frames[k] if k in joined else None for k in range(1, n)],
                    no_merge=no_merge_reason(merge_report, str(team.state), events),
                )
            outputs["figure"] = str(run_dir / "figure.png")
        report: dict[str, Any] = {
            "complete": True,
            "interrupted": None,
            "scenario": world.name,
            "seed": config.seed,
            "steps": steps,
            "max_steps": max_steps,
            "sim_time_s": round(steps * env_config.dt, 6),
            "wall_time_s": round(wall_time, 3),
            "interaction": config.interaction,
            "comm": config.comm,
            "oracle": config.oracle,
            "given_at": config.given_at,
            "single": config.single,
            "robots": len(agents),
            "policy": policy_label(config.policy),
            "policy_spec": config.policy,
            "merge": merge_report,
            "coverage": coverage,
            "t90_s": None if t90 is None else round(t90, 3),
            "until_merged": keep_on,
            "coverage_step": coverage_step,
            "steps_after_coverage": 0 if coverage_step is None else steps - coverage_step,
            "coverage_curve": [[s, round(c, 4)] for s, c in coverage_curve],
            "slam": {
                agent: {
                    "ate_m": round(ate(i), 4),
                    "map_agreement": round(
                        map_agreement(own_maps[i], world_from_maps[i], truth), 4
                    ),
                }
                for i, agent in enumerate(agents)
            },
            "merged_map_accuracy": None
            if merged is None
            else round(map_agreement(merged, world_from_maps[0], truth), 4),
            "collision_steps": {agent: int(collisions[agent]) for agent in agents},
            "team_state": str(team.state),
            "decisions": events,
            "outputs": outputs,
        }
        if recorder is not None:
            if merged is not None:
                recorder.log_grid("team/merged_map", merged)
            interrupted = interrupted or received()
            ending = "finished" if interrupted is None else f"interrupted ({interrupted})"
            recorder.log_event(
                f"run {ending} after {steps} steps, coverage {coverage['merged']:.1%}"
            )
            try:
                recorder.close()
                recording_part.replace(run_dir / "recording.rrd")
            except OSError as error:  # RecordingError from close(), or the rename's
                failed = error if isinstance(error, RecordingError) else None
                failed = failed or RecordingError.of(run_dir / "recording.rrd", error)
            else:
                outputs["recording"] = str(run_dir / "recording.rrd")
            finally:
                recording_part.unlink(missing_ok=True)
        interrupted = interrupted or received()
        report.update(complete=interrupted is None, interrupted=interrupted)
        report["errors"] = [] if failed is None else [str(failed)]
        write_text_atomic(run_dir / "report.json", json.dumps(report, indent=2) + "\n")
        if failed is not None:
            raise failed
        return report
    except BaseException:  # a crash: close the recording, leave no partial file
        try:
            if recorder is not None:
                with suppress(Exception):  # the crash is what the caller sees
                    recorder.close()
        finally:
            recording_part.unlink(missing_ok=True)
        raise
    finally:
        release_run_dir(run_dir)


@dataclass(slots=True)
class _DrawnRendezvous:
    """What the recording shows of the current rendezvous: whether one is drawn (its end
    clears it once) and robot 0's sightings of robot 1 so far, each with its verdict."""

    active: bool = False
    sightings: list[tuple[FloatArray, bool]] = field(default_factory=list)
    merged_key: tuple[tuple[int, int], ...] = ()
    """What the Team view's merged map was fused from: per robot, its map's scan count
    and its transform's identity."""


@dataclass(slots=True)
class _MergeView:
    """What the Merge view shows: the maps of the last attempt, the rendezvous (its
    identity and whether it was in place) whose hypothesis is drawn, the acceptances
    drawn."""

    maps: tuple[GridMap, GridMap] | None = None
    shown: tuple[int, bool] | None = None
    index: int = 0
    accepted: int = 0


def _words(proposed_by: str, attempt: int | None) -> str:
    """``"from the virtual robot (merge attempt 4)"``, ``"from sightings"``."""
    return f"from {source_words(proposed_by)}" + (
        f" (merge attempt {attempt})" if attempt is not None else ""
    )


def _log_attempts(
    recorder: Recorder, team: TeamCoordinator, attempts: list[MergeAttempt], view: _MergeView
) -> None:
    """Log merge attempts, each with what the team does with its hypotheses."""
    for attempt in attempts:
        recorder.log_merge_attempt(
            attempt.number,
            attempt.result,
            attempt.map0,
            attempt.map1,
            label=f"robot_{attempt.robots[0]}'s and robot_{attempt.robots[1]}'s maps at "
            f"step {attempt.step}",
            then=_attempt_outcome(team, attempt, attempt is attempts[-1]),
        )
        view.maps = (attempt.map0, attempt.map1)


def _attempt_outcome(team: TeamCoordinator, attempt: MergeAttempt, last: bool) -> str:
    """What the team does with a merge attempt's hypotheses, for its event."""
    if not last or team.hypotheses_attempt != attempt.number or not team.hypotheses:
        return "no hypothesis goes to verification"
    judged = {id(h.map1_from_map2): h for h in attempt.result.hypotheses}
    parts = []
    for index, (hypothesis, source) in enumerate(
        zip(team.hypotheses, team.hypothesis_sources, strict=True)
    ):
        scored = judged.get(id(hypothesis))
        score = "" if scored is None else f", agreement {scored.acceptance_index:.2f}"
        parts.append(f"#{index} (from {source_words(source)}{score})")
    verb = "goes" if len(parts) == 1 else "go"
    return f"hypothesis {'; '.join(parts)} {verb} to verification by rendezvous"


def _record_merge(
    recorder: Recorder,
    team: TeamCoordinator,
    maps: MapCache,
    view: _MergeView,
    decisions: Sequence[Any],
    moved: Sequence[int],
) -> None:
    """Keep the Merge view on the team's state: the hypothesis under verification (from
    where, verified how), then the accepted and refined transform with the fused map;
    a hypothesis rejected or set aside in words (docs/reading-a-recording.md)."""
    if len(team.acceptances) > view.accepted or moved:
        new = team.acceptances[view.accepted :]
        view.accepted = len(team.acceptances)
        for k in moved or (1,):
            frame, verified = team.frames[k], team.verified[k]
            if frame is None or verified is None or team.roots[k] != 0:
                continue
            m0, mk = maps(0), maps(k)
            dist, turn = recorder.merge_difference(verified, frame, mk)
            if new:
                done = new[-1]
                text = (
                    f"robot_{k}'s map accepted at step {done.step}: hypothesis "
                    f"#{done.index} ({done.index + 1} of {done.count}), "
                    f"{_words(done.proposed_by, done.attempt)}, "
                    f"verified: {done.how}; refined: {dist:.2f} m / {turn:.2f}° from the "
                    "verified estimate"
                )
            else:
                text = (
                    f"robot_{k}'s transform re-refined at step {recorder.step}: {dist:.2f} m / "
                    f"{turn:.2f}° from the verified estimate"
                )
            short = f"robot_{k}: " + (
                f"accepted at step {new[-1].step}, refined" if new else "re-refined"
            )
            recorder.log_merge_accepted(
                verified,
                frame,
                m0,
                mk,
                _fuse_all([m0, mk], {1: frame}),
                text,
                caption=f"{short}: {dist:.2f} m / {turn:.2f}° from the verified estimate",
                event=bool(new),
            )
        view.shown = None
        return
    rendezvous = team.rendezvous
    if rendezvous is not None:
        key = (id(rendezvous), rendezvous.in_place)
        if key == view.shown:
            return
        view.shown, view.index = key, rendezvous.index
        a, b = team.pair
        if team.roots[a] == a and team.roots[b] == b:
            m1, m2 = maps(a), maps(b)
        elif view.maps is not None:
            m1, m2 = view.maps
        else:
            return
        if rendezvous.formed_at is not None:
            how = "by sightings once both robots have moved on"
        elif rendezvous.in_place and rendezvous.waits:
            how = "where the robots explore, waiting for a chance meeting"
        elif rendezvous.in_place:
            how = "where the robots stand, confirming while they move"
        else:
            x, y = rendezvous.meeting_point
            how = f"at the rendezvous ({x:.1f}, {y:.1f})"
        attempt = None if rendezvous.formed_at is not None else team.hypotheses_attempt
        text = (
            f"hypothesis #{rendezvous.index} ({rendezvous.index + 1} of {len(team.hypotheses)}), "
            f"{_words(team.source_of(rendezvous), attempt)}: verifying {how}"
        )
        recorder.log_merge_verification(
            rendezvous.hypothesis,
            m1,
            m2,
            text,
            caption=f"hypothesis #{rendezvous.index} ({rendezvous.index + 1} of "
            f"{len(team.hypotheses)}), from {source_words(team.source_of(rendezvous))}: "
            f"verifying {how.split(' (')[0]}",
        )
    elif view.shown is not None:
        view.shown = None
        ended = [d.text for d in decisions if f"#{view.index}" in d.text]
        why = ended[-1] if ended else f"hypothesis #{view.index}: verification ended"
        recorder.log_merge_caption(why, level="WARN")


def _record_step(
    recorder: Recorder,
    env: MultiRobotSlamEnv,
    team: TeamCoordinator,
    maps: MapCache,
    observations: dict[str, Any],
    infos: dict[str, Any],
    config: RunConfig,
    logged_scans: list[int],
    drawn: _DrawnRendezvous,
) -> None:
    """What one step adds to the recording (docs/design.md §7)."""
    agents = list(env.possible_agents)
    lidar = env.config.lidar
    due = recorder.map_due or not env.agents
    coordinated = len(team.members) > 1 and team.merged_map is not None
    for i, agent in enumerate(agents):
        radius = env.config.robot.radius
        recorder.log_true_pose(i, infos[agent]["true_pose"], radius=radius)
        recorder.log_robot_pose(i, observations[agent]["pose"], radius=radius)
        if recorder.step % config.scan_every == 0:
            recorder.log_scan(
                i,
                infos[agent]["true_pose"],
                observations[agent]["scan"],
                env.simulator.beam_angles,
                lidar.max_range,
            )
        if not due:
            continue
        slam = env.robot_slam(agent)
        recorder.log_robot_path(i, slam.trajectory)
        if slam.n_integrated != logged_scans[i]:
            recorder.log_grid(f"{agent}/map", maps(i))
            logged_scans[i] = slam.n_integrated
        # Plans and frontiers are in the frame of the map explored: robot 0's while
        # coordinating; bring them into the robot's own frame.
        own_from_plan = inverse(team.frames[i]) if i != 0 and team.coordinated(i) else None
        for entity, points in (("plan", team.plan_of(i)), ("frontiers", team.frontiers_of(i))):
            if own_from_plan is not None and len(points):
                points = transform_points(own_from_plan, points)
            if entity == "plan":
                recorder.log_line(f"{agent}/plan", points, robot=i)
            else:
                recorder.log_points(f"{agent}/frontiers", points, robot=i)
    # A rendezvous can be settled within a few steps: log it every step while it lasts.
    rendezvous = team.rendezvous
    if rendezvous is not None:
        # The pair meeting, side 0 and side 1, each in its group root's frame (robot 0's
        # while robot 0 is one of them); side 1's plan and pose brought there by the
        # hypothesis under test.
        hypothesis = rendezvous.hypothesis
        pair = team.pair
        plans: list[FloatArray] = [np.empty((0, 2))] * len(agents)
        poses: list[FloatArray | None] = [None] * len(agents)
        for side, robot in enumerate(pair):
            to_root = team.explored_frame(robot)
            if side == 1:
                to_root = hypothesis if to_root is None else compose(hypothesis, to_root)
            plan = team.plan_of(robot)
            if to_root is not None and len(plan):
                plan = transform_points(to_root, plan)
            plans[robot] = plan
            pose = team.pose_in_root(robot, observations[agents[robot]]["pose"])
            poses[robot] = pose if side == 0 else compose(hypothesis, pose)
        # Side 0's sightings of side 1 since the rendezvous began, each judged against
        # where the hypothesis puts side 1 (as the team judges them).
        peer = observations[agents[pair[0]]]["peer"][pair[1] - (pair[1] > pair[0])]
        if peer[0] > 0.5:
            seen = sighting_pose(peer[1], peer[2], peer[3])
            first, second = poses[pair[0]], poses[pair[1]]
            assert first is not None and second is not None
            predicted = compose(inverse(first), second)
            verdict = judge_sighting(seen, predicted, team.config.rendezvous).matches
            drawn.sightings.append((compose(first, seen)[:2], verdict))
        recorder.log_rendezvous(
            rendezvous.meeting_point,
            plans[: max(pair) + 1],
            poses=poses,
            sightings=np.array([s for s, _ in drawn.sightings]).reshape(-1, 2),
            sighting_matches=[m for _, m in drawn.sightings],
            radius=env.config.robot.radius,
        )
        drawn.active = True
    elif drawn.active:
        recorder.clear_rendezvous()
        drawn.active, drawn.sightings = False, []
    # The Team view's merged map: every robot in robot 0's frame, each with its current
    # map (robot 0's own view holds the others' maps as last received, stale while a
    # link is down), logged whenever one of them changed: a map (scan counts, updated on
    # the steps maps are due) or a transform (at once).
    joined = [k for k in range(1, len(agents)) if team.roots[k] == 0 and team.frames[k] is not None]
    if coordinated and joined:
        key = tuple((logged_scans[k], id(team.frames[k])) for k in (0, *joined))
        if key != drawn.merged_key:
            own = [maps(k) if k == 0 or k in joined else maps(0) for k in range(len(agents))]
            recorder.log_grid(
                "team/merged_map", _fuse_all(own, {k: team.frames[k] for k in joined})
            )
            drawn.merged_key = key


def _fuse_all(own_maps: list[GridMap], transforms: dict[int, FloatArray | None]) -> GridMap:
    """Robot 0's map with robot k's fused in by ``transforms[k]`` (``map0_from_map_k``)."""
    others = []
    for k, transform in transforms.items():
        assert transform is not None
        others.append((own_maps[k], transform))
    return fuse_all(own_maps[0], others)


def _robot_merge(team: TeamCoordinator, robot: int, truth: FloatArray) -> dict[str, Any]:
    """One robot's entry in the report's ``merge.robots``: its own transforms (refined and
    as verified), its truth, its errors and the step it joined robot 0's frame."""
    transform = team.common_transform(robot)
    verified = team.verified[robot] if transform is not None else None
    entry: dict[str, Any] = {
        "joined": transform is not None,
        "step_joined": None if transform is None else team.step_joined[robot],
        "transform": None if transform is None else _pose_dict(transform),
        "verified_transform": None if verified is None else _pose_dict(verified),
        "true_transform": _pose_dict(truth),
        "translation_error_m": None,
        "rotation_error_deg": None,
    }
    if transform is not None:
        translation_error, rotation_error = relative_transform_error(transform, truth)
        entry.update(
            translation_error_m=round(translation_error, 4),
            rotation_error_deg=round(math.degrees(rotation_error), 4),
        )
    return entry
