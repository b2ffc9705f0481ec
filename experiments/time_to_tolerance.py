"""The time-to-tolerance yardstick with learned policies: how soon each policy reaches the tolerances.

Every policy stops by the same information state (``stop=information``) on the practitioner's sensors
(``+experiment=time_to_tolerance_<task>``, held-out seeds 50000..). Runs ``vical-evaluate`` once per task with the
baselines (the greedy planner, the long and short expert, random motion), once per learned run (the reference
and each further one, each its own table row, on the same sensors), once per critic-scored planner (the planner's
candidates scored by a learned run's value, ``policy=critic_planner``), once per hybrid that hands a learned run's
episode over to the planner at its step limit (``policy=handover``), pools the results and prints, per
task, the time-to-tolerance table: stops, right stops, time and path at the stop, decision time per step, and the
paired difference to the reference with its 95 % interval; then each learned run's training time (its train.log).

Usage:
    python experiments/time_to_tolerance.py --runs runs/a runs/b runs/c           # reference: the shipped policy
    python experiments/time_to_tolerance.py --reference runs/a --runs runs/b runs/c --tasks joint
    python experiments/time_to_tolerance.py --runs runs/a --critics runs/a shipped     # and planners scored by them
    python experiments/time_to_tolerance.py --handovers shipped                   # the shipped policy, then the planner
    python experiments/time_to_tolerance.py --baselines greedy_information rate_planner   # any policy conf as a row
    python experiments/time_to_tolerance.py --episodes 20 --seed 40000 ...        # the tuning sensors
    python experiments/time_to_tolerance.py --sensor paper --baselines ...        # the paper's sensors, no baselines
    python experiments/time_to_tolerance.py --reuse ...                          # keep the results already written
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from datetime import datetime
from pathlib import Path

from vical.apps.evaluate import stops_table, yardstick_config
from vical.evaluation.results_file import by_policy, read_results
from vical.evaluation.time_to_tolerance import summarize_stops

ROOT = Path(__file__).resolve().parents[1]
TASKS = ("joint", "intrinsic")
BASELINES = ("greedy_information", "expert_long", "expert_short", "random_moving")
SHIPPED = "shipped"
_STAMP = re.compile(r"^\[(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d),\d+\]")


def label(run: str, policy: str = "learned") -> str:
    """The table row of a learned run's ``policy`` (``learned``: its agent; ``critic_planner``: the planner scored by
    its value; ``handover``: its agent for its step limit, then the planner)."""
    kinds = {"learned": "learned", "critic_planner": "critic-scored planner", "handover": "learned, then planner"}
    kind = kinds[policy]
    return f"{kind} (shipped)" if run == SHIPPED else f"{kind} ({Path(run).name})"


def evaluate(
    task: str, out: Path, policies: list[str], run: str | None, args: argparse.Namespace, policy: str = "learned"
) -> Path:
    """``vical-evaluate`` of ``policies`` on the yardstick's sensors (``policy``, ``learned``, ``critic_planner`` or
    ``handover``: of the run ``run``); its results file (an existing one is kept with ``--reuse``)."""
    if args.reuse and (out / "results.csv").is_file():
        return out / "results.csv"
    overrides = [
        f"+experiment=time_to_tolerance_{task}",
        f"policies=[{','.join(policies)}]",
        f"reference={policies[0]}",
        f"episodes={args.episodes}",
        f"seed={args.seed}",
        f"out={out}",
        "overwrite=true",
    ]
    if run is not None:
        overrides += [f"policy={policy}", f"policy.name='{label(run, policy)}'"]
    if run not in (None, SHIPPED):
        overrides.append(f"policy.run_dir={run}")
    if args.sensor == "paper":  # the paper's sensors, one lens model
        overrides += ["sensor=paper", "task.camera_model=radtan"]
    subprocess.run([sys.executable, "-m", "vical.apps.evaluate", *overrides], cwd=ROOT, check=True)
    return out / "results.csv"


def training_minutes(run: str) -> float | None:
    """Minutes between the first and the last line of a run's train.log (None: no log, the shipped policy)."""
    log = Path(run) / "train.log"
    if run == SHIPPED or not log.is_file():
        return None
    stamps = [_STAMP.match(line) for line in log.read_text().splitlines()]
    times = [datetime.strptime(m.group(1), "%Y-%m-%d %H:%M:%S") for m in stamps if m]
    return (times[-1] - times[0]).total_seconds() / 60 if len(times) > 1 else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS))
    parser.add_argument("--reference", default=SHIPPED, help="the learned run every policy is paired with")
    parser.add_argument("--runs", nargs="*", default=[], help="further learned runs, each its own row")
    parser.add_argument(
        "--critics",
        nargs="*",
        default=[],
        help="learned runs whose value scores the planner's "
        "candidates (policy=critic_planner; shipped: the shipped policy's), each its own row",
    )
    parser.add_argument(
        "--handovers",
        nargs="*",
        default=[],
        help="learned runs that act for their step limit and then hand over to the planner (policy=handover; "
        "shipped: the shipped policy), each its own row",
    )
    parser.add_argument("--baselines", nargs="*", default=list(BASELINES), help="baselines beside the reference")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=50000, help="first sensor seed (50000..: held out)")
    parser.add_argument("--sensor", choices=("practitioner", "paper"), default="practitioner")
    parser.add_argument("--reuse", action="store_true", help="keep the results a run already wrote")
    parser.add_argument("--out", type=Path, default=ROOT / "evaluations" / "time_to_tolerance")
    args = parser.parse_args()
    for task in args.tasks:
        rule = yardstick_config(task, "time_to_tolerance")["stop"]  # the experiment's: its tolerances and horizon
        where = args.out / args.sensor / task
        files = [evaluate(task, where / "baselines", args.baselines, None, args)] if args.baselines else []
        for run in [args.reference, *args.runs]:
            files.append(evaluate(task, where / Path(run).name, ["learned"], run, args))
        for run in args.critics:
            out = where / f"critic_{Path(run).name}"
            files.append(evaluate(task, out, ["critic_planner"], run, args, "critic_planner"))
        for run in args.handovers:
            files.append(evaluate(task, where / f"handover_{Path(run).name}", ["handover"], run, args, "handover"))
        rows = by_policy([row for path in files for row in read_results(path)])
        tolerances = rule["information"]["tolerances"]
        verifying = rule["out_of_reach"] and rule["verify_s"] is not None
        stops = summarize_stops(rows, task, tolerances, label(args.reference), rule["horizon_s"], verifying)
        print(f"\n## {task} task, sensor={args.sensor}, seeds {args.seed}..{args.seed + args.episodes - 1}\n")
        print(stops_table(stops))
    for run in [args.reference, *args.runs]:
        minutes = training_minutes(run)
        print(f"training time of {label(run)}: " + ("-" if minutes is None else f"{minutes:.1f} min"))


if __name__ == "__main__":
    main()
