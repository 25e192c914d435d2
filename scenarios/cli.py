"""The ``mrslam`` command line.

``mrslam run``                 the end-to-end experiment on the default scenario
``mrslam merge M1.yaml M2.yaml [M3.yaml ...]`` merge ROS map files into the first's frame
``mrslam scenarios``           list worlds; ``--export NAME OUT.yaml`` writes a floor plan
``mrslam bench sim``           simulator speed, side by side with IR-SIM
``mrslam bench slam``          onboard SLAM accuracy (ATE, map agreement) and speed
``mrslam bench explore``       time to 90 % coverage: team, independent, oracle, one robot
``mrslam bench soak``          one long run with SLAM and the team: steps/s and memory
``mrslam bench merge``         map merging: our pipeline against the random walk alone and
                               the ROS map_merge feature baseline, on simulated map pairs
                               (``--set cuts``: on pairs cut from the real map files)
``mrslam --version``           the installed version

Exit codes: 0 done; 2 bad input (unknown scenario, unreadable map, bad values, an output
that would overwrite an input), printed as one line ``mrslam: error: ...``; 3 ``mrslam
merge`` found no confident merge (the transform is null and the reason is printed); 1 an
unexpected failure (one line; ``--debug`` shows the traceback); 130 / 143 / 129
interrupted by Ctrl-C (SIGINT) / SIGTERM / SIGHUP (the terminal or ssh session closed),
128 + the signal's number as shells report it.

Signals (scenarios/interrupts.py): ``mrslam run`` notes the signal and stops between two
steps, writes its outputs (the report marked incomplete) and exits 130 / 143 / 129. Any
other command is ended by the signal at once: one line ``mrslam: interrupted by SIGINT``
on stderr, then the process ends by the signal itself (shells report 130 / 143 / 129;
Python's ``subprocess`` a returncode of -2 / -15 / -1). No Python exception is ever
raised inside C code (a pymunk callback, a numba kernel), so none is swallowed and
nothing crashes. Outputs are written under temporary names and renamed
(mrslam_env/atomic.py), so an interrupted command never leaves a half-written output; a
hidden temporary file (``.NAME.XXXX.part.EXT``) may remain, as after a kill. This holds
for the ``mrslam`` console script; ``main()`` called from Python installs no such
handler (a Ctrl-C there is Python's ``KeyboardInterrupt``: one line, status 130).

Outputs: every command that writes checks its outputs before any work: an output that is
one of its inputs (a map YAML or its image, also through links) or cannot be written is
refused, and an existing output is refused unless ``--overwrite``. Folders: ``mrslam run``
never writes into an existing folder: it creates ``<out>/<name>``, or the next free
``<name>-2``, ``<name>-3``, … when that exists (``--overwrite`` reuses ``<out>/<name>``
instead, deleting only the earlier run's outputs; scenarios/experiment.py); ``bench
explore --out`` refuses an existing folder that is not empty.
"""

from __future__ import annotations

from scenarios import interrupts

# First of all: as the console script, a Ctrl-C or SIGTERM is noted from here on, never
# raised in the middle of an import (see _cmd_run).
interrupts.install_for_console_script()

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, NoReturn  # noqa: E402

__all__ = ["main"]

EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2
EXIT_NO_MERGE = 3
EXIT_HUNG_UP = 129  # 128 + SIGHUP (terminal or ssh session closed), as shells report it
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM


def _exit_signalled(name: str) -> int:
    """The exit status of a command ended by the signal ``name`` (e.g. ``"SIGTERM"``)."""
    return {"SIGHUP": EXIT_HUNG_UP, "SIGINT": EXIT_INTERRUPTED}.get(name, EXIT_TERMINATED)


