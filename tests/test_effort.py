"""Error versus effort: budgeted calibrations are calibrations of the recording cut at that path; paired summaries."""

import math

import numpy as np
import pytest
from configs import env_config

from vical.calib.tasks import run_task
from vical.config_checks import ConfigError
from vical.evaluation.error_vs_effort import rows_at_budget, significance_lines, summarize_budget, summarize_effort
from vical.evaluation.harness import END, EpisodeRow, PolicyEvaluator, PolicySpec, run_trajectory
from vical.geometry import invert_transform
from vical.io.recording import load_recording, save_recording
from vical.sim.sampling import sensor_imu_pose

EXPERT_SHORT = {"_target_": "vical.policies.expert.expert_policy", "task": "intrinsic", "length": "short"}
# Two views close to the start: a little data, by design worse than the expert's.
LAZY = {"_target_": "vical.policies.base.WaypointPolicy", "waypoints": [[0.05, 0, 0, 0, 0.1, 0], [0, 0, 0, 0, 0, 0.1]]}


@pytest.fixture(scope="module")
def expert():
    evaluator = PolicyEvaluator(PolicySpec("expert", EXPERT_SHORT, None), env_config("intrinsic"), budgets=(0.5, 1.0))
    yield evaluator
    evaluator.close()


def truth_path_time(recording, budget: float) -> int:
    """[ns] when the camera body's path, rebuilt from the true IMU trajectory, reaches ``budget`` [m]."""
    T_imu_body = invert_transform(sensor_imu_pose(recording.truth))
    positions = (recording.trajectory.T_world_imu @ T_imu_body)[:, :3, 3]
    path = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))]
    return int(recording.trajectory.t[np.searchsorted(path, budget)])


def test_budget_rows_calibrate_the_recording_cut_where_the_path_reached_the_budget(expert, tmp_path):
    rows = expert.episode(7)
    assert [r.budget_m for r in rows] == [0.5, 1.0, END]
    run = run_trajectory(expert.envs[0], expert.policies[0], 7)  # the same seed replays the same episode
    for row in rows:
        cut = run.recording.until_path(row.budget_m)
        outcome = run_task(expert.task, cut)
        assert row.score_pct == pytest.approx(outcome.score, rel=1e-9)
        # The path profile is sampled with the IMU (5 ms): the cut lies within one sample of the budget.
        assert row.path_length_m == pytest.approx(min(row.budget_m, run.recording.path_length), abs=5e-3)
        assert row.frames == len(cut.frames)
    # The cut, checked without the path profile: where the path rebuilt from the true trajectory reaches 1 m.
    cut = run.recording.until_path(1.0)
    t_truth = truth_path_time(run.recording, 1.0)
    assert abs(int(cut.imu.t[-1]) - t_truth) <= 10_000_000  # two IMU samples: the truth is sampled at 200 Hz
    assert np.all(cut.frames.t <= cut.imu.t[-1] + 5_000_000) and np.all(cut.imu.t <= cut.imu.t[-1])
    later = run.recording.frames.t > cut.frames.t[-1]
    assert np.all(run.recording.frames.t[later] > t_truth - 10_000_000)  # nothing after the cut is kept
    np.testing.assert_array_equal(cut.imu.gyro, run.recording.imu.gyro[: len(cut.imu)])  # a prefix, untouched
    # A user's recording cut at that path, written and read back, calibrates the same.
    loaded = load_recording(save_recording(cut, tmp_path / "cut"))
    assert loaded.path_length == pytest.approx(cut.path_length) and len(loaded.path_profile) == len(cut.path_profile)
    assert run_task(expert.task, loaded).score == pytest.approx(rows[1].score_pct, rel=1e-9)


def row(
    policy: str, seed: int, budget: float, score: float | None, prior: float = 5.0, path: float = 1.0
) -> EpisodeRow:
    return EpisodeRow(
        policy, seed, budget, score_pct=score, prior_score_pct=prior, path_length_m=path, failed=score is None
    )


