"""The exploration benchmark behind ``mrslam bench explore``.

Per scenario and seed, the end-to-end experiment (:func:`scenarios.experiment.run_experiment`)
runs once per mode, all from the same starts:

===============  =====================================================================
``team``         the team coordinator: merge by virtual robot motion, rendezvous
                 verification, coordinated exploration of the merged map
``independent``  the same two robots exploring independently (no interaction)
``oracle``       the relative pose known from step 0 (the true ``map0_from_map1``, from
                 the env's start poses): coordinated exploration from the start, as after
                 a verified merge; what coordination could gain at most
``single``       robot 0 alone (robot 1 stays put, its map does not count)
===============  =====================================================================

Reported per scenario:

=========================  ==========================================================
``t90[mode]``              mean simulated time (s) until the maps (of the robots that
                           count) cover 90 % of the free area; a run that never gets
                           there counts as its time limit (and in ``unfinished[mode]``)
``t90_coordinated``        ``t90["team"]``; ``t90_independent``: ``t90["independent"]``
``speedup``                ``t90_independent / t90_coordinated``
``oracle_gain_share``      ``(t90_independent - t90_team) / (t90_independent -
                           t90_oracle)``: the share of the oracle's gain the team gets
                           (None when the oracle gains nothing)
``faster``                 team runs that reached 90 % sooner than the same seed's
                           independent run
``verified``               team runs with a verified merge (at any time, also after
                           the run's target coverage: ``RunConfig.until_merged``) /
                           team runs
``wrong_accepted``         verified merges off by more than 0.10 m or 1° (must be 0)
``translation_error``      median, p90 and max translation error (m) of the verified
                           merges; ``rotation_error`` the same in degrees
``verified_before_t90``    team runs that verified their merge before their maps
                           covered 90 % (or verified it in a run that never did)
``seeking_steps``          robot-steps the team runs spent seeking contact (driving
                           back to the place of the last link and waiting there)
``rendezvous_steps``       robot-steps the team runs spent driving to a meeting point
                           or waiting there (None when no report gives it)
``steps_after_coverage``   steps the team runs went on after reaching their target
                           coverage without a verified merge, until merged or with
                           nothing left to explore (``until_merged``)
``collisions[mode]``       collision steps per run (summed over the moving robots):
                           median, max, and the median as % of the moving robots' steps
=========================  ==========================================================

With several scenarios a last row, ``all``, summarises every run.

**A policy of one's own.** ``policy`` (``mrslam bench explore --policy module:factory``,
:mod:`agents.policy`) runs every scenario, seed and mode a second time with that
exploration policy in place of the frontier explorer; the summary then has one row per
scenario and policy (a ``policy`` column), the frontier baseline's beside the policy's,
on the same seeds and starts.

**Team sizes.** ``robots`` (``--robots 2 3 4``) runs every scenario, seed and mode with
each team size; the summary then has one row per scenario and size (a ``robots`` column)
and, per row, ``joined``: the robots (besides robot 0) that a verified transform brought
into robot 0's frame, over all team runs, and the worst error of those transforms in
``translation_error`` / ``rotation_error``. The worlds' own starts are used for the first
two robots; the simulator chooses the others' (seeded).

Coverage is judged against the ground truth (evaluation only); runs stop as ``mrslam
run`` does, at 95 % (or the step limit), so that the merge figures are those of the main
job.
"""

from __future__ import annotations

import json
import math
import statistics
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from mrslam_env.atomic import write_text_atomic
from mrslam_env.config import EnvConfig
from scenarios.experiment import RunConfig, check_policy, run_experiment
from scenarios.sweep import run_tasks

__all__ = [
    "DEFAULT_SCENARIOS",
    "MODES",
    "format_explore_table",
    "is_wrong",
    "oracle_gain_share",
    "run_explore_benchmark",
    "run_row",
    "summarise_reports",
    "upgrade_report",
]

