"""Reading ``vical-evaluate``'s ``results.csv`` back, and choosing which training seed to ship.

A results file holds one row per policy, sensor seed and path budget (``budget_m``: the budget in
metres, ``end`` for the whole episode). The paired comparisons read, per sensor, the row of the
budget, or the whole episode's row when the episode ended before it; a failed calibration counts
at the nominal parameters' error (``prior_score_pct``), as in ``vical.policies.effort``.

Choosing the seed (:func:`choose_seed`) follows a rule fixed before any result is read: every
candidate run is evaluated on tuning sensors (never the held-out ones a table reports) in each
task; a candidate is eligible when, in every task, it reaches its goal often enough, its stops are
right (the errors the task is scored by within the tolerances it stopped for), and its path and
recording time stay within a fraction of the reference baseline's; among the eligible, the
lowest mean paired error difference against the reference at one path budget wins.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vical.policies.statistics import Interval, paired_difference

END = "end"
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
# The errors each task is scored by, named as results.csv's columns and as the information
# tolerances (conf/env/information.yaml). The joint task's intrinsics are left out: its asymmetric
# distortion, which the radtan model cannot fit, biases them by design (docs/evaluation.md).
SCORED_GROUPS = {
    "intrinsic": ("focal_px", "principal_point_px", "distortion_px"),
    "extrinsic": ("rotation_deg", "translation_mm", "time_offset_ms"),
    "joint": ("rotation_deg", "translation_mm", "time_offset_ms"),
}

Scores = dict[str, dict[str, dict[int, float]]]


def read_results(path: Path) -> list[dict[str, str]]:
    """The rows of a ``vical-evaluate`` results file; ``ValueError`` naming the file when it is not one."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such results file; run vical-evaluate ... out=<dir> and pass <dir>/results.csv")
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{path}: not a vical-evaluate results file, it lacks the columns {missing}")
        return list(reader)


def scores_of(rows: Sequence[Mapping[str, str]]) -> Scores:
    """``{policy: {budget: {seed: effective error [%]}}}``: a failed calibration at the nominal parameters' error."""
    scores: Scores = {}
    for row in rows:
        failed = row["failed"] == "True"
        score = float(row["prior_score_pct"] if failed else row["score_pct"])
        scores.setdefault(row["policy"], {}).setdefault(row["budget_m"], {})[int(row["seed"])] = score
    return scores


def at_budget(budgets: Mapping[str, Mapping[int, float]], budget: str) -> dict[int, float]:
    """Per seed the error at ``budget``, or the whole episode's when the episode ended before."""
    return {seed: budgets.get(budget, {}).get(seed, whole) for seed, whole in budgets[END].items()}


def budget_key(label: str) -> float:
    """Sort key of a budget label: metres, ``end`` last."""
    return math.inf if label == END else float(label)


def compare(scores: Scores, policy: str, other: str, budget: str) -> Interval:
    """Mean paired difference ``policy - other`` [%] at ``budget`` over their common sensors, with its 95 % CI."""
    for name in (policy, other):
        if name not in scores:
            raise ValueError(f"no policy {name!r} in the results; they hold {sorted(scores)}")
    # Any policy's labels: a budget that neither of the two reached still counts their whole episodes.
    budget = _budget_label(budget, [label for budgets in scores.values() for label in budgets])
    a, b = at_budget(scores[policy], budget), at_budget(scores[other], budget)
    seeds = sorted(set(a) & set(b))
    if not seeds:
        raise ValueError(f"{policy!r} and {other!r} share no sensor seed: evaluate both with the same seed=")
    return paired_difference(np.array([a[s] for s in seeds]), np.array([b[s] for s in seeds]))


def _budget_label(budget: str, labels: Sequence[str]) -> str:
    """The file's label of ``budget`` (``1`` is written ``1.0``); ``ValueError`` when no policy reached it."""
    if budget == END:
        return END
    for label in labels:
        if label != END and float(label) == float(budget):
            return label
    raise ValueError(
        f"no path budget {budget} m in the results; they hold {sorted(set(labels) - {END}, key=float)} m "
        "(vical-evaluate budgets=...)"
    )


@dataclass(frozen=True)
class TaskAssessment:
    """One candidate policy in one task, on the tuning sensors.

    Attributes:
        goal: fraction of the episodes that ended at the goal (the terminal condition).
        right: of those, the fraction whose scored errors are within the tolerances (nan: none stopped).
        path_m, time_s: mean path and recording time of the whole episodes.
        reference_path_m, reference_time_s: the same of the reference baseline.
        versus: the mean paired error difference against the reference at the rule's budget [%].
    """

    goal: float
    right: float
    path_m: float
    time_s: float
    reference_path_m: float
    reference_time_s: float
    versus: Interval


