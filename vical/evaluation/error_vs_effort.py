"""Error versus effort: per-policy errors at path budgets, paired comparisons with a reference, the figure.

``vical.evaluation.harness`` calibrates every episode at each path budget below its path and
whole. Here, at each budget, every sensor contributes the row of that budget, or, when its
episode ended before travelling that far, the whole episode's row (the policy had stopped: its
final calibration is what it delivers at that effort). A failed calibration counts with the error
of the nominal parameters (``EpisodeRow.effective_score_pct``). The paired comparison with the
reference policy is over the sensors both evaluated (``vical.evaluation.intervals``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from vical.evaluation.harness import END, EpisodeRow
from vical.evaluation.intervals import LEVEL, MIN_SENSORS, Interval, paired_by_sensor
from vical.io.atomic import atomic_file


@dataclass(frozen=True)
class BudgetSummary:
    """One policy at one path budget, over the evaluated sensors.

    Attributes:
        policy: the table row.
        budget_m: the path budget [m]; ``inf`` for whole episodes.
        sensors: sensors evaluated.
        reached: fraction of episodes whose path reached the budget (the others stand in with their
            whole episode).
        failed: fraction of failed calibrations.
        mean_error_pct, median_error_pct: the task's error [%], failures at the nominal parameters' error.
        intrinsic_px, rotation_deg, translation_mm, time_offset_ms: medians of the absolute errors over
            successful calibrations (None where the task does not estimate them).
        path_m, time_s: mean path [m] and recording time [s] of the calibrated data.
        versus: mean paired difference to the reference policy [%] with its 95 % interval (None for the
            reference itself, when the two were not evaluated on the same sensors, or on fewer than
            ``MIN_SENSORS``).
    """

    policy: str
    budget_m: float
    sensors: int
    reached: float
    failed: float
    mean_error_pct: float
    median_error_pct: float
    intrinsic_px: float | None
    rotation_deg: float | None
    translation_mm: float | None
    time_offset_ms: float | None
    path_m: float
    time_s: float
    versus: Interval | None


def rows_at_budget(rows: Sequence[EpisodeRow], budget: float) -> dict[int, EpisodeRow]:
    """Per sensor seed, the row of ``budget``, or the whole episode's when it ended before that path."""
    by_seed: dict[int, dict[float, EpisodeRow]] = {}
    for row in rows:
        by_seed.setdefault(row.seed, {})[row.budget_m] = row
    return {seed: budgets.get(budget, budgets[END]) for seed, budgets in sorted(by_seed.items())}


def _median(rows: Sequence[EpisodeRow], key: str) -> float | None:
    values = [getattr(r, key) for r in rows if not r.failed and getattr(r, key) is not None]
    return float(np.median(values)) if values else None


def _versus(chosen: dict[int, EpisodeRow], reference: dict[int, EpisodeRow]) -> Interval | None:
    score = {s: r.effective_score_pct for s, r in chosen.items()}
    return paired_by_sensor(score, {s: r.effective_score_pct for s, r in reference.items()})


def summarize_budget(
    name: str, rows: Sequence[EpisodeRow], budget: float, reference: Sequence[EpisodeRow] | None
) -> BudgetSummary:
    """``name``'s summary at ``budget``; ``reference``: the reference policy's rows (None for the reference itself)."""
    chosen = rows_at_budget(rows, budget)
    picked = list(chosen.values())
    scores = np.array([r.effective_score_pct for r in picked])
    return BudgetSummary(
        policy=name,
        budget_m=budget,
        sensors=len(picked),
        reached=float(np.mean([r.budget_m == budget for r in picked])),
        failed=float(np.mean([r.failed for r in picked])),
        mean_error_pct=float(np.mean(scores)),
        median_error_pct=float(np.median(scores)),
        intrinsic_px=_median(picked, "intrinsic_px"),
        rotation_deg=_median(picked, "rotation_deg"),
        translation_mm=_median(picked, "translation_mm"),
        time_offset_ms=_median(picked, "time_offset_ms"),
        path_m=float(np.mean([r.path_length_m for r in picked])),
        time_s=float(np.mean([r.recording_time_s for r in picked])),
        versus=None if reference is None else _versus(chosen, rows_at_budget(reference, budget)),
    )


def summarize_effort(
    rows_by_policy: Mapping[str, Sequence[EpisodeRow]], budgets: Sequence[float], reference: str | None
) -> list[BudgetSummary]:
    """Every policy at every budget and at the episode's end, in policy then budget order."""
    ref_rows = rows_by_policy.get(reference) if reference is not None else None
    return [
        summarize_budget(name, rows, budget, None if name == reference else ref_rows)
        for name, rows in rows_by_policy.items()
        for budget in (*budgets, END)
    ]


def budget_label(budget: float) -> str:
    return "end" if math.isinf(budget) else f"{budget:g} m"


def significance_lines(summaries: Sequence[BudgetSummary], reference: str) -> list[str]:
    """Per budget, which policies are significantly lower / higher in error than ``reference`` (95 % paired CI)."""
    compared = [s for s in summaries if s.policy != reference]
    if compared and all(s.sensors < MIN_SENSORS for s in compared):
        sensors = min(s.sensors for s in compared)
        return [
            f"- no confidence interval against {reference}: a paired {100 * LEVEL:.0f} % interval needs at least "
            f"{MIN_SENSORS} sensors, these were evaluated on {sensors}"
        ]
    lines = []
    for budget in dict.fromkeys(s.budget_m for s in summaries):
        at = [s for s in summaries if s.budget_m == budget and s.versus is not None]
        lower = [s.policy for s in at if s.versus.verdict == "lower"]
        higher = [s.policy for s in at if s.versus.verdict == "higher"]
        same = [s.policy for s in at if s.versus.verdict == "no difference"]
        parts = [f"lower error: {', '.join(lower) or 'none'}", f"higher error: {', '.join(higher) or 'none'}"]
        if same:
            parts.append(f"no significant difference: {', '.join(same)}")
        lines.append(f"- at {budget_label(budget)}, against {reference}: " + "; ".join(parts))
    return lines


def effort_figure(summaries: Sequence[BudgetSummary], task: str):
    """Median error [%] (log scale) against mean path [m] and recording time [s], one line per policy."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for name in dict.fromkeys(s.policy for s in summaries):
        points = sorted((s for s in summaries if s.policy == name), key=lambda s: s.path_m)
        errors = [max(s.median_error_pct, 1e-4) for s in points]
        for ax, x in zip(axes, ([s.path_m for s in points], [s.time_s for s in points]), strict=True):
            ax.plot(x, errors, marker="o", label=name)
    axes[0].set_xlabel("path of the calibrated data [m]")
    axes[1].set_xlabel("recording time [s]")
    axes[0].set_ylabel(f"median {task} error [%]")
    for ax in axes:
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=8)
    fig.suptitle(f"{task} task: error versus effort (points: path budgets and the episodes' end)")
    fig.tight_layout()
    return fig


def write_effort_figure(path: str | Path, summaries: Sequence[BudgetSummary], task: str) -> None:
    """Write ``effort_figure`` as a PNG, atomically."""
    fig = effort_figure(summaries, task)
    try:
        with atomic_file(path) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
    finally:
        plt.close(fig)