DEFAULT_SCENARIOS = ("office", "warehouse", "maze", "twin_wings", "procedural-0")
MODES = ("team", "independent", "oracle", "single", "late-oracle")
WRONG_TRANSLATION = 0.10
"""A verified merge further off than this (m) is wrong."""
WRONG_ROTATION_DEG = 1.0
"""… or further off than this (°)."""


def is_wrong(translation_error: float, rotation_error_deg: float) -> bool:
    """Whether a verified merge with these errors (m, °) counts as wrong."""
    return translation_error > WRONG_TRANSLATION or rotation_error_deg > WRONG_ROTATION_DEG


def oracle_gain_share(t_independent: float, t_team: float, t_oracle: float) -> float | None:
    """``(t_independent - t_team) / (t_independent - t_oracle)``: the share of what knowing
    the relative pose gains that the team gets; None when the oracle gains nothing."""
    gain = t_independent - t_oracle
    if gain <= 0:
        return None
    return (t_independent - t_team) / gain


Given = tuple[int, tuple[tuple[float, float, float], ...]]
"""What a late-oracle run is given: (step, ``map0_from_map_i`` for i = 1 ... n-1)."""


def _mode_config(mode: str, given: Given | None = None) -> dict[str, bool]:
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; modes: {', '.join(MODES)}")
    return {
        "interaction": mode in ("team", "oracle") or given is not None,
        "oracle": mode == "oracle",
        "single": mode == "single",
    }


def late_oracle_given(team_report: dict[str, Any]) -> Given | None:
    """What the late oracle of a team run is given: the step at which the team run had
    joined every robot into robot 0's frame and its final transforms; None when it never
    did (the late oracle is then an independent run)."""
    merge = upgrade_report(team_report)["merge"]
    step = merge.get("step_all_joined")
    robots = merge.get("robots") or {}
    if not merge.get("all_joined") or step is None or not robots:
        return None
    transforms = []
    for k in range(1, len(robots) + 1):
        t = robots[f"robot_{k}"]["transform"]
        transforms.append((float(t["x"]), float(t["y"]), float(t["theta"])))
    return int(step), tuple(transforms)


def _run(
    scenario: str,
    seed: int,
    max_steps: int,
    mode: str,
    policy: str | None,
    robots: int,
    out: Path,
    given: Given | None = None,
) -> dict[str, Any]:
    flags = _mode_config(mode, given)
    config = RunConfig(
        scenario=scenario,
        seed=seed,
        max_steps=max_steps,
        out=out,
        name=f"{scenario}-{seed}-{mode}-{robots}" + ("" if policy is None else "-policy"),
        policy=policy,
        robots=robots,
        record=False,
        figure=False,
        progress=False,
        interaction=flags["interaction"],
        oracle=flags["oracle"],
        single=flags["single"],
        given_at=None if given is None else given[0],
        given_transforms=None if given is None else given[1],
    )
    return run_experiment(config)


Task = tuple[int, str, int, int, str | None, int, str, Given | None]
"""One run: (index in the sweep, scenario, seed, max_steps, policy spec or None, robots,
mode, what a late oracle is given)."""


def _task(task: Task) -> dict[str, Any]:
    """One run's report (the JSON of ``mrslam run``) with the task under ``"bench"``. The
    run writes into a folder of its own, deleted after: a Ray worker may be on another
    machine, so the report travels back as the result and the caller keeps it."""
    index, scenario, seed, max_steps, policy, robots, mode, given = task
    with tempfile.TemporaryDirectory(prefix="mrslam-bench-explore-") as folder:
        report = _run(scenario, seed, max_steps, mode, policy, robots, Path(folder), given)
    report["outputs"] = {}  # the files went with the folder
    report["bench"] = {
        "index": index,
        "scenario": scenario,
        "seed": seed,
        "max_steps": max_steps,
        "mode": mode,
        "policy_spec": policy,
        "robots": robots,
        "given_at": None if given is None else given[0],
    }
    return report


