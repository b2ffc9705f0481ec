"""The information-greedy planner: its candidates, its predictions against what the env then records, its episodes."""

import dataclasses
from types import SimpleNamespace

import hydra.utils
import numpy as np
import pytest
from configs import env_config
from scipy.spatial.transform import Rotation
from scipy.stats import spearmanr

from vical.config_checks import ConfigError
from vical.env.actions import goal_offset
from vical.env.lookahead import GRAVITY_WORLD, IMU_RATE, ArmTiming, Lookahead, Prediction, imu_readings
from vical.evaluation.harness import build_env, instantiate_policy, run_trajectory
from vical.policies.greedy import DEFAULT_SAMPLES, candidate_actions, greedy_demonstrator, greedy_information_policy
from vical.policies.learned import load_run, shipped_policy_dir
from vical.policies.stopping import StopRule, with_stop
from vical.sim.motion import quintic

SCALE = np.array([0.3, 1.57, 1.57, 0.6, 0.3, 0.3])  # the practitioner's action scale


def test_the_candidates_are_the_twelve_one_axis_moves_at_full_scale_and_draws_from_the_box():
    candidates = candidate_actions(SCALE, DEFAULT_SAMPLES, np.random.default_rng(0))
    assert candidates.shape == (12 + DEFAULT_SAMPLES, 6)
    full = np.r_[np.full(3, SCALE[0]), SCALE[3:]]
    steps = np.array([goal_offset(np.zeros(6), a, np.full(6, 10.0)) for a in candidates[:12]])
    expected = np.concatenate([[sign * full[axis] * np.eye(6)[axis] for sign in (1, -1)] for axis in range(6)])
    np.testing.assert_allclose(steps, expected, atol=1e-3)  # a polar angle clipped to 1.57: 0.2 mm off the plane
    assert np.all(np.abs(candidates) <= SCALE + 1e-12)  # every candidate in the action box
    assert not np.allclose(candidates[12:], candidate_actions(SCALE, DEFAULT_SAMPLES, np.random.default_rng(1))[12:])


@pytest.mark.parametrize("task", ["joint", "intrinsic"])
def test_a_predicted_step_sheds_the_excess_the_recorded_step_then_sheds(task):
    """Random steps of an episode: the prediction made before each step against the information state after it.
    Measured (sensor seeds 7-9): rank correlation 0.92-0.98, mean error 7-24 % of the mean excess shed."""
    env = hydra.utils.instantiate(env_config(task, "practitioner", "env=information"))
    rng = np.random.default_rng(7)
    predicted, recorded = [], []
    try:
        env.reset(seed=7)
        for _ in range(10):
            action = rng.uniform(env.action_space.low, env.action_space.high)
            before = env.state.excess
            prediction = Lookahead(env.state, env.frame, env.pose_offset, env.config, env.step_timing).predict(action)
            env.step(action)
            predicted.append(before - prediction.excess)
            recorded.append(before - env.state.excess)
    finally:
        env.close()
    predicted, recorded = np.array(predicted[1:]), np.array(recorded[1:])  # the first step: the guess's start
    assert spearmanr(predicted, recorded)[0] > 0.85
    assert np.mean(np.abs(predicted - recorded)) < 0.4 * np.mean(np.abs(recorded))


def test_the_planner_reads_only_the_episodes_state_never_the_simulator_or_the_truth():
    """It plans from what vical-collect's episode offers (state, frame, offset, config, action box, step timing)
    alone."""
    planner = greedy_information_policy()
    env = build_env(env_config("joint", "practitioner"), planner)
    try:
        env.reset(seed=5)
        planner.reset(env, np.random.default_rng(5))
        seen = SimpleNamespace(state=env.state, frame=env.frame, pose_offset=env.pose_offset, config=env.config,
                               action_space=env.action_space, step_timing=env.step_timing)  # fmt: skip
        assert env.step_timing == ArmTiming(env.config.settle_time)  # the arm's motion, then the env's rest
        first = planner.act(None, seen)
        planner.reset(env, np.random.default_rng(5))
        assert np.array_equal(planner.act(None, env), first)
    finally:
        env.close()
    assert np.all(np.abs(first) <= env.action_space.high + 1e-9)


@pytest.mark.integration
def test_the_planner_reaches_the_goal_sooner_than_random_motion_with_the_same_stop():
    env_cfg = env_config("joint", "practitioner")
    planner = greedy_information_policy()
    random = with_stop(instantiate_policy({"_target_": "vical.policies.random_policy.RandomMovingPolicy"}, "r"),
                       StopRule("information"))  # fmt: skip
    runs = {}
    for name, policy in (("planner", planner), ("random", random)):
        env = build_env(env_cfg, policy)
        try:
            runs[name] = [run_trajectory(env, policy, seed) for seed in (3, 4)]
        finally:
            env.close()
    assert all(run.coverage_reached for run in runs["planner"])
    time = {name: np.mean([run.recording.duration for run in r]) for name, r in runs.items()}
    assert time["planner"] < 0.5 * time["random"], time
    assert len(planner.decision_times) == sum(run.steps for run in runs["planner"])


