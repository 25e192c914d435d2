"""The whole experiment behind ``mrslam run``, from Python.

Two robots that do not know where the other started explore with onboard SLAM; when their
radio link is up they exchange and merge maps, drive to a rendezvous to verify the best
hypothesis with their peer sensor, then explore the merged map together. Writes
recording.rrd (open with ``rerun``), report.json, the ROS maps and figure.png.

Run: python examples/04_full_experiment.py [OUT_DIR] [--steps 3000] [--scenario office]
"""

import argparse
import tempfile
from pathlib import Path

from scenarios.experiment import RunConfig, run_experiment

parser = argparse.ArgumentParser()
parser.add_argument("out", nargs="?", help="output folder (default: a temporary folder)")
parser.add_argument("--steps", type=int, default=3000, help="at most this many 0.1 s steps")
parser.add_argument("--scenario", default="office")
args = parser.parse_args()

out = Path(args.out or tempfile.mkdtemp())
config = RunConfig(scenario=args.scenario, seed=0, max_steps=args.steps, out=out, name="run")
report = run_experiment(config)  # stops at 95 % coverage or after --steps

merge = report["merge"]
print(f"{report['steps']} steps ({report['sim_time_s']} s simulated) in {report['wall_time_s']} s")
print(f"team state: {report['team_state']}; coverage {report['coverage']['merged']:.1%}")
if merge["verified"]:
    print(
        f"merge verified at step {merge['step_first_joined']} after testing "
        f"{merge['hypotheses_tested']} hypotheses: error {merge['worst_translation_error_m']} m, "
        f"{merge['worst_rotation_error_deg']}°"
    )
else:
    print("no verified merge (try more --steps)")
run_dir = Path(report["outputs"]["run_dir"])
print(f"wrote {run_dir}:", ", ".join(sorted(path.name for path in run_dir.iterdir())))
