"""Time to the tolerances: how soon each policy stops by the information state, and whether its stop was right.

With one stopping rule for every policy (``stop=information``) the policies differ only in their motion, and
the practitioner's question is how long each takes to a calibration within the tolerances. Per policy, over its
whole episodes:

- **stopped**: the share that ended at the goal (every goal group predicted within tolerance) within the step
  limit; the others ran to their end (the step limit, or a trajectory's last waypoint);
- **right**: of the stopped, the share whose true errors of the task's scored groups are within the tolerances
  (``vical.evaluation.seed_choice.stopped_right``; a failed calibration is not right);
- **time** and **path**: recording time [s] and end-effector path [m] at the stop; an episode that never stopped
  counts with its whole recording (at the step limit), so a policy gains nothing by not stopping. With a common
  **horizon** (``stop.horizon_s``) an episode that had not stopped by then counts at the horizon, whenever its own
  limit ended it (a policy gains nothing by a short step limit either; ``cut short`` says how many ended before
  it), and a stop after the horizon is no stop;
- **out of reach**: the share stopped because the reachability forecast called the goal out of reach within the
  horizon (``stop.out_of_reach``, ``vical.env.reachability``); such a run counts at the horizon, so giving up early
  is never rewarded. **Verdict right**: of those, the share that did not reach the goal when run on to
  ``stop.verify_s`` (nan: not run on). **Forecast**: of the runs stopped at the goal, the share whose predicted time
  (the forecast halfway to it) is within a factor ``FORECAST_FACTOR`` of the measured;
- **decision**: the policy's mean time to choose an action [ms per step] (what a robot waits between motions);
- the paired difference of time and path to the reference policy's on the same sensors, with its 95 % bootstrap
  interval (``vical.evaluation.intervals.paired_by_sensor``: none unless both ran the same sensors, at least
  ``MIN_SENSORS`` of them).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from vical.evaluation.harness import END, EpisodeRow
from vical.evaluation.intervals import Interval, paired_by_sensor
from vical.evaluation.seed_choice import SCORED_GROUPS, stopped_right

FORECAST_FACTOR = 1.5  # a predicted time to the tolerances within this factor of the measured one is right


@dataclass(frozen=True)
class StopSummary:
    """One policy's stops (module doc).

    Attributes:
        policy: the table row; sensors: whole episodes.
        stopped: share that stopped at the goal; right: share of those whose stop was right (nan: none stopped).
        time_s, median_time_s: mean and median recording time at the stop [s]; path_m: mean path [m].
        decision_ms: mean time to choose an action [ms per step] (nan: not recorded).
        cut_short: share of the episodes that neither stopped nor reached the horizon (0 without one).
        out_of_reach: share stopped as out of reach; verdict_right: share of those that did not reach the goal when
            run on (nan: none, or not run on); forecast_right: share of the stopped whose predicted time was within
            ``FORECAST_FACTOR`` of the measured (nan: none stopped, or no forecast).
        time_versus, path_versus: paired differences to the reference (None for the reference itself, or too few
            common sensors).
    """

    policy: str
    sensors: int
    stopped: float
    right: float
    time_s: float
    median_time_s: float
    path_m: float
    decision_ms: float
    cut_short: float
    out_of_reach: float
    verdict_right: float
    forecast_right: float
    time_versus: Interval | None
    path_versus: Interval | None


def _paired(rows: Sequence[EpisodeRow], reference: Sequence[EpisodeRow], key: str) -> Interval | None:
    return paired_by_sensor({r.seed: getattr(r, key) for r in rows}, {r.seed: getattr(r, key) for r in reference})


def at_horizon(row: EpisodeRow, horizon_s: float | None) -> EpisodeRow:
    """``row`` as the summary counts it with a common horizon (module doc): not stopped by then, at the horizon."""
    if horizon_s is None or (row.coverage_reached and row.recording_time_s <= horizon_s):
        return row
    return dataclasses.replace(row, coverage_reached=False, recording_time_s=float(horizon_s))


def _cut_short(rows: Sequence[EpisodeRow], horizon_s: float | None) -> float:
    """The share of ``rows`` that neither stopped (at the goal, or as out of reach) nor reached ``horizon_s`` (their
    own limit came first)."""
    if horizon_s is None or not rows:
        return 0.0
    ended = [r.coverage_reached or bool(r.out_of_reach) for r in rows]
    return float(np.mean([not e and r.recording_time_s < horizon_s for r, e in zip(rows, ended, strict=True)]))


def _share(flags: Sequence[bool]) -> float:
    return float(np.mean(flags)) if flags else math.nan


def out_of_reach_rows(rows: Sequence[EpisodeRow], horizon_s: float | None) -> list[EpisodeRow]:
    """The runs of ``rows`` stopped as out of reach within ``horizon_s`` (any time without one)."""
    return [r for r in rows if r.out_of_reach and (horizon_s is None or (r.verdict_s or 0.0) <= horizon_s)]


def verdict_right(row: EpisodeRow) -> bool:
    """Whether an out-of-reach verdict held: the run, gone on past it (``stop.verify_s``), never reached the goal."""
    return row.reached_s is None


def forecast_right(row: EpisodeRow) -> bool:
    """A stopped run's predicted time to the goal was within ``FORECAST_FACTOR`` of its measured one."""
    if row.predicted_s is None or row.recording_time_s <= 0:
        return False
    return 1 / FORECAST_FACTOR <= row.predicted_s / row.recording_time_s <= FORECAST_FACTOR


