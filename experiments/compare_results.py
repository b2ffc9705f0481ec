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
from pathlib import Path

from vical.evaluation.error_vs_effort import budget_label
from vical.evaluation.results_file import budgets_of, by_policy, compare, read_results


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("results", type=Path)
    p.add_argument("--policy", required=True, help="the policy's table name")
    p.add_argument("--against", nargs="+", required=True, help="the table names it is compared with")
    args = p.parse_args(argv)
    try:
        results = read_results(args.results)
    except ValueError as e:
        raise SystemExit(f"compare_results: {e}") from None
    rows = by_policy(results)
    for name in [args.policy, *args.against]:
        if name not in rows:
            raise SystemExit(f"compare_results: no policy {name!r} in {args.results}; it holds {sorted(rows)}")
    print(f"| budget | {' | '.join(f'{args.policy} - {other} [%] (95 % CI)' for other in args.against)} |")
    print("|---" * (len(args.against) + 1) + "|")
    for budget in budgets_of(results):
        cells = []
        for other in args.against:
            d = compare(rows, args.policy, other, budget)
            cells.append(f"{d.estimate:+.3f} [{d.low:+.3f}, {d.high:+.3f}]")
        print(f"| {budget_label(budget)} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