def test_before_it_sees_the_board_the_planner_searches_along_the_line_of_sight():
    """A practitioner's product whose board its wide lens detects only nearer than the start: the planner goes
    nearer until a frame poses the board, then plans."""
    planner = greedy_information_policy()
    env = build_env(env_config("joint", "practitioner", "sensor=practitioner", "task.camera_model=sensor"), planner)
    try:
        seed = 40000
        while env.reset(seed=seed) and env.recording().frames.num_detections.max() > 0:
            seed += 1  # the first sensor that sees no corner at the start pose
        planner.reset(env, np.random.default_rng(seed))
        reach = env.config.workspace.bound[0]
        distances = []
        while env.recording().frames.num_detections.max() == 0:
            assert env.steps < 6, "the search did not find the board"
            env.step(planner.act(None, env))
            distances.append(env.pose_offset[0])
        assert distances[0] > 0.5 * reach  # the first step heads for the board, a full step of the action box
        assert env.recording().frames.num_detections.max() >= 4
    finally:
        env.close()


def test_bad_planner_settings_are_refused_by_key():
    with pytest.raises(ConfigError, match=r"policy\.samples must be an integer >= 0"):
        greedy_information_policy(samples=-1)
    with pytest.raises(ConfigError, match=r"trained on the coverage state: name one with policy\.run_dir"):
        greedy_information_policy(workspace="paper")


def test_the_predicted_imu_reads_the_rates_and_specific_force_of_the_motion():
    """A quintic turn about a tilted axis while translating: gyro and accelerometer against the analytic ones."""
    T, dt = 1.2, 1.0 / IMU_RATE
    t = np.arange(0.0, T + dt / 2, dt)
    s, ds, dds = quintic(t / T)
    axis, angle, travel = (
        np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]),
        0.9,
        np.array([0.2, -0.1, 0.15]),
    )
    R0 = Rotation.from_rotvec([0.2, 0.4, -0.3]).as_matrix()
    poses = np.tile(np.eye(4), (len(t), 1, 1))
    poses[:, :3, :3] = R0 @ Rotation.from_rotvec(np.outer(s * angle, axis)).as_matrix()
    poses[:, :3, 3] = np.outer(s, travel)
    gyro, specific_force = imu_readings(poses, dt)
    rate = np.outer(ds / T * angle, axis)  # body rates: the turn is about a body-fixed axis
    inner = slice(2, -2)  # the differences' ends
    np.testing.assert_allclose(gyro[inner], rate[inner], atol=0.01 * angle / T)
    expected = np.einsum("nji,nj->ni", poses[:, :3, :3], np.outer(dds / T**2, travel) - GRAVITY_WORLD)
    np.testing.assert_allclose(specific_force[inner], expected[inner], atol=0.01)


def test_the_planners_price_is_its_learned_runs_not_the_envs():
    """The env it drives is given vical-evaluate's reward (20 per metre); the planner pays the run's (5)."""
    planner = greedy_information_policy()
    env = build_env(env_config("joint", "practitioner"), planner)
    try:
        env.reset(seed=1)
        excess = env.state.excess
        stay = Prediction(np.zeros(6), 1.0, 0.0, 0, {}, excess, False)
        metre = dataclasses.replace(stay, path_length=1.0)
        cost = planner.score(stay, excess, env) - planner.score(metre, excess, env)
    finally:
        env.close()
    assert env.config.reward.path_weight == 20.0
    trained = load_run(shipped_policy_dir())[1]["config"]["env"]["reward"]
    assert cost == pytest.approx(trained["path_weight"]) and cost == pytest.approx(5.0)


def test_as_vical_trains_demonstrator_the_planner_pays_the_trained_envs_own_prices():
    """`greedy_demonstrator` plans in the env being trained at that env's prices (20 per metre here), no run's."""
    planner = greedy_demonstrator()
    env = build_env(env_config("joint", "practitioner"), greedy_information_policy())  # an information state env
    try:
        env.reset(seed=1)
        planner.reset(env, np.random.default_rng(1))
        excess = env.state.excess
        stay = Prediction(np.zeros(6), 1.0, 0.0, 0, {}, excess, False)
        cost = planner.score(stay, excess, env) - planner.score(dataclasses.replace(stay, path_length=1.0), excess, env)
        first = planner.act(None, env)
    finally:
        env.close()
    assert cost == pytest.approx(env.config.reward.path_weight) and cost == pytest.approx(20.0)
    assert np.all(np.abs(first) <= env.action_space.high + 1e-9)