OLD_REPORT_KEYS = {"sim_time": "sim_time_s", "wall_time": "wall_time_s", "t90": "t90_s"}
"""Top-level keys of the reports written before units were in the key names (issue 36)."""
OLD_MERGE_KEYS = {
    "translation_error": "worst_translation_error_m",
    "rotation_error": "worst_rotation_error_deg",
    "step_verified": "step_first_joined",
}
"""The same in ``merge``: the old ``translation_error`` / ``rotation_error`` were already
the worst over the joined robots (m, °), ``step_verified`` the first robot's join."""


def upgrade_report(report: dict[str, Any]) -> dict[str, Any]:
    """A run report with the current key names, also when an earlier version wrote it
    (``bench explore --from`` reads the reports an earlier ``--out`` kept)."""
    renamed = {OLD_REPORT_KEYS.get(key, key): value for key, value in report.items()}
    merge = report.get("merge")
    if isinstance(merge, dict):
        renamed["merge"] = {OLD_MERGE_KEYS.get(key, key): value for key, value in merge.items()}
    return renamed


def run_row(report: dict[str, Any]) -> dict[str, Any]:
    """The benchmark's row of one run, from its report (as :func:`_task` returns it and
    ``--out`` keeps it; old key names too, :func:`upgrade_report`). The row's times are in
    s, its errors in m and °."""
    report = upgrade_report(report)
    bench = report["bench"]
    mode, robots = bench["mode"], bench["robots"]
    merge = report["merge"]
    collisions = report["collision_steps"]
    moving = ["robot_0"] if mode == "single" else list(collisions)
    return {
        "scenario": bench["scenario"],
        "seed": bench["seed"],
        "mode": mode,
        "policy": report["policy"],
        "robots": robots,
        "joined": merge.get("joined", int(merge["verified"])),
        "t90": report["t90_s"],
        "t90_or_limit": report["t90_s"]
        if report["t90_s"] is not None
        else bench["max_steps"] * 0.1,
        "verified": merge["verified"],
        "translation_error": merge["worst_translation_error_m"],
        "rotation_error": merge["worst_rotation_error_deg"],
        "hypotheses_tested": merge["hypotheses_tested"],
        "step_verified": merge["step_first_joined"],
        "verified_before_t90": _verified_before_t90(report),
        "seeking_steps": merge.get("seeking_steps", 0),
        "rendezvous_steps": merge.get("rendezvous_steps"),
        "steps_after_coverage": report.get("steps_after_coverage", 0),
        "coverage": report["coverage"]["merged"],
        "steps": report["steps"],
        "given_at": bench.get("given_at"),
        "collision_steps": sum(collisions[agent] for agent in moving),
        "robot_steps": report["steps"] * len(moving),
        "wall_time": report["wall_time_s"],
    }


def _verified_before_t90(report: dict[str, Any]) -> bool:
    """Whether the run verified its merge before its maps covered 90 % (or verified it
    in a run that never got there)."""
    step = report["merge"]["step_first_joined"]
    if step is None:
        return False
    t90 = report["t90_s"]
    return t90 is None or step * report["sim_time_s"] / max(report["steps"], 1) <= t90


def _report_name(report: dict[str, Any]) -> str:
    bench = report["bench"]
    name = f"{bench['scenario']}-{bench['seed']}-{bench['mode']}-{bench['robots']}"
    return name if bench["policy_spec"] is None else f"{name}-{report['policy']}"


