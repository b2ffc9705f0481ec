"""Evaluation library: per-episode rows with real values, the joint task's two trajectories, failed calibrations."""

import numpy as np
import pytest
from configs import env_config

from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.tasks import run_task
from vical.config_checks import ConfigError
from vical.evaluation.harness import (
    WALL_TIME_FIELDS,
    EpisodeRow,
    PolicyEvaluator,
    PolicySpec,
    evaluate_policies,
    evaluate_policy,
    instantiate_policy,
    run_trajectory,
    summarize,
)
from vical.parallel import ParallelConfig
from vical.policies.base import Policy

SHORT = {"_target_": "vical.policies.handcrafted.handcrafted_policy", "length": "short"}
HANDCRAFTED_SHORT = PolicySpec(
    "hand-crafted trajectory (short)", {**SHORT, "task": "intrinsic"}, {**SHORT, "task": "extrinsic"}, None, True
)
STILL = {"_target_": "vical.policies.base.WaypointPolicy", "waypoints": [[0.0] * 6]}  # records only the start pose


def test_rows_and_summary_hold_the_episodes_real_values():
    evaluator = PolicyEvaluator(HANDCRAFTED_SHORT, env_config("intrinsic", "paper"))
    try:
        rows = [row for seed in (0, 1) for row in evaluator.episode(seed)]
        # The same seed replays the same sensor and motion: the row's values are the recording's.
        (env,), (policy,) = evaluator.envs, evaluator.policies
        run = run_trajectory(env, policy, seed=1)
        outcome = run_task(evaluator.task, run.recording)
    finally:
        evaluator.close()
    assert len(rows) == 2  # no budgets: the whole episode only
    row = rows[1]
    assert not row.failed and row.policy == "hand-crafted trajectory (short)" and row.seed == 1
    assert row.budget_m == np.inf
    assert row.path_length_m == pytest.approx(run.recording.path_length, rel=1e-9)
    assert row.path_length_m > 0.3
    assert row.steps == run.steps == len(policy.waypoints)
    assert row.frames == len(run.recording.frames)
    assert row.score_pct == pytest.approx(outcome.score, rel=1e-6)
    assert row.intrinsic_pct == row.score_pct
    assert row.intrinsic_px == pytest.approx(np.linalg.norm(outcome.errors.intrinsic_abs_px), rel=1e-6)
    assert np.hypot(row.focal_px, row.principal_point_px) == pytest.approx(row.intrinsic_px, rel=1e-6)
    assert 0.0 < row.distortion_px < 5.0
    assert row.extrinsic_pct is None and row.rotation_deg is None and row.time_offset_ms is None
    assert 0.0 < row.calib_time_s < 10.0
    summary = summarize("x", rows)
    scores = [r.score_pct for r in rows]
    assert (summary.episodes, summary.failed) == (2, 0)
    assert summary.mean_error_pct == pytest.approx(np.mean(scores))
    assert summary.error_std_pct == pytest.approx(np.std(scores))
    assert summary.path_length_m == pytest.approx(np.mean([r.path_length_m for r in rows]))
    assert summary.calib_time_s == pytest.approx(np.mean([r.calib_time_s for r in rows]))
    assert summary.rotation_deg is None


def test_joint_task_runs_both_trajectories_and_calibrates_intrinsics_from_the_first():
    evaluator = PolicyEvaluator(HANDCRAFTED_SHORT, env_config("joint", "paper"), paper_protocol=True)
    try:
        assert evaluator.task.calibrate == "two_stage" and evaluator.task.error_metric == "extrinsic_relative"
        assert [p.task for p in evaluator.policies] == ["intrinsic", "extrinsic"]
        (row,) = evaluator.episode(0)
        pairs = enumerate(zip(evaluator.envs, evaluator.policies, strict=True))
        first, second = (run_trajectory(env, p, 0, noise_stream=k) for k, (env, p) in pairs)
        outcome = run_task(evaluator.task, second.recording, first.recording.frames)
    finally:
        evaluator.close()
    truth = first.recording.truth
    np.testing.assert_array_equal(truth.camera.intrinsics, second.recording.truth.camera.intrinsics)  # one sensor
    np.testing.assert_array_equal(truth.T_cam_imu, second.recording.truth.T_cam_imu)
    assert not row.failed
    assert row.path_length_m == pytest.approx(first.recording.path_length + second.recording.path_length, rel=1e-9)
    assert row.steps == first.steps + second.steps
    intrinsic = calibrate_intrinsics(
        first.recording.frames, first.recording.target, "radtan", (truth.camera.width, truth.camera.height)
    )
    np.testing.assert_allclose(outcome.result.camera.intrinsics, intrinsic.camera.intrinsics, rtol=1e-9)
    assert row.score_pct == pytest.approx(outcome.score, rel=1e-6)
    assert row.score_pct == pytest.approx(row.extrinsic_pct)
    assert row.rotation_deg is not None and row.translation_mm is not None and row.time_offset_ms is not None


