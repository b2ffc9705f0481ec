"""Reading ``vical-evaluate``'s ``results.csv`` back, and paired comparisons of the policies it holds.

A results file holds one row per policy, sensor seed and path budget (``budget_m``: the budget in
metres, ``end`` for the whole episode). The paired comparisons read, per sensor, the row of the
budget, or the whole episode's row when the episode ended before it; a failed calibration counts
at the nominal parameters' error (``prior_score_pct``), as in ``vical.evaluation.error_vs_effort``.
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from vical.evaluation.error_vs_effort import rows_at_budget
from vical.evaluation.harness import END, EpisodeRow
from vical.evaluation.intervals import Interval, paired_difference

REQUIRED = (
    "policy",
    "seed",
    "budget_m",
    "score_pct",
    "prior_score_pct",
    "failed",
    "coverage_reached",
    "path_length_m",
    "recording_time_s",
)
# How a column of results.csv is read back: by the EpisodeRow field's annotation; an empty cell is None.
_PARSERS = {"str": str, "int": int, "float": float, "bool": lambda cell: cell == "True"}


def read_results(path: Path) -> list[EpisodeRow]:
    """The rows of a ``vical-evaluate`` results file; ``ValueError`` naming the file when it is not one."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such results file; run vical-evaluate ... out=<dir> and pass <dir>/results.csv")
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{path}: not a vical-evaluate results file, it lacks the columns {missing}")
        return [_episode_row(path, reader.line_num, cells) for cells in reader]


def _episode_row(path: Path, line: int, cells: Mapping[str, str]) -> EpisodeRow:
    values = {}
    for f in dataclasses.fields(EpisodeRow):
        cell = cells.get(f.name)
        if cell is None or (cell == "" and f.type.endswith("| None")):
            continue  # a column an older file lacks, or n/a: the field's default
        try:
            values[f.name] = END if f.name == "budget_m" and cell == "end" else _PARSERS[f.type.split(" |")[0]](cell)
        except ValueError:
            raise ValueError(f"{path}, line {line}: {f.name} {cell!r} is not a {f.type}") from None
    return EpisodeRow(**values)


def by_policy(rows: Sequence[EpisodeRow]) -> dict[str, list[EpisodeRow]]:
    """The rows grouped by their policy (the table row)."""
    out: dict[str, list[EpisodeRow]] = {}
    for row in rows:
        out.setdefault(row.policy, []).append(row)
    return out


def budgets_of(rows: Sequence[EpisodeRow]) -> list[float]:
    """The path budgets [m] the rows hold, ascending, ``END`` (inf) last."""
    return sorted({row.budget_m for row in rows})


def compare(rows: Mapping[str, Sequence[EpisodeRow]], policy: str, other: str, budget: float) -> Interval:
    """Mean paired difference ``policy - other`` [%] at ``budget`` over their common sensors, with its 95 % CI."""
    for name in (policy, other):
        if name not in rows:
            raise ValueError(f"no policy {name!r} in the results; they hold {sorted(rows)}")
    # Any policy's budgets: one that neither of the two reached still compares their whole episodes.
    held = budgets_of([row for policy_rows in rows.values() for row in policy_rows])
    if budget not in held:
        raise ValueError(
            f"no path budget {budget:g} m in the results; they hold {[b for b in held if b != END]} m "
            "(vical-evaluate budgets=...)"
        )
    a, b = rows_at_budget(rows[policy], budget), rows_at_budget(rows[other], budget)
    seeds = sorted(set(a) & set(b))
    if not seeds:
        raise ValueError(f"{policy!r} and {other!r} share no sensor seed: evaluate both with the same seed=")
    mine = np.array([a[s].effective_score_pct for s in seeds])
    return paired_difference(mine, np.array([b[s].effective_score_pct for s in seeds]))
