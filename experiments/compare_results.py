"""Paired comparisons between any two policies of a ``vical-evaluate`` results file, at every path budget.

``vical-evaluate`` compares every policy with one reference (``reference=``); this reads its
``results.csv`` and compares ``--policy`` with each of ``--against`` the same way (per sensor the
row of the budget, or the whole episode's when it ended earlier; a failed calibration at the
nominal parameters' error; mean paired difference with its 95 % bootstrap interval), so a
policy can be compared with every baseline without evaluating again.

    .venv/bin/python experiments/compare_results.py evaluations/<run>/results.csv \
        --policy "model-free learned policy" --against "expert (long)" "expert (short)" "random moving policy"
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from vical.policies.statistics import paired_difference

END = "end"


def read_scores(path: Path) -> dict[str, dict[str, dict[int, float]]]:
    """``{policy: {budget: {seed: effective error [%]}}}`` of a results file."""
    scores: dict[str, dict[str, dict[int, float]]] = {}
    with open(path, newline="", encoding="utf-8") as f:
        for row in csv.DictReader(f):
            failed = row["failed"] == "True"
            score = float(row["prior_score_pct"] if failed else row["score_pct"])
            scores.setdefault(row["policy"], {}).setdefault(row["budget_m"], {})[int(row["seed"])] = score
    return scores


def at_budget(budgets: dict[str, dict[int, float]], budget: str) -> dict[int, float]:
    """Per seed the error at ``budget``, or the whole episode's when the episode ended before."""
    return {seed: budgets.get(budget, {}).get(seed, whole) for seed, whole in budgets[END].items()}


def budget_key(label: str) -> float:
    return np.inf if label == END else float(label)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("results", type=Path)
    p.add_argument("--policy", required=True, help="the policy's table name")
    p.add_argument("--against", nargs="+", required=True, help="the table names it is compared with")
    args = p.parse_args()
    scores = read_scores(args.results)
    for name in [args.policy, *args.against]:
        if name not in scores:
            raise SystemExit(f"compare_results: no policy {name!r} in {args.results}; it holds {sorted(scores)}")
    budgets = sorted({b for s in scores.values() for b in s}, key=budget_key)
    mine = scores[args.policy]
    print(f"| budget | {' | '.join(f'{args.policy} - {other} [%] (95 % CI)' for other in args.against)} |")
    print("|---" * (len(args.against) + 1) + "|")
    for budget in budgets:
        cells = []
        for other in args.against:
            a, b = at_budget(mine, budget), at_budget(scores[other], budget)
            seeds = sorted(set(a) & set(b))
            d = paired_difference(np.array([a[s] for s in seeds]), np.array([b[s] for s in seeds]))
            cells.append(f"{d.estimate:+.3f} [{d.low:+.3f}, {d.high:+.3f}]")
        label = budget if budget == END else f"{float(budget):g} m"
        print(f"| {label} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
