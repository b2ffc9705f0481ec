"""Choosing which training seed to ship, from ``vical-evaluate`` results on tuning sensors.

The rule (:func:`choose_seed`) is fixed before any result is read: every candidate run is evaluated
on tuning sensors (never the held-out ones a table reports) in each task; a candidate is eligible
when, in every task, it reaches its goal often enough, its stops are right (the errors the task is
scored by within the tolerances it stopped for), and its path and recording time stay within a
fraction of the reference baseline's; among the eligible, the lowest mean paired error difference
against the reference at one path budget wins (``vical.evaluation.results_file.compare``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from vical.env.information import SCORED_GROUPS as TASK_SCORED_GROUPS
from vical.env.settings import GROUP_TOLERANCE
from vical.evaluation.harness import END, EpisodeRow
from vical.evaluation.intervals import Interval
from vical.evaluation.results_file import by_policy, compare

# The errors each task is scored by (vical.env.information.SCORED_GROUPS), named as results.csv's columns and as
# the information tolerances (conf/env/information.yaml). The joint task's intrinsics are left out: its
# asymmetric distortion, which the radtan model cannot fit, biases them by design (docs/evaluation.md).
SCORED_GROUPS = {task: tuple(GROUP_TOLERANCE[g] for g in groups) for task, groups in TASK_SCORED_GROUPS.items()}


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
    budget: float = 0.5
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


def _ends(rows: Sequence[EpisodeRow], policy: str) -> list[EpisodeRow]:
    ends = [r for r in rows if r.policy == policy and r.budget_m == END]
    if not ends:
        raise ValueError(f"no whole-episode rows of policy {policy!r}; the results hold {sorted(by_policy(rows))}")
    return ends


def stopped_right(row: EpisodeRow, task: str, tolerances: Mapping[str, float]) -> bool:
    """Whether an episode's scored errors are all within ``tolerances`` (a failed calibration is not)."""
    if row.failed:
        return False
    return all(getattr(row, group) <= float(tolerances[group]) for group in SCORED_GROUPS[task])


def assess(
    candidate: Sequence[EpisodeRow],
    baselines: Sequence[EpisodeRow],
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
    stopped = [r for r in mine if r.coverage_reached]
    right = [stopped_right(r, task, tolerances) for r in stopped]
    # Only the reference's rows of the baselines: their file may hold a policy of the candidate's name.
    rows = {policy: [r for r in candidate if r.policy == policy], rule.reference: by_policy(baselines)[rule.reference]}
    return TaskAssessment(
        goal=len(stopped) / len(mine),
        right=float(np.mean(right)) if right else math.nan,
        path_m=float(np.mean([r.path_length_m for r in mine])),
        time_s=float(np.mean([r.recording_time_s for r in mine])),
        reference_path_m=float(np.mean([r.path_length_m for r in theirs])),
        reference_time_s=float(np.mean([r.recording_time_s for r in theirs])),
        versus=compare(rows, policy, rule.reference, rule.budget),
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