@dataclass(frozen=True)
class ShipRule:
    """The rule that picks the seed to ship (see the module's docstring)."""

    reference: str = "expert (long)"
    budget: str = "0.5"
    min_goal: float = 0.9
    min_right: float = 0.9
    effort_fraction: float = 0.25

    def failures(self, task: str, a: TaskAssessment) -> list[str]:
        """What keeps a candidate from being eligible in ``task`` (empty: nothing)."""
        out = []
        if a.goal < self.min_goal:
            out.append(f"{task}: goal {a.goal:.0%} < {self.min_goal:.0%}")
        if math.isnan(a.right):
            out.append(f"{task}: no episode stopped at the goal")
        elif a.right < self.min_right:
            out.append(f"{task}: stops right {a.right:.0%} < {self.min_right:.0%}")
        if a.path_m > self.effort_fraction * a.reference_path_m:
            out.append(f"{task}: path {a.path_m:.2f} m > {self.effort_fraction:g} x {a.reference_path_m:.2f} m")
        if a.time_s > self.effort_fraction * a.reference_time_s:
            out.append(f"{task}: time {a.time_s:.1f} s > {self.effort_fraction:g} x {a.reference_time_s:.1f} s")
        return out


def _ends(rows: Sequence[Mapping[str, str]], policy: str) -> list[Mapping[str, str]]:
    ends = [r for r in rows if r["policy"] == policy and r["budget_m"] == END]
    if not ends:
        raise ValueError(
            f"no whole-episode rows of policy {policy!r}; the results hold {sorted({r['policy'] for r in rows})}"
        )
    return ends


def stopped_right(row: Mapping[str, str], task: str, tolerances: Mapping[str, float]) -> bool:
    """Whether an episode's scored errors are all within ``tolerances`` (a failed calibration is not)."""
    if row["failed"] == "True":
        return False
    return all(float(row[group]) <= float(tolerances[group]) for group in SCORED_GROUPS[task])


def assess(
    candidate: Sequence[Mapping[str, str]],
    baselines: Sequence[Mapping[str, str]],
    task: str,
    tolerances: Mapping[str, float],
    rule: ShipRule,
    policy: str = "model-free learned policy",
) -> TaskAssessment:
    """A candidate's rows (``policy``) in ``task`` against the reference among ``baselines`` rows."""
    if task not in SCORED_GROUPS:
        raise ValueError(f"task must be one of {sorted(SCORED_GROUPS)}, got {task!r}")
    missing = [g for g in SCORED_GROUPS[task] if g not in tolerances]
    if missing:
        raise ValueError(f"the tolerances lack {missing} of the {task} task: set env.information.tolerances")
    mine, theirs = _ends(candidate, policy), _ends(baselines, rule.reference)
    stopped = [r for r in mine if r["coverage_reached"] == "True"]
    right = [stopped_right(r, task, tolerances) for r in stopped]
    # Only the reference's rows of the baselines: their file may hold a policy of the candidate's name.
    scores = scores_of(
        [r for r in candidate if r["policy"] == policy] + [r for r in baselines if r["policy"] == rule.reference]
    )
    return TaskAssessment(
        goal=len(stopped) / len(mine),
        right=float(np.mean(right)) if right else math.nan,
        path_m=float(np.mean([float(r["path_length_m"]) for r in mine])),
        time_s=float(np.mean([float(r["recording_time_s"]) for r in mine])),
        reference_path_m=float(np.mean([float(r["path_length_m"]) for r in theirs])),
        reference_time_s=float(np.mean([float(r["recording_time_s"]) for r in theirs])),
        versus=compare(scores, policy, rule.reference, rule.budget),
    )


def choose_seed(
    assessments: Mapping[str, Mapping[str, TaskAssessment]], rule: ShipRule, scored_task: str = "joint"
) -> str | None:
    """The eligible candidate with the lowest difference against the reference in ``scored_task`` (None: none)."""
    eligible = {
        name: tasks[scored_task].versus.estimate
        for name, tasks in assessments.items()
        if not any(rule.failures(task, a) for task, a in tasks.items())
    }
    return min(eligible, key=eligible.__getitem__) if eligible else None