def test_a_failed_calibration_is_a_counted_row():
    still = PolicySpec("still", STILL, STILL)
    evaluation = evaluate_policy(still, env_config("intrinsic", "paper"), seeds=[0], progress=False)
    (failed,) = evaluation.rows
    assert failed.failed and "frames" in failed.error
    assert failed.score_pct is None and failed.steps == 0
    # Paired comparisons count it at the nominal parameters' error: the mean camera against this sensor.
    assert failed.effective_score_pct == failed.prior_score_pct > 0.5
    assert evaluation.summary.failed == 1 and np.isnan(evaluation.summary.mean_error_pct)
    good = EpisodeRow("p", 1, score_pct=2.0, intrinsic_pct=2.0, path_length_m=1.0, calib_time_s=0.5)
    summary = summarize("p", [good, failed])
    assert (summary.episodes, summary.failed) == (2, 1)
    assert summary.mean_error_pct == 2.0 and summary.error_std_pct == 0.0
    assert summary.path_length_m == pytest.approx((1.0 + failed.path_length_m) / 2)


def test_policy_specs_are_checked():
    with pytest.raises(ConfigError, match=r"policy\.name"):
        PolicySpec.from_config({"intrinsic": STILL})
    with pytest.raises(ConfigError, match=r"policy\.extrinsic"):
        PolicySpec.from_config({"name": "p", "extrinsic": {"length": "long"}})
    spec = PolicySpec.from_config({"name": "only intrinsic", "intrinsic": STILL, "extrinsic": None, "joint": None})
    joint_task = type("Task", (), {"calibrate": "joint"})()
    with pytest.raises(ConfigError, match="no spec for the joint task"):
        spec.for_task(joint_task)
    two = PolicySpec.from_config({"name": "two", "intrinsic": STILL, "extrinsic": None, "paper_two_trajectories": True})
    with pytest.raises(ConfigError, match="runs two trajectories but has no extrinsic spec"):
        two.for_task(joint_task, paper_protocol=True)
    with pytest.raises(ConfigError, match=r"no spec for the joint task .*under the paper's protocol"):
        two.for_task(joint_task)
    with pytest.raises(ConfigError, match="paper_two_trajectories must be true or false"):
        PolicySpec.from_config({"name": "p", "intrinsic": STILL, "paper_two_trajectories": "yes"})
    with pytest.raises(ConfigError, match="returned dict, not a Policy"):
        instantiate_policy({"_target_": "builtins.dict"}, "p")
    with pytest.raises(ConfigError, match=r"policy 'p': .*handcrafted_policy failed: .*lengths"):
        instantiate_policy({**SHORT, "task": "intrinsic", "length": "medium"}, "p")


RANDOM_SHORT = PolicySpec(
    "random moving (3 steps)",
    {"_target_": "vical.policies.random_policy.RandomMovingPolicy", "max_steps": 3},
    {"_target_": "vical.policies.random_policy.RandomMovingPolicy", "max_steps": 3},
)


def _without_wall_time(rows: list[EpisodeRow]) -> list[dict]:
    return [{k: v for k, v in vars(r).items() if k not in WALL_TIME_FIELDS} for r in rows]


@pytest.mark.integration
def test_parallel_evaluation_gives_the_serial_rows():
    """Episodes on two worker processes: the same rows in the same order (all but the wall times)."""
    specs, env, seeds = [HANDCRAFTED_SHORT, RANDOM_SHORT], env_config("intrinsic", "paper"), [0, 1, 2]
    serial = evaluate_policies(specs, env, seeds, budgets=(0.3,), progress=False)
    parallel = evaluate_policies(specs, env, seeds, budgets=(0.3,), parallel=ParallelConfig(2), progress=False)
    for s, p in zip(serial, parallel, strict=True):
        assert len(s.rows) >= len(seeds) and _without_wall_time(s.rows) == _without_wall_time(p.rows)
    assert any(r.budget_m == 0.3 for r in serial[0].rows)  # budget rows too


@pytest.mark.integration
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time
def test_evaluation_on_a_local_ray_instance_gives_the_serial_rows():
    """The episodes as Ray tasks (a local instance of 2 CPUs): the serial rows and numbers, in the same order."""
    import ray  # a dev dependency: `make test` installs it, so this test never skips

    specs, env, seeds = [HANDCRAFTED_SHORT, RANDOM_SHORT], env_config("intrinsic", "paper"), [0, 1]
    serial = evaluate_policies(specs, env, seeds, budgets=(0.3,), progress=False)
    try:
        on_ray = evaluate_policies(specs, env, seeds, budgets=(0.3,), parallel=ParallelConfig(2, "ray"), progress=False)
        assert ray.cluster_resources()["CPU"] == 2  # the evaluation really ran on Ray
    finally:
        ray.shutdown()
    for s, r in zip(serial, on_ray, strict=True):
        assert len(s.rows) >= len(seeds) and _without_wall_time(s.rows) == _without_wall_time(r.rows)


class BrokenPolicy(Policy):
    """A policy whose action has the wrong length: the env's step raises in the middle of the episode."""

    name = "broken"

    def act(self, obs: np.ndarray, env) -> np.ndarray:
        return np.zeros(5)


def test_an_episode_that_raises_becomes_a_failed_row_naming_its_seed_and_the_rest_runs():
    broken = PolicySpec("broken", {"_target_": "test_evaluation.BrokenPolicy"}, None)
    evaluation = evaluate_policies([broken, HANDCRAFTED_SHORT], env_config("intrinsic", "paper"), [4], progress=False)
    (row,) = evaluation[0].rows
    assert row.failed and row.seed == 4 and row.error.startswith("the episode of sensor seed 4 failed: ")
    assert not evaluation[1].rows[0].failed  # the other policy's episode ran