def run_explore_benchmark(
    scenarios: Sequence[str] = DEFAULT_SCENARIOS,
    seeds: Sequence[int] = range(5),
    max_steps: int = 4000,
    *,
    modes: Sequence[str] = MODES,
    jobs: int = 1,
    progress: Callable[[str], None] | None = None,
    policy: str | None = None,
    robots: Sequence[int] = (2,),
    ray: str | None = None,
    out: Path | None = None,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Run the benchmark (``jobs`` runs at a time, in processes) in the given ``modes``
    (of :data:`MODES`), with the frontier explorer and, when given, the exploration
    ``policy`` (``module:factory``) too; returns (summary rows per scenario and policy,
    per-run rows). ``robots``: the team sizes, one summary row per scenario and size.

    ``ray``: run as Ray tasks (``""`` a local instance, or the cluster ``RAY_ADDRESS``
    names; else a cluster address; the ``MRSLAM_*`` variables reach the workers;
    :mod:`scenarios.sweep`) instead of the process pool; the rows are the same. ``out``: a
    new (or empty) folder that keeps every run's report, ``reports/<run>.json``, as it
    arrives, and the table, ``explore.md``, and ``summary.json`` at the end;
    :func:`summarise_reports` rebuilds the summary from it."""
    for mode in modes:
        _mode_config(mode)
    for size in robots:
        RunConfig(robots=size)  # refuses a bad size before any run
    check_policy(policy, EnvConfig())
    policies = [None] if policy is None else [None, policy]
    if out is not None:
        check_out_folder(out)
        (out / "reports").mkdir(parents=True, exist_ok=True)
    late = "late-oracle" in modes
    if late and "team" not in modes:
        raise ValueError("the late-oracle mode needs the team mode (it is given its transforms)")
    runs_of = [
        (scenario, seed, spec, size)
        for scenario in scenarios
        for size in robots
        for seed in seeds
        for spec in policies
    ]
    first = [mode for mode in modes if mode != "late-oracle"]
    tasks: list[Task] = [
        (index, *run)
        for index, run in enumerate(
            (scenario, seed, max_steps, spec, size, mode, None)
            for scenario, seed, spec, size in runs_of
            for mode in first
        )
    ]

    def arrived(report: dict[str, Any]) -> None:
        if out is not None:
            text = json.dumps(report, indent=2) + "\n"
            write_text_atomic(out / "reports" / f"{_report_name(report)}.json", text)
        if progress is not None:
            row = run_row(report)
            label = "" if policy is None else f" ({row['policy']})"
            label += "" if list(robots) == [2] else f", {row['robots']} robots"
            progress(f"{row['scenario']} seed {row['seed']} {row['mode']}{label}: t90 {row['t90']}")

    reports = run_tasks(_task, tasks, jobs=jobs, ray=ray, on_result=arrived)
    if late:  # then each team run's late oracle, given what that team run found
        team = {
            (b["scenario"], b["seed"], b["policy_spec"], b["robots"]): report
            for report in reports
            if (b := report["bench"])["mode"] == "team"
        }
        given = [
            (len(reports) + index, scenario, seed, max_steps, spec, size, "late-oracle", found)
            for index, (scenario, seed, spec, size) in enumerate(runs_of)
            for found in [late_oracle_given(team[(scenario, seed, spec, size)])]
        ]
        reports += run_tasks(_task, given, jobs=jobs, ray=ray, on_result=arrived)
    runs = [run_row(report) for report in reports]
    rows = _summary_rows(runs)
    if out is not None:
        write_text_atomic(out / "explore.md", format_explore_table(rows) + "\n")
        summary = json.dumps({"summary": rows, "runs": runs}, indent=2) + "\n"
        write_text_atomic(out / "summary.json", summary)
    return rows, runs


def check_out_folder(out: Path) -> None:
    """Refuse, before any run, an ``--out`` folder that is not new or empty (a sweep never
    mixes its reports with another's) or that cannot be created or written.

    Raises
    ------
    ValueError
        Naming the folder and the problem.
    """
    out = Path(out)
    if out.exists():
        if not out.is_dir() or any(out.iterdir()):
            raise ValueError(
                f"--out {out}: already exists and is not an empty folder (it may hold an "
                f"earlier sweep's reports: --from {out} rebuilds their table; choose a new "
                "--out to run again)"
            )
        where = out
    else:
        where = out.parent
        while not where.exists() and where != where.parent:
            where = where.parent
        if not where.is_dir():
            raise ValueError(f"--out {out}: cannot be created, {where} is not a folder")
    try:  # the only sure test of "can be written here" is writing
        with tempfile.TemporaryFile(dir=where):
            pass
    except OSError as error:
        raise ValueError(f"--out {out}: cannot write in {where} ({error.strerror})") from None


def summarise_reports(folder: Path) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(summary rows, per-run rows) rebuilt from the reports a sweep kept
    (``folder/reports/*.json``, or ``folder/*.json``): the same rows
    :func:`run_explore_benchmark` returned, for the runs that are there."""
    files = sorted((folder / "reports").glob("*.json")) or sorted(
        f for f in folder.glob("*.json") if f.name != "summary.json"
    )
    if not files:
        raise ValueError(f"{folder}: no run reports (reports/*.json) to summarise")
    keyed = []
    for file in files:
        try:
            report = json.loads(file.read_text(encoding="utf-8"))
            keyed.append((report["bench"]["index"], run_row(report)))
        except (json.JSONDecodeError, KeyError, TypeError) as error:
            raise ValueError(f"{file}: not a bench explore run report ({error!r})") from error
    runs = [row for _, row in sorted(keyed, key=lambda pair: pair[0])]
    return _summary_rows(runs), runs


def _summary_rows(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per scenario, team size and policy (in the runs' order), and the ``all``
    rows when there are several scenarios."""
    scenarios = list(dict.fromkeys(r["scenario"] for r in runs))
    sizes = list(dict.fromkeys(r["robots"] for r in runs))
    labels = list(dict.fromkeys(r["policy"] for r in runs))
    rows = [
        _summarise(scenario, runs, policy=label, robots=size)
        for scenario in scenarios
        for size in sizes
        for label in labels
    ]
    if len(scenarios) > 1:
        rows += [
            _summarise(None, runs, policy=label, robots=size) for size in sizes for label in labels
        ]
    return rows


def _spread(values: Sequence[float]) -> tuple[float, float, float] | None:
    """(median, p90, max) of ``values``, or None when there are none."""
    if not values:
        return None
    data = np.asarray(values, dtype=np.float64)
    return (
        round(float(np.median(data)), 4),
        round(float(np.percentile(data, 90)), 4),
        round(float(np.max(data)), 4),
    )


def _summarise(
    scenario: str | None,
    runs: list[dict[str, Any]],
    *,
    policy: str | None = None,
    robots: int | None = None,
) -> dict[str, Any]:
    """The summary row of one scenario, or of all runs (``scenario=None``, named "all");
    of the runs of one ``policy`` (its label) and team size ``robots`` when given, else
    of all."""
    mine = [
        r
        for r in runs
        if (scenario is None or r["scenario"] == scenario)
        and (policy is None or r.get("policy", "frontier") == policy)
        and (robots is None or r.get("robots", 2) == robots)
    ]
    by_mode = {mode: [r for r in mine if r["mode"] == mode] for mode in MODES}
    t90 = {
        mode: round(statistics.fmean(r["t90_or_limit"] for r in chosen), 1)
        for mode, chosen in by_mode.items()
        if chosen
    }
    team, solo = by_mode["team"], by_mode["independent"]
    solo_time = {(r["scenario"], r["seed"]): r["t90_or_limit"] for r in solo}
    faster = sum(
        r["t90_or_limit"] < solo_time.get((r["scenario"], r["seed"]), -math.inf) for r in team
    )
    verified = [r for r in team if r["verified"]]
    wrong = [r for r in verified if is_wrong(r["translation_error"], r["rotation_error"])]
    t_team, t_solo, t_oracle = t90.get("team"), t90.get("independent"), t90.get("oracle")
    share = None
    if t_team is not None and t_solo is not None and t_oracle is not None:
        share = oracle_gain_share(t_solo, t_team, t_oracle)
    t_late = t90.get("late-oracle")
    late_share = None
    if t_late is not None and t_solo is not None and t_oracle is not None:
        late_share = oracle_gain_share(t_solo, t_late, t_oracle)
    collisions: dict[str, dict[str, float]] = {}
    for mode, chosen in by_mode.items():
        if not chosen:
            continue
        counts = [r["collision_steps"] for r in chosen]
        shares = [100.0 * r["collision_steps"] / max(r["robot_steps"], 1) for r in chosen]
        collisions[mode] = {
            "median": float(statistics.median(counts)),
            "max": float(max(counts)),
            "median_percent": round(float(statistics.median(shares)), 3),
        }
    translation = _spread([r["translation_error"] for r in verified])
    rotation = _spread([r["rotation_error"] for r in verified])
    return {
        "scenario": "all" if scenario is None else scenario,
        "policy": "frontier" if policy is None else policy,
        "robots": 2 if robots is None else robots,
        "runs": len(team),
        "faster": faster,
        "t90": t90,
        "t90_coordinated": t_team,
        "t90_independent": t_solo,
        "speedup": round(t_solo / t_team, 3) if t_team and t_solo is not None else None,
        "oracle_gain_share": None if share is None else round(share, 3),
        "late_oracle_gain_share": None if late_share is None else round(late_share, 3),
        "gain_over_independent": {
            mode: _paired(solo, by_mode[mode]) for mode in ("team", "late-oracle", "oracle")
        },
        "unfinished": {
            mode: sum(r["t90"] is None for r in chosen)
            for mode, chosen in by_mode.items()
            if chosen
        },
        "unfinished_coordinated": sum(r["t90"] is None for r in team),
        "unfinished_independent": sum(r["t90"] is None for r in solo),
        "verified": len(verified),
        "joined": sum(r.get("joined", int(r["verified"])) for r in team),
        "joinable": sum(r.get("robots", 2) - 1 for r in team),
        "wrong_accepted": len(wrong),
        "translation_error": translation,
        "rotation_error": rotation,
        "max_translation_error": None if translation is None else translation[2],
        "max_rotation_error": None if rotation is None else rotation[2],
        "hypotheses_tested": sum(r["hypotheses_tested"] for r in team),
        "verified_before_t90": sum(r.get("verified_before_t90", False) for r in team),
        "seeking_steps": sum(r.get("seeking_steps", 0) for r in team),
        "rendezvous_steps": (
            None
            if all(r.get("rendezvous_steps") is None for r in team)
            else sum(r.get("rendezvous_steps") or 0 for r in team)
        ),
        "steps_after_coverage": sum(r.get("steps_after_coverage", 0) for r in team),
        "collisions": collisions,
    }


def _paired(
    baseline: Sequence[dict[str, Any]], runs: Sequence[dict[str, Any]]
) -> dict[str, float | int | None] | None:
    """``baseline`` t90 minus ``runs`` t90 over the runs of the same scenario, seed, policy
    and team size (s; at the time limit for a run that never got there): the mean, the
    half-width of its 95 % confidence interval (Student's t; None for fewer than two
    pairs) and the number of pairs; None without a pair."""
    times = {
        (r["scenario"], r["seed"], r.get("policy"), r.get("robots")): r["t90_or_limit"]
        for r in baseline
    }
    differences = [
        times[key] - r["t90_or_limit"]
        for r in runs
        if (key := (r["scenario"], r["seed"], r.get("policy"), r.get("robots"))) in times
    ]
    if not differences:
        return None
    n = len(differences)
    half = None
    if n > 1:
        spread = statistics.stdev(differences) / math.sqrt(n)
        half = round(float(stats.t.ppf(0.975, n - 1)) * spread, 1)
    return {"mean": round(statistics.fmean(differences), 1), "ci95": half, "n": n}


def _gain_text(row: dict[str, Any], mode: str) -> str:
    paired = row.get("gain_over_independent", {}).get(mode)
    if paired is None:
        return "-"
    half = paired["ci95"]
    return f"{paired['mean']:+.1f}" + ("" if half is None else f" ± {half:.1f}")


def _time(row: dict[str, Any], mode: str) -> str:
    value = row["t90"].get(mode)
    if value is None:
        return "-"
    unfinished = row["unfinished"].get(mode, 0)
    return f"{value:.1f}" + (f" ({unfinished}✗)" if unfinished else "")


def format_explore_table(rows: Sequence[dict[str, Any]]) -> str:
    """The summary as a markdown table. A t90 with "(n✗)" includes n runs that never
    reached 90 % (counted at their time limit). Rows of more than one policy get a
    ``policy`` column after the scenario."""
    by_policy = len({row.get("policy", "frontier") for row in rows}) > 1
    by_size = {row.get("robots", 2) for row in rows} != {2}
    lines = [
        "| scenario | "
        + ("policy | " if by_policy else "")
        + ("robots | joined | " if by_size else "")
        + "t90 team (s) | t90 independent (s) | t90 oracle (s) | t90 late oracle (s) | "
        "t90 single (s) | speed-up indep/team | share of oracle gain | "
        "late oracle's share | indep − team (s, paired, 95 % CI) | "
        "indep − late oracle (s, paired) | faster | verified | wrong accepted | "
        "error m med / p90 / max | error ° med / p90 / max | "
        "collision steps team med / max (% steps) | hypotheses tested | "
        "verified before t90 | contact seeking (robot-steps) | rendezvous (robot-steps) | "
        "steps after coverage |",
        "| --- | "
        + ("--- | " if by_policy else "")
        + ("---: | ---: | " if by_size else "")
        + "---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: "
        "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in rows:
        rendezvous = row.get("rendezvous_steps")
        rendezvous_text = "-" if rendezvous is None else str(rendezvous)
        translation, rotation = row["translation_error"], row["rotation_error"]
        t_error = "-" if translation is None else " / ".join(f"{v:.3f}" for v in translation)
        r_error = "-" if rotation is None else " / ".join(f"{v:.2f}" for v in rotation)
        speedup = "-" if row["speedup"] is None else f"{row['speedup']:.2f}×"
        share_text = " | ".join(
            "-" if value is None else f"{value:.0%}"
            for value in (row["oracle_gain_share"], row.get("late_oracle_gain_share"))
        )
        team_collisions = row["collisions"].get("team")
        if team_collisions is None:
            collisions = "-"
        else:
            collisions = (
                f"{team_collisions['median']:.0f} / {team_collisions['max']:.0f} "
                f"({team_collisions['median_percent']:.1f} %)"
            )
        policy = f" {row.get('policy', 'frontier')} |" if by_policy else ""
        if by_size:
            policy += f" {row['robots']} | {row['joined']}/{row['joinable']} |"
        lines.append(
            f"| {row['scenario']} |{policy} {_time(row, 'team')} | {_time(row, 'independent')} | "
            f"{_time(row, 'oracle')} | {_time(row, 'late-oracle')} | {_time(row, 'single')} | "
            f"{speedup} | {share_text} | {_gain_text(row, 'team')} | "
            f"{_gain_text(row, 'late-oracle')} | "
            f"{row['faster']}/{row['runs']} | {row['verified']}/{row['runs']} | "
            f"{row['wrong_accepted']} | {t_error} | {r_error} | {collisions} | "
            f"{row['hypotheses_tested']} | {row.get('verified_before_t90', 0)}/{row['runs']} | "
            f"{row.get('seeking_steps', 0)} | {rendezvous_text} | "
            f"{row.get('steps_after_coverage', 0)} |"
        )
    return "\n".join(lines)