def _integer_from(minimum: int, what: str) -> Any:
    """An argparse type: an integer >= ``minimum``, refused as "must be ``what``"."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be {what}, got {value}")
        return value

    return parse


_count = _integer_from(1, "an integer >= 1")
"""argparse type of a count (steps, repeats, seeds, pairs, jobs)."""
_seed = _integer_from(0, "a non-negative integer")
"""argparse type of a seed."""


SLAM_MODES = ("slam", "pose_graph", "odometry", "ground_truth")
"""``mrslam run --slam-mode`` (mrslam_env.slam.config.SLAM_MODES, spelled out here: the
command line starts on the standard library alone)."""
MIN_RESOLUTION = 0.001
MAX_RESOLUTION = 1.0
"""The range of ``scenarios --export --resolution``, m/cell (real maps: 0.01 to 0.1)."""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mrslam")
    except PackageNotFoundError:  # run from a source tree that is not installed
        return "unknown (not installed)"


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line error and exit status 2 (usage goes to -h)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="mrslam", description="Multi-robot SLAM research toolkit.")
    parser.add_argument(
        "--debug", action="store_true", help="show the traceback of an unexpected failure"
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=_Parser
    )

    run = commands.add_parser("run", help="run the end-to-end experiment")
    run.add_argument("--scenario", default="office", help="scenario name (see `mrslam scenarios`)")
    run.add_argument("--map", type=Path, help="build the world from a ROS map YAML instead")
    run.add_argument("--seed", type=_seed, default=0)
    run.add_argument(
        "--max-steps",
        type=int,
        default=None,
        help="env steps of 0.1 s (default: from the building's reachable floor and the "
        "team size, at least 3000)",
    )
    run.add_argument(
        "--out", type=Path, default=Path("runs"), help="parent folder of the run folder"
    )
    run.add_argument(
        "--name",
        help="run folder name (default <scenario>-seed<seed>); a used, non-empty folder is "
        "never mixed: the run goes to <name>-2, <name>-3, ... unless --overwrite",
    )
    run.add_argument(
        "--overwrite",
        action="store_true",
        help="reuse the run folder, deleting the earlier run's outputs in it first",
    )
    run.add_argument("--no-record", action="store_true", help="do not write recording.rrd")
    run.add_argument(
        "--independent",
        action="store_true",
        help="the robots never interact (the no-coordination baseline)",
    )
    run.add_argument("--no-comm", action="store_true", help="the radio link never comes up")
    run.add_argument(
        "--stop-at-coverage",
        action="store_true",
        help="stop at the target coverage even if the team has not merged its maps yet",
    )
    run.add_argument(
        "--policy",
        metavar="MODULE:FACTORY",
        help="the robots' exploration policy: factory(env, rng) in an importable module or a "
        ".py file (default: the frontier explorer; see agents/policy.py)",
    )
    run.add_argument("--robots", type=int, default=2, help="team size, 2 to 8 (default 2)")
    run.add_argument(
        "--slam-mode",
        choices=SLAM_MODES,
        default="slam",
        help="each robot's onboard SLAM: slam (default), pose_graph (with loop closure), "
        "odometry or ground_truth",
    )
    run.add_argument("--json", action="store_true", help="print the report as JSON on stdout")

    merge = commands.add_parser(
        "merge",
        help="merge two or more ROS map files into the first one's frame "
        "(exit 0 merged, 3 no confident merge for some map, 2 bad input)",
    )
    merge.add_argument("maps", type=Path, nargs="+", metavar="MAP.yaml", help="2 or more maps")
    merge.add_argument(
        "-o",
        "--output",
        type=Path,
        help="write the merged map: NAME.yaml + NAME.pgm (NAME, NAME.yaml or NAME.pgm)",
    )
    merge.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    merge.add_argument("--rrd", type=Path, help="record the merge stages to this .rrd file")
    merge.add_argument("--seed", type=_seed, default=0, help="seed of the randomised stages")
    merge.add_argument(
        "--overwrite", action="store_true", help="replace an existing -o map or --rrd file"
    )

    scen = commands.add_parser("scenarios", help="list the worlds, or export one as a ROS map")
    scen.add_argument(
        "--export",
        nargs=2,
        metavar=("NAME", "OUT.yaml"),
        help="write NAME's ground-truth floor plan as a ROS map (PGM + YAML)",
    )
    scen.add_argument(
        "--resolution",
        type=float,
        default=0.05,
        help=f"export resolution, m/cell, {MIN_RESOLUTION} to {MAX_RESOLUTION} (default 0.05)",
    )
    scen.add_argument("--overwrite", action="store_true", help="replace an existing --export map")
    scen.add_argument("--json", action="store_true")

    bench = commands.add_parser("bench", help="benchmarks")
    kinds = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")
    sim = kinds.add_parser("sim", help="env steps per second, side by side with IR-SIM")
    sim.add_argument(
        "--scenarios", nargs="*", help="scenario names (default: all hand-made + procedural-0)"
    )
    sim.add_argument("--steps", type=_count, default=1000)
    sim.add_argument("--repeats", type=_count, default=3)
    sim.add_argument("--no-irsim", action="store_true", help="skip the IR-SIM comparison")
    sim.add_argument(
        "--rl",
        action="store_true",
        help="agent-steps/s of the RL configurations (parallel env Dict/flat, SLAM off/on; "
        "single-robot env; AsyncVectorEnv of 2) on the first scenario (default office), and "
        "the frontier teammate's ms/step",
    )
    sim.add_argument("--json", action="store_true")
    slam = kinds.add_parser("slam", help="onboard SLAM: ATE against odometry, map agreement, speed")
    slam.add_argument(
        "--scenarios",
        nargs="*",
        help="scenario names (default: the built-in five and the six real buildings)",
    )
    slam.add_argument("--steps", type=_count, default=3000, help="env steps per run (default 3000)")
    slam.add_argument("--seed", type=_seed, default=0)
    slam.add_argument("--json", action="store_true")
    explore = kinds.add_parser(
        "explore",
        help="time to 90 %% coverage: the team against independent robots, the oracle "
        "(relative pose known) and one robot alone",
    )
    explore.add_argument("--scenarios", nargs="*", help="scenario names (default: built-in five)")
    explore.add_argument("--seeds", type=_count, default=5, help="seeds 0..N-1 (default 5)")
    explore.add_argument("--max-steps", type=_count, default=4000, help="per run (default 4000)")
    explore.add_argument("--jobs", type=_count, default=1, help="runs at a time (default 1)")
    explore.add_argument(
        "--modes",
        default="team,independent,oracle,single,late-oracle",
        help="comma-separated runs per scenario and seed, of team, independent, oracle, "
        "single, late-oracle (independent robots given the team run's own transforms at "
        "its own verification step; needs team) (default: all five)",
    )
    explore.add_argument(
        "--policy",
        metavar="MODULE:FACTORY",
        help="also run this exploration policy (factory(env, rng)) on the same seeds; its "
        "rows appear beside the frontier explorer's",
    )
    explore.add_argument(
        "--robots",
        type=int,
        nargs="+",
        default=[2],
        metavar="N",
        help="team sizes, 2 to 8 (default 2); one row per scenario and size",
    )
    explore.add_argument(
        "--ray",
        nargs="?",
        const="",
        metavar="ADDRESS",
        help="run the runs as Ray tasks: alone, on a local Ray instance of --jobs CPUs (or on "
        "the cluster RAY_ADDRESS names); with an ADDRESS (e.g. auto, or the HOST:PORT ray start "
        "--head prints), on that cluster; the MRSLAM_* variables reach the workers "
        "(pip install 'mrslam[ray]')",
    )
    explore.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="keep every run's report (DIR/reports/*.json), the table (DIR/explore.md) and "
        "summary.json in DIR (new or empty)",
    )
    explore.add_argument(
        "--from",
        dest="from_dir",
        type=Path,
        metavar="DIR",
        help="run nothing: rebuild the table from the reports an --out DIR kept",
    )
    explore.add_argument("--json", action="store_true")
    soak = kinds.add_parser(
        "soak", help="one long run with SLAM and the team: steps/s and memory over time"
    )
    soak.add_argument("--scenario", default="office")
    soak.add_argument("--steps", type=_count, default=100_000, help="env steps (default 1e5)")
    soak.add_argument("--every", type=_count, default=10_000, help="steps between rows")
    soak.add_argument("--seed", type=_seed, default=0)
    soak.add_argument("--json", action="store_true")
    merge = kinds.add_parser(
        "merge", help="map merging: success, wrong answers, refusals and time per method"
    )
    merge.add_argument(
        "--pairs", type=_count, default=40, help="pairs of the built-in or custom set (default 40)"
    )
    merge.add_argument(
        "--set",
        choices=("both", "builtin", "real", "cuts"),
        default="both",
        help="default pair sets: the built-in worlds (--pairs), the real buildings "
        "(--real-pairs), or both side by side (default); cuts: pairs cut from the six real map "
        "files at their native resolution, map 2 turned by a random angle, with disjoint and "
        "different-building pairs (--cut-pairs); ignored with --worlds/--maps",
    )
    merge.add_argument(
        "--real-pairs", type=_count, default=24, help="pairs of the real-building set (default 24)"
    )
    merge.add_argument(
        "--cut-pairs", type=_count, default=24, help="pairs of the cut set (default 24)"
    )
    merge.add_argument(
        "--worlds",
        nargs="+",
        metavar="NAME",
        help="one custom set (--pairs) from these scenarios (built-in or real buildings)",
    )
    merge.add_argument(
        "--maps",
        nargs="+",
        type=Path,
        metavar="MAP.yaml",
        help="one custom set (--pairs) also from worlds built from these ROS map files",
    )
    merge.add_argument(
        "--native-resolution",
        action="store_true",
        help="custom set: run the SLAM at each map's own resolution (the real-building set "
        "always does; default: the SLAM's 0.05 m)",
    )
    merge.add_argument(
        "--variants",
        default="pad4000,yaw,res",
        help="variants ours and ours-nocrop also run on, on every set but the built-in one: "
        "pad4000, yaw, "
        "res, comma-separated, or none (default: pad4000,yaw,res)",
    )
    merge.add_argument("--seed", type=_seed, default=0)
    merge.add_argument(
        "--methods",
        default="ours,random-walk,features",
        help="comma-separated methods: ours, ours-nocrop, ours-cascade, random-walk, features, "
        "hough (default: ours,random-walk,features)",
    )
    merge.add_argument("--regenerate", action="store_true", help="rebuild the cached pairs")
    merge.add_argument(
        "--jobs",
        type=_count,
        default=1,
        help="worlds simulated at a time for new pairs (default 1)",
    )
    merge.add_argument(
        "--ray",
        nargs="?",
        const="",
        metavar="ADDRESS",
        help="simulate new pairs' worlds as Ray tasks: alone, on a local Ray instance of --jobs "
        "CPUs; with an ADDRESS, on that cluster (the merges themselves run here, timed one at "
        "a time)",
    )
    merge.add_argument(
        "--cache",
        type=Path,
        default=Path("runs") / "bench-merge-pairs",
        help="folder of the cached pairs (default runs/bench-merge-pairs)",
    )
    merge.add_argument(
        "--no-aliasing",
        action="store_true",
        help="skip the exhaustive placement searches that label how well each pair's maps "
        "single out the truth and which pairs no method can decide (a few seconds a pair "
        "each, cached with the pairs)",
    )
    merge.add_argument("--out", type=Path, help="per-pair results: .csv, else JSON")
    merge.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    merge.add_argument("--json", action="store_true", help="print the summary as JSON")
    return parser


def _cmd_run(args: argparse.Namespace) -> int:
    # SIGINT, SIGTERM and SIGHUP only note the signal, from before the heavy imports (the
    # console script) or from here (main() called from a program) to the last line
    # printed; the run looks at the note between its setup phases and its steps
    # (scenarios/experiment.py, "Interrupted runs"), so no handler ever raises inside a
    # numba kernel or a callback, and no signal is lost. The note ends with the command.
    try:
        with interrupts.noting_signals():
            return _run(args)
    finally:
        interrupts.end_console_script()


def kernels_compiled() -> bool:
    """Whether numba's cache holds compiled kernels of the package (an index file under
    ``NUMBA_CACHE_DIR``, or by default in the package's ``__pycache__`` folders)."""
    cache = os.environ.get("NUMBA_CACHE_DIR")
    root = Path(cache) if cache else Path(__file__).resolve().parents[1] / "mrslam_env"
    return next(root.rglob("*.nbi"), None) is not None


