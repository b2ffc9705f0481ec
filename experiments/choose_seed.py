"""Which training seed to ship: the rule of ``vical.evaluation.seed_choice.choose_seed`` on tuning sensors.

Evaluate every candidate run and the baselines on the same tuning sensors (reset seeds that no
held-out table uses: the documented tables use 40000-40019 for tuning, 50000-50049 held out), in
the joint and the intrinsic task:

    vical-evaluate +experiment=yardstick_joint seed=40000 episodes=20 out=tune/base_joint
    vical-evaluate +experiment=yardstick_joint seed=40000 episodes=20 'policies=[learned]' \\
        policy.run_dir=runs/seed0 out=tune/seed0_joint
    (the same with yardstick_intrinsic, and for every run)

then

    .venv/bin/python experiments/choose_seed.py --baselines tune/base_joint/results.csv \\
        tune/base_intrinsic/results.csv --candidate runs/seed0 tune/seed0_joint/results.csv \\
        tune/seed0_intrinsic/results.csv --candidate runs/seed1 ...

prints per candidate and task the goal rate, the stops that were right (the task's scored errors
within the tolerances of the run's ``env.information.tolerances``), the mean path and time against
the reference's, and the paired difference at the budget; then the eligible candidate to ship.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from omegaconf import OmegaConf

from vical.evaluation.results_file import read_results
from vical.evaluation.seed_choice import ShipRule, TaskAssessment, assess, choose_seed

TASKS = ("joint", "intrinsic")


def tolerances_of(run_dir: Path) -> dict[str, float]:
    """The information tolerances a run was trained with (its ``config.yaml``)."""
    config = run_dir / "config.yaml"
    if not config.is_file():
        raise SystemExit(f"choose_seed: {config} is missing: pass the run_dir of a vical-train run")
    tolerances = OmegaConf.select(OmegaConf.load(config), "env.information.tolerances")
    if tolerances is None:
        raise SystemExit(
            f"choose_seed: {config} has no env.information.tolerances: the run was not trained on the information MDP"
        )
    return {k: float(v) for k, v in tolerances.items()}


def row(name: str, task: str, a: TaskAssessment, rule: ShipRule) -> str:
    v = a.versus
    failures = "; ".join(f.split(": ", 1)[1] for f in rule.failures(task, a)) or "-"
    right = "-" if math.isnan(a.right) else f"{a.right:.0%}"
    return (
        f"| {name} | {task} | {a.goal:.0%} | {right} | {a.path_m:.2f} / {a.reference_path_m:.2f} | "
        f"{a.time_s:.1f} / {a.reference_time_s:.1f} | {v.estimate:+.3f} [{v.low:+.3f}, {v.high:+.3f}] | {failures} |"
    )


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--baselines", nargs=2, type=Path, required=True, metavar=("JOINT_CSV", "INTRINSIC_CSV"))
    p.add_argument(
        "--candidate", nargs=3, action="append", required=True, metavar=("RUN_DIR", "JOINT_CSV", "INTRINSIC_CSV")
    )
    p.add_argument("--reference", default=ShipRule.reference, help="the baseline's table name")
    p.add_argument("--budget", type=float, default=ShipRule.budget, help="the path budget [m] of the comparison")
    args = p.parse_args(argv)
    rule = ShipRule(reference=args.reference, budget=args.budget)
    try:
        baselines = {task: read_results(path) for task, path in zip(TASKS, args.baselines, strict=True)}
        assessments = {}
        for run_dir, *paths in args.candidate:
            tolerances = tolerances_of(Path(run_dir))
            assessments[run_dir] = {
                task: assess(read_results(Path(path)), baselines[task], task, tolerances, rule)
                for task, path in zip(TASKS, paths, strict=True)
            }
    except ValueError as e:
        raise SystemExit(f"choose_seed: {e}") from None
    print(
        f"| run | task | goal | stops right | path [m] / {rule.reference} | time [s] / {rule.reference} | "
        f"- {rule.reference} at {rule.budget:g} m [%] (95 % CI) | not eligible because |"
    )
    print("|---" * 8 + "|")
    for name, tasks in assessments.items():
        for task, a in tasks.items():
            print(row(name, task, a, rule))
    chosen = choose_seed(assessments, rule)
    print(f"\nship: {chosen}" if chosen else "\nship: none is eligible")


if __name__ == "__main__":
    main()
