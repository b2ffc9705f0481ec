"""Time to the tolerances: stops, right stops, time and path at the stop, paired differences to a reference."""

import math

import numpy as np
import pytest

from vical.evaluation.harness import END, EpisodeRow
from vical.evaluation.intervals import paired_difference
from vical.evaluation.time_to_tolerance import summarize_stops

TOLERANCES = {"rotation_deg": 0.1, "translation_mm": 2.0, "time_offset_ms": 0.1, "focal_px": 0.35}


def row(policy, seed, stopped, time, path, rotation=0.05, failed=False, budget=END):
    return EpisodeRow(policy, seed, budget_m=budget, coverage_reached=stopped, recording_time_s=time,
                      path_length_m=path, rotation_deg=rotation, translation_mm=1.0, time_offset_ms=0.05,
                      focal_px=5.0, failed=failed)  # fmt: skip


def test_stops_right_stops_and_the_paired_differences_are_counted_from_the_whole_episodes():
    rng = np.random.default_rng(0)
    seeds = range(12)
    ref_time, ref_path = rng.uniform(15, 25, 12), rng.uniform(0.8, 1.2, 12)
    reference = [row("expert", s, True, t, p) for s, t, p in zip(seeds, ref_time, ref_path, strict=True)]
    mine = [
        row("planner", s, s != 0, ref_time[s] - 3, ref_path[s] - 0.2, rotation=0.2 if s == 1 else 0.05, failed=s == 2)
        for s in seeds
    ]
    mine.append(row("planner", 5, True, 1.0, 0.1, budget=0.5))  # a budget's row: not an episode's end
    expert, planner = summarize_stops({"expert": reference, "planner": mine}, "joint", TOLERANCES, "expert")
    assert (planner.sensors, planner.stopped) == (12, pytest.approx(11 / 12))
    # Of the 11 stopped, seed 1 is off by 0.2 deg and seed 2's calibration failed; focal_px is not scored here.
    assert planner.right == pytest.approx(9 / 11)
    assert planner.time_s == pytest.approx(np.mean(ref_time - 3))
    assert planner.time_versus.estimate == pytest.approx(-3.0) and planner.time_versus.high < 0
    expected = paired_difference(ref_path - 0.2, ref_path)
    assert planner.path_versus.estimate == pytest.approx(expected.estimate)
    assert expert.time_versus is None and expert.right == 1.0


def test_no_interval_on_too_few_sensors_and_no_right_without_a_stop():
    rows = {"a": [row("a", s, False, 30.0, 2.0) for s in range(3)], "b": [row("b", s, True, 10, 1) for s in range(3)]}
    a, b = summarize_stops(rows, "joint", TOLERANCES, "b")
    assert b.stopped == 1 and b.right == 1.0
    assert a.stopped == 0 and math.isnan(a.right) and a.time_versus is None  # 3 sensors: no 95 % interval
    with pytest.raises(ValueError, match="task must be one of"):
        summarize_stops(rows, "two_stage", TOLERANCES, None)


def test_the_decision_time_is_the_mean_over_the_episodes_steps():
    rows = [row("planner", s, True, 10.0, 1.0) for s in range(3)]
    for r, (ms, steps) in zip(rows, ((200.0, 10), (300.0, 30), (None, 5)), strict=True):
        r.decision_ms, r.steps = ms, steps
    (planner,) = summarize_stops({"planner": rows}, "joint", TOLERANCES, None)
    assert planner.decision_ms == pytest.approx((200.0 * 10 + 300.0 * 30) / 40)  # the untimed row left out
    (old,) = summarize_stops({"old": [row("old", 0, True, 10.0, 1.0)]}, "joint", TOLERANCES, None)
    assert math.isnan(old.decision_ms)  # a results file from before the column


def test_a_common_horizon_counts_every_run_not_stopped_by_then_at_it():
    runs = [
        row("p", 0, True, 20.0, 1.0),  # stopped within the horizon: as it is
        row("p", 1, True, 60.0, 3.0),  # stopped after it: no stop, at the horizon
        row("p", 2, False, 30.0, 1.5),  # its own limit ended it first: at the horizon, and cut short
        row("p", 3, False, 90.0, 4.0),  # ran past it: at the horizon
    ]
    (plain,) = summarize_stops({"p": runs}, "joint", TOLERANCES, None)
    (capped,) = summarize_stops({"p": runs}, "joint", TOLERANCES, None, horizon_s=45.0)
    assert plain.stopped == 0.5 and plain.time_s == pytest.approx(50.0) and plain.cut_short == 0.0
    assert capped.stopped == 0.25 and capped.right == 1.0
    assert capped.time_s == pytest.approx((20.0 + 3 * 45.0) / 4) and capped.median_time_s == 45.0
    assert capped.cut_short == 0.25


def test_runs_stopped_as_out_of_reach_count_at_the_horizon_and_their_verdicts_and_forecasts_are_checked():
    runs = [
        row("p", 0, True, 20.0, 1.0),  # the goal at 20 s, predicted halfway at 25 s: within 1.5x
        row("p", 1, True, 10.0, 0.5),  # predicted at 30 s: not within 1.5x
        row("p", 2, False, 18.0, 1.0),  # out of reach at 18 s, and not reached by 90 s: right
        row("p", 3, False, 25.0, 1.2),  # out of reach at 25 s, but reached at 70 s: wrong
        row("p", 4, False, 45.0, 2.0),  # neither: ran to the horizon
    ]
    runs[0].predicted_s, runs[1].predicted_s = 25.0, 30.0
    runs[2].out_of_reach, runs[2].verdict_s = "time_offset", 18.0
    runs[3].out_of_reach, runs[3].verdict_s, runs[3].reached_s = "rotation", 25.0, 70.0
    (p,) = summarize_stops({"p": runs}, "joint", TOLERANCES, None, horizon_s=45.0, verifying=True)
    assert p.stopped == pytest.approx(2 / 5) and p.out_of_reach == pytest.approx(2 / 5)
    assert p.verdict_right == 0.5 and p.forecast_right == 0.5
    assert p.time_s == pytest.approx((20.0 + 10.0 + 3 * 45.0) / 5)  # giving up early is never rewarded
    assert p.cut_short == 0.0  # a verdict is an end, not a limit
    (unchecked,) = summarize_stops({"p": runs}, "joint", TOLERANCES, None, horizon_s=45.0)
    assert math.isnan(unchecked.verdict_right)  # not run on: nothing to check the verdicts by