def _run(args: argparse.Namespace) -> int:
    if not kernels_compiled():
        print("mrslam: compiling the numba kernels once (about 40 s more)...", file=sys.stderr)
    from scenarios.experiment import RunConfig, run_experiment

    config = RunConfig(
        scenario=args.scenario,
        map_path=args.map,
        seed=args.seed,
        max_steps=args.max_steps,
        out=args.out,
        name=args.name,
        record=not args.no_record,
        interaction=not args.independent,
        comm=not args.no_comm,
        until_merged=not args.stop_at_coverage,
        policy=args.policy,
        robots=args.robots,
        slam_mode=args.slam_mode,
        progress=not args.json,
        overwrite=args.overwrite,
    )
    report = run_experiment(config)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        merge = report["merge"]
        if merge["verified"]:
            worst = "error" if report["robots"] == 2 else "worst error"
            merged = (
                f"merge verified at step {merge['step_first_joined']} "
                f"({merge['hypotheses_tested']} hypotheses tested), {worst} "
                f"{merge['worst_translation_error_m']:.3f} m / "
                f"{merge['worst_rotation_error_deg']:.2f}°"
            )
        else:
            merged = f"no merge ({merge['hypotheses_tested']} hypotheses tested)"
        if report["robots"] > 2:
            merged += f"; {merge['joined']} of {report['robots'] - 1} robots joined robot_0's frame"
        coverage = report["coverage"]["merged"]
        print(
            f"{report['scenario']}: {report['steps']} steps "
            f"({report['sim_time_s']:.0f} s simulated) in {report['wall_time_s']:.1f} s; "
            f"{merged}; coverage {coverage:.0%}"
        )
        print(f"outputs in {report['outputs']['run_dir']}")
    # A signal noted after report.json was written still ends the command as a signal does.
    interrupted = report["interrupted"] or interrupts.received()
    if interrupted is not None:
        done = "partial outputs" if not report["complete"] else "the run had ended; outputs"
        print(
            f"mrslam: interrupted by {interrupted} after {report['steps']} steps; "
            f"{done} in {report['outputs']['run_dir']}",
            file=sys.stderr,
        )
        return _exit_signalled(interrupted)
    return 0