def _mean_decision_ms(rows: Sequence[EpisodeRow]) -> float:
    """The mean time per step [ms] over the episodes' steps (nan where no row recorded it)."""
    timed = [r for r in rows if r.decision_ms is not None and r.steps > 0]
    if not timed:
        return math.nan
    return float(sum(r.decision_ms * r.steps for r in timed) / sum(r.steps for r in timed))


def summarize_stops(
    rows: Mapping[str, Sequence[EpisodeRow]],
    task: str,
    tolerances: Mapping[str, float],
    reference: str | None,
    horizon_s: float | None = None,
    verifying: bool = False,
) -> list[StopSummary]:
    """Every policy's stops from its rows (``{policy: rows}``, every budget; the whole episodes are used), counted
    at the common ``horizon_s`` [s] where one is given; ``verifying``: the runs stopped as out of reach were run on
    (``stop.verify_s``), so their verdicts are checked."""
    if task not in SCORED_GROUPS:
        raise ValueError(f"task must be one of {sorted(SCORED_GROUPS)}, got {task!r}")
    whole = {name: [r for r in rs if r.budget_m == END] for name, rs in rows.items()}
    ends = {name: [at_horizon(r, horizon_s) for r in rs] for name, rs in whole.items()}
    summaries = []
    for name, mine in ends.items():
        if not mine:
            continue
        stopped = [r for r in mine if r.coverage_reached]
        right = [stopped_right(r, task, tolerances) for r in stopped]
        given_up = out_of_reach_rows(whole[name], horizon_s)
        checked = verifying and given_up
        forecasts = any(r.predicted_s is not None for r in stopped)
        versus = reference is not None and name != reference and reference in ends
        times = [r.recording_time_s for r in mine]
        summaries.append(
            StopSummary(
                policy=name,
                sensors=len(mine),
                stopped=len(stopped) / len(mine),
                right=float(np.mean(right)) if right else math.nan,
                time_s=float(np.mean(times)),
                median_time_s=float(np.median(times)),
                path_m=float(np.mean([r.path_length_m for r in mine])),
                decision_ms=_mean_decision_ms(mine),
                cut_short=_cut_short(whole[name], horizon_s),
                out_of_reach=len(given_up) / len(mine),
                verdict_right=_share([verdict_right(r) for r in given_up]) if checked else math.nan,
                forecast_right=_share([forecast_right(r) for r in stopped]) if forecasts else math.nan,
                time_versus=_paired(mine, ends[reference], "recording_time_s") if versus else None,
                path_versus=_paired(mine, ends[reference], "path_length_m") if versus else None,
            )
        )
    return summaries