def test_episodes_that_ended_early_stand_in_with_their_whole_recording_and_failures_count_at_the_prior():
    rows = [row("p", 0, 1.0, 0.2), row("p", 0, END, 0.1, path=1.5), row("p", 1, END, None, path=0.8)]
    at = rows_at_budget(rows, 1.0)
    assert at[0].budget_m == 1.0 and at[1].budget_m == END  # seed 1 stopped at 0.8 m
    summary = summarize_budget("p", rows, 1.0, None)
    assert summary.reached == 0.5 and summary.failed == 0.5
    assert summary.mean_error_pct == pytest.approx((0.2 + 5.0) / 2)  # the failure at the nominal error
    assert summary.path_m == pytest.approx((1.0 + 0.8) / 2) and summary.versus is None


def test_summaries_compare_every_policy_with_the_reference_by_sensor():
    seeds = range(30)
    rng = np.random.default_rng(0)
    hard = rng.lognormal(-2, 1, 30)
    rows = {
        "reference": [row("reference", s, END, h) for s, h in zip(seeds, hard, strict=True)],
        "better": [row("better", s, END, 0.8 * h) for s, h in zip(seeds, hard, strict=True)],
    }
    summaries = summarize_effort(rows, budgets=(), reference="reference")
    assert [s.policy for s in summaries] == ["reference", "better"]
    assert summaries[0].versus is None
    assert summaries[1].versus.verdict == "lower" and summaries[1].versus.estimate == pytest.approx(-0.2 * hard.mean())


@pytest.mark.parametrize("sensors", [1, 4])
def test_fewer_than_five_sensors_give_no_interval_and_say_why(sensors):
    """A bootstrap over one sensor reads [x, x]: below five sensors no interval is printed, and the lines say why."""
    rows = {
        "reference": [row("reference", s, END, 0.3) for s in range(sensors)],
        "other": [row("other", s, END, 0.1 + 0.01 * s) for s in range(sensors)],
    }
    summaries = summarize_effort(rows, budgets=(), reference="reference")
    assert summaries[1].versus is None
    assert significance_lines(summaries, "reference") == [
        f"- no confidence interval against reference: a paired 95 % interval needs at least 5 sensors, "
        f"these were evaluated on {sensors}"
    ]


def test_a_policy_better_by_design_is_significantly_better_on_real_episodes(expert):
    lazy = PolicyEvaluator(PolicySpec("lazy", LAZY, None), env_config("intrinsic"), budgets=(0.5,))
    try:
        rows = {"lazy": [], "expert": []}
        for seed in range(30, 35):
            rows["lazy"] += lazy.episode(seed)
            rows["expert"] += expert.episode(seed)
    finally:
        lazy.close()
    assert all(r.budget_m == END for r in rows["lazy"])  # the lazy policy never travels 0.5 m
    summaries = summarize_effort(rows, budgets=(0.5,), reference="lazy")
    for summary in summaries[2:]:  # the expert at 0.5 m and at its end
        assert summary.versus.verdict == "lower", summary
        assert summary.versus.high < 0
        assert not math.isnan(summary.median_error_pct)


def test_budgets_are_refused_for_two_trajectory_episodes_and_must_increase():
    spec = PolicySpec("two", EXPERT_SHORT, {**EXPERT_SHORT, "task": "extrinsic"}, None, paper_two_trajectories=True)
    with pytest.raises(ConfigError, match=r"runs two trajectories .* pass budgets=\[\]"):
        PolicyEvaluator(spec, env_config("joint"), budgets=(1.0,), paper_protocol=True)
    with pytest.raises(ConfigError, match="budgets must be strictly increasing path lengths > 0"):
        PolicyEvaluator(PolicySpec("e", EXPERT_SHORT, None), env_config("intrinsic"), budgets=(1.0, 1.0))