def _cmd_merge(args: argparse.Namespace) -> int:
    import numpy as np

    from mrslam_env.mapio import load_map, map_images, map_yaml_path, save_map
    from mrslam_env.merge.pipeline import merge_maps

    if len(args.maps) < 2:
        raise ValueError(f"merge needs at least two maps, got {len(args.maps)}")
    if len(args.maps) > 2 and args.rrd is not None:
        raise ValueError("--rrd records the stages of a two-map merge; give two maps")
    grids = [load_map(path) for path in args.maps]
    inputs = [*args.maps, *map_images(*args.maps)]
    outputs = []
    if args.output is not None:
        if args.output.is_dir():
            raise ValueError(f"output {args.output} is a folder; name a file (NAME.yaml)")
        output_yaml = map_yaml_path(args.output)
        outputs += [output_yaml, output_yaml.with_suffix(".pgm")]
    if args.rrd is not None:
        outputs.append(args.rrd)
    check_outputs(outputs, inputs, overwrite=args.overwrite)
    if len(grids) > 2:
        return _merge_many(args, grids)
    m1, m2 = grids
    result = merge_maps(m1, m2, rng=np.random.default_rng(args.seed), trace=args.rrd is not None)
    if result.fused is not None and args.output is not None:
        args.output = save_map(args.output, result.fused)
    if args.rrd is not None:
        from mrslam_env.atomic import atomic_path
        from mrslam_env.recording import Recorder

        with atomic_path(args.rrd) as temporary, Recorder(temporary, n_robots=2) as recorder:
            recorder.log_merge(result, m1, m2)
    if args.json:
        print(json.dumps(result.as_dict(), indent=2))
    elif result.transform is not None:
        x, y, theta = result.transform
        print(f"map1_from_map2: x {x:.4f} m, y {y:.4f} m, theta {math.degrees(theta):.3f}°")
        print(result.reason)
        if args.output is not None:
            print(f"merged map written to {args.output}")
    else:
        print(result.reason)
    return 0 if result.transform is not None else EXIT_NO_MERGE


def _merge_many(args: argparse.Namespace, grids: list[Any]) -> int:
    """``mrslam merge A B C ...``: every map into A's frame; exit 3 if any is unmerged."""
    from mrslam_env.mapio import save_map
    from mrslam_env.merge.many import merge_many

    result = merge_many(grids, rng=args.seed)
    names = [str(path) for path in args.maps]

    def pose(transform: Any) -> dict[str, float] | None:
        if transform is None:
            return None
        x, y, theta = (float(v) for v in transform)
        return {"x": x, "y": y, "theta": theta}

    if args.output is not None:
        args.output = save_map(args.output, result.fused)
    if args.json:
        report = {
            "maps": names,
            "transforms": {name: pose(t) for name, t in zip(names, result.transforms, strict=True)},
            "unmerged": [names[k] for k in result.unmerged],
            "tree": [[names[a], names[b]] for a, b in result.tree],
            "inconsistent": [[names[a], names[b]] for a, b in result.inconsistent],
            "pairs": [
                {"map1": names[i], "map2": names[j], **pair.as_dict()}
                for (i, j), pair in result.pairs.items()
            ],
            "seconds": round(sum(p.seconds.get("total", 0.0) for p in result.pairs.values()), 4),
        }
        print(json.dumps(report, indent=2))
    else:
        for name, transform in zip(names[1:], result.transforms[1:], strict=True):
            if transform is None:
                print(f"{name}: no confident merge with any map")
            else:
                x, y, theta = transform
                print(
                    f"{name}: map0_from_map x {x:.4f} m, y {y:.4f} m, "
                    f"theta {math.degrees(theta):.3f}°"
                )
        for a, b in result.inconsistent:
            print(f"warning: the merge of {names[a]} and {names[b]} contradicts the others")
        if args.output is not None:
            print(f"merged map written to {args.output}")
    return EXIT_NO_MERGE if result.unmerged else 0


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from mrslam_env.registry import available_scenarios, build_world

    if args.export:
        from mrslam_env.mapio import check_grid_size, map_images, map_yaml_path, save_map
        from mrslam_env.sim.world import ground_truth_map
        from scenarios.worlds.real import REAL_BUILDINGS, map_file

        name, out = args.export
        if not MIN_RESOLUTION <= args.resolution <= MAX_RESOLUTION:  # also nan and inf
            raise ValueError(
                f"--resolution must lie in [{MIN_RESOLUTION}, {MAX_RESOLUTION}] m/cell, "
                f"got {args.resolution}"
            )
        world = build_world(name)
        xmin, ymin, xmax, ymax = world.bounds
        check_grid_size(
            ((ymax - ymin + 1.0) / args.resolution, (xmax - xmin + 1.0) / args.resolution),
            f"{name} at {args.resolution} m/cell",
        )
        output_yaml = map_yaml_path(out)
        inputs: list[Path] = []
        if name in REAL_BUILDINGS:  # the packaged map it is built from
            inputs = [map_file(name), *map_images(map_file(name))]
        outputs = [output_yaml, output_yaml.with_suffix(".pgm")]
        check_outputs(outputs, inputs, overwrite=args.overwrite)
        path = save_map(output_yaml, ground_truth_map(world, args.resolution, margin=0.5))
        print(f"wrote {path}")
        return 0
    catalogue = available_scenarios()
    rows = [
        {"name": f"{key}[-SEED]" if s.parametric else key, "description": s.description}
        for key, s in sorted(catalogue.items())
    ]
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        width = max(len(r["name"]) for r in rows)
        for r in rows:
            print(f"{r['name']:<{width}}  {r['description']}")
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    if args.bench == "slam":
        return _cmd_bench_slam(args)
    if args.bench == "merge":
        return _cmd_bench_merge(args)
    if args.bench == "explore":
        return _cmd_bench_explore(args)
    if args.bench == "soak":
        return _cmd_bench_soak(args)
    if args.rl:
        return _cmd_bench_sim_rl(args)
    from mrslam_env.registry import available_scenarios, build_world
    from scenarios.bench.sim import bench_sim

    names = args.scenarios or [
        ("procedural-0" if s.parametric else key)
        for key, s in sorted(available_scenarios().items())
    ]
    worlds = {name: build_world(name) for name in names}
    rows = bench_sim(worlds, n_steps=args.steps, repeats=args.repeats, irsim=not args.no_irsim)
    if args.json:
        print(json.dumps([row.as_dict() for row in rows], indent=2))
        return 0
    print(f"env steps/s, 2 robots x 360 beams, median of {args.repeats} x {args.steps} steps")
    print(f"{'scenario':<14} {'mrslam':>10} {'IR-SIM':>10} {'ratio':>7} {'with SLAM':>10}")
    for row in rows:
        theirs = "-" if row.irsim_steps_per_s is None else f"{row.irsim_steps_per_s:10.0f}"
        ratio = "-" if row.ratio is None else f"{row.ratio:6.1f}x"
        slam = "-" if row.with_slam_steps_per_s is None else f"{row.with_slam_steps_per_s:10.0f}"
        print(
            f"{row.scenario:<14} {row.mrslam_steps_per_s:>10.0f} {theirs:>10} {ratio:>7} {slam:>10}"
        )
    return 0


def _cmd_bench_sim_rl(args: argparse.Namespace) -> int:
    from scenarios.bench.sim import bench_rl

    scenario = args.scenarios[0] if args.scenarios else "office"
    rows, teammate = bench_rl(scenario, n_steps=args.steps, repeats=args.repeats)
    if args.json:
        out = {"scenario": scenario, "rows": [row.as_dict() for row in rows]}
        print(json.dumps({**out, "teammate": teammate.as_dict()}, indent=2))
        return 0
    print(f"{scenario}: 2 robots x 360 beams, median of {args.repeats} x {args.steps} steps")
    print(f"{'configuration':<60} {'agent-steps/s':>13} {'env steps/s':>11}")
    for row in rows:
        print(
            f"{row.configuration:<60} {row.agent_steps_per_s:>13.0f} {row.env_steps_per_s:>11.0f}"
        )
    print(
        f"frontier teammate: {teammate.explorer_ms_per_step:.2f} ms/step explorer, "
        f"{teammate.robot_map_ms_per_step:.2f} ms/step reading its map, "
        f"{teammate.replans_per_100_steps:.1f} replans per 100 steps"
    )
    return 0


def _cmd_bench_slam(args: argparse.Namespace) -> int:
    from scenarios.bench.slam import (
        DEFAULT_SCENARIOS,
        format_slam_table,
        run_slam_benchmark,
        warm_up,
    )

    warm_up()  # compile/load the numba kernels before anything is timed
    rows = run_slam_benchmark(args.scenarios or DEFAULT_SCENARIOS, args.steps, args.seed)
    print(json.dumps(rows, indent=2) if args.json else format_slam_table(rows))
    return 0


def _cmd_bench_soak(args: argparse.Namespace) -> int:
    from scenarios.bench.soak import format_soak_table, run_soak

    def progress(row: dict[str, object]) -> None:
        print(
            f"step {row['step']}: {row['steps_per_s']} steps/s, RSS {row['rss_mb']} MB",
            file=sys.stderr,
            flush=True,
        )

    rows = run_soak(args.scenario, args.steps, args.every, args.seed, progress=progress)
    print(json.dumps(rows, indent=2) if args.json else format_soak_table(rows))
    return 0


def _cmd_bench_explore(args: argparse.Namespace) -> int:
    from scenarios.bench.explore import format_explore_table, summarise_reports

    if args.from_dir is not None:
        if args.out is not None:
            raise ValueError("--out keeps the reports of a run; --from runs nothing: give one")
        rows, runs = summarise_reports(args.from_dir)
    else:
        rows, runs = _run_bench_explore(args)
    if args.json:
        print(json.dumps({"summary": rows, "runs": runs}, indent=2))
    else:
        print(format_explore_table(rows))
    return 0


def _run_bench_explore(
    args: argparse.Namespace,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    from scenarios.bench.explore import DEFAULT_SCENARIOS, MODES, run_explore_benchmark

    modes = [mode.strip() for mode in args.modes.split(",") if mode.strip()]
    unknown = [mode for mode in modes if mode not in MODES]
    if not modes or unknown:
        raise ValueError(f"--modes must name some of {', '.join(MODES)}, got {args.modes!r}")
    return run_explore_benchmark(
        args.scenarios or DEFAULT_SCENARIOS,
        range(args.seeds),
        args.max_steps,
        modes=modes,
        jobs=args.jobs,
        progress=None if args.json else lambda text: print(text, file=sys.stderr),
        policy=args.policy,
        robots=args.robots,
        ray=args.ray,
        out=args.out,
    )


def _cmd_bench_merge(args: argparse.Namespace) -> int:
    from scenarios.bench.merge.aliasing import load_or_compute_aliasing
    from scenarios.bench.merge.cuts import CutConfig, load_or_generate_cut_pairs
    from scenarios.bench.merge.methods import resolve_methods
    from scenarios.bench.merge.pairs import (
        REAL_WORLDS,
        PairGenerationConfig,
        load_or_generate_pairs,
    )
    from scenarios.bench.merge.report import (
        format_aliasing_breakdown,
        format_family_breakdown,
        format_merge_table,
        format_scenario_breakdown,
        format_twin_breakdown,
        summarize,
        write_rows,
    )
    from scenarios.bench.merge.run import VARIANTS, run_merge_benchmark
    from scenarios.bench.merge.twins import load_or_compute_world_twins

    names = [name.strip() for name in args.methods.split(",") if name.strip()]
    if not names:
        raise ValueError("--methods names no method")
    variants = [v.strip() for v in args.variants.split(",") if v.strip() and v.strip() != "none"]
    for variant in variants:
        if variant not in VARIANTS:
            raise ValueError(f"unknown variant {variant!r}; variants are {', '.join(VARIANTS)}")
    methods, skipped = resolve_methods(names)
    if args.out is not None:  # the maps read and their images are never written over
        from contextlib import suppress

        from mrslam_env.mapio import MapFileError, map_images

        inputs = list(args.maps or ())
        for path in args.maps or ():
            with suppress(MapFileError):  # reported when the pairs are made, before --out
                inputs += map_images(path)
        check_outputs([args.out], inputs, overwrite=args.overwrite)

    def progress(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    # (title, config, variants); the built-in set's config is the historical default, so
    # its cache key and figures stay comparable across releases
    sets: list[tuple[str, PairGenerationConfig | CutConfig, list[str]]] = []
    if args.worlds or args.maps:
        config = PairGenerationConfig(
            n_pairs=args.pairs,
            seed=args.seed,
            worlds=tuple(args.worlds or ()),
            maps=tuple(str(path) for path in args.maps or ()),
            native_resolution=args.native_resolution,
        )
        sets.append((f"custom: {', '.join(config.labels())}", config, variants))
    else:
        if args.set in ("both", "builtin"):
            config = PairGenerationConfig(n_pairs=args.pairs, seed=args.seed)
            sets.append(("built-in worlds", config, []))
        if args.set in ("both", "real"):
            config = PairGenerationConfig(
                n_pairs=args.real_pairs, seed=args.seed, worlds=REAL_WORLDS, native_resolution=True
            )
            sets.append(("real buildings", config, variants))
        if args.set == "cuts":
            sets.append(
                (
                    "cut from the real maps",
                    CutConfig(n_pairs=args.cut_pairs, seed=args.seed),
                    variants,
                )
            )

    all_rows: list[dict[str, Any]] = []
    results = []
    for title, pair_set, set_variants in sets:
        if isinstance(pair_set, CutConfig):
            pairs, manifest = load_or_generate_cut_pairs(
                pair_set, args.cache, regenerate=args.regenerate, progress=progress
            )
        else:
            pairs, manifest = load_or_generate_pairs(
                pair_set,
                args.cache,
                regenerate=args.regenerate,
                progress=progress,
                jobs=args.jobs,
                ray=args.ray,
            )
        rows = run_merge_benchmark(
            pairs, methods, seed=args.seed, variants=set_variants, progress=progress
        )
        if not args.no_aliasing:
            folder = Path(args.cache) / pair_set.cache_key()
            labels = load_or_compute_aliasing(pairs, folder, progress=progress)
            for row in rows:
                found = labels.get(row["pair_id"])
                row["aliasing"] = None if found is None else found.label
                row["aliasing_ratio"] = None if found is None else found.ratio
                row["aliasing_dominated"] = None if found is None else found.dominated
            if isinstance(pair_set, PairGenerationConfig):  # cut pairs have no world
                twins = load_or_compute_world_twins(
                    pairs, folder, worlds=pair_set.world, progress=progress
                )
                for row in rows:
                    twin = twins.get(row["pair_id"])
                    row["undecidable"] = None if twin is None else twin.undecidable
                    row["twin_overlap"] = None if twin is None else twin.twin_overlap
        bases = [m for m in ("ours", "ours-nocrop") if m in methods]
        columns = list(methods) + [f"{m}+{v}" for v in set_variants for m in bases]
        for row in rows:
            row["pair_set"] = title
        all_rows.extend(rows)
        results.append((title, pairs, manifest, rows, summarize(rows, columns), columns))

    first = results[0]
    generation = {
        "pairs": sum(len(r[1]) for r in results),
        "generation_seconds": sum(r[2]["generation_seconds"] for r in results),
        "shortfall": sum(r[2]["shortfall"] for r in results),
    }
    report = {
        "summary": first[4],
        "skipped": skipped,
        **generation,
        "sets": {
            title: {
                "summary": summary,
                "pairs": len(pairs),
                "generation_seconds": manifest["generation_seconds"],
                "shortfall": manifest["shortfall"],
            }
            for title, pairs, manifest, _, summary, _ in results
        },
    }
    if args.out is not None:
        write_rows(args.out, all_rows, report)
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    for number, (title, pairs, manifest, rows, summary, _) in enumerate(results):
        if number:
            print()
        if len(results) > 1 or title.startswith("custom"):
            print(f"## {title}")
        print(
            f"{len(pairs)} pairs ({sum(p.overlapping() for p in pairs)} overlapping), "
            f"generated in {manifest['generation_seconds']:.0f} s"
        )
        print(format_merge_table(summary, skipped))
        if "ours" in methods:
            print()
            print(format_scenario_breakdown(rows))
            for breakdown in (format_aliasing_breakdown(rows), format_twin_breakdown(rows)):
                if breakdown:
                    print()
                    print(breakdown)
    families = {row["family"] for row in all_rows}
    if len(results) > 1 or len(families) > 1:
        print()
        print("## per world family")
        columns = list(dict.fromkeys(c for result in results for c in result[5]))
        print(format_family_breakdown(all_rows, columns))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mrslam`` console script; returns the exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    handlers = {
        "run": _cmd_run,
        "merge": _cmd_merge,
        "scenarios": _cmd_scenarios,
        "bench": _cmd_bench,
    }
    try:
        if args.command != "run":
            # As the console script, a signal ends any other command at once, by the signal
            # itself, with one line (a signal noted while the modules loaded: now); never a
            # KeyboardInterrupt inside C code (module docstring). main() called from a
            # program installs nothing: there a Ctrl-C stays Python's KeyboardInterrupt.
            interrupts.end_on_signals()
        return handlers[args.command](args)
    except KeyboardInterrupt as stop:
        name = getattr(stop, "signal_name", "SIGINT")
        before = args.command == "run" and isinstance(stop, interrupts.RunInterrupted)
        detail = " before the run folder was made; nothing written" if before else ""
        print(f"mrslam: interrupted by {name}{detail}", file=sys.stderr)
        return _exit_signalled(name)
    except (ValueError, OSError, MemoryError) as error:
        if args.debug:
            raise
        print(f"mrslam: error: {_one_line(error)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as error:
        if args.debug:
            raise
        print(
            f"mrslam: unexpected error: {type(error).__name__}: {_one_line(error)} "
            "(run again with --debug for the traceback)",
            file=sys.stderr,
        )
        return EXIT_FAILURE


def _one_line(error: BaseException) -> str:
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


def check_outputs(
    outputs: Sequence[Path], inputs: Sequence[Path], *, overwrite: bool = False
) -> None:
    """Refuse, before any work, output files that would overwrite an input or cannot be
    written: the same file as an input (also through links), an existing folder, a missing
    or read-only folder; and an existing file unless ``overwrite`` (``--overwrite``).

    Raises
    ------
    ValueError
        Naming the output and the problem.
    """
    resolved_inputs = {Path(p).resolve() for p in inputs}
    seen: set[Path] = set()
    for output in outputs:
        output = Path(output)
        if output.resolve() in resolved_inputs:
            raise ValueError(f"output {output} would overwrite an input file")
        if output.resolve() in seen:
            raise ValueError(f"two outputs are the same file: {output}")
        seen.add(output.resolve())
        if output.is_dir():
            raise ValueError(f"output {output} is a folder; name a file")
        if output.exists() and not overwrite:
            raise ValueError(f"output {output} exists; --overwrite replaces it")
        if not output.parent.is_dir():
            raise ValueError(f"output folder {output.parent} does not exist")
        try:  # the only sure test of "can be written here" is writing
            with tempfile.TemporaryFile(dir=output.parent):
                pass
        except OSError as error:
            raise ValueError(f"cannot write in {output.parent} ({error.strerror})") from None


if __name__ == "__main__":
    sys.exit(main())
