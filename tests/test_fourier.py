"""Fourier-loop baselines: the loop's shape and bounds, the policies' configs and a real episode each."""

from types import SimpleNamespace

import hydra.utils
import numpy as np
import pytest
import yaml
from configs import CONF, env_parts
from hydra import compose, initialize_config_dir

from vical.config_checks import ConfigError
from vical.env.calibration import CalibrationEnv
from vical.env.settings import MdpConfig, Workspace
from vical.policies.base import Policy
from vical.policies.fourier import (
    DEFAULT_PARAMS_FILE,
    HARMONICS,
    SHAPE,
    FourierTrajectory,
    FourierTrajectoryPolicy,
    model_based_policy,
    random_trajectory_policy,
    workspace_bound,
)

BOUND = np.array([0.08, 0.10, 0.08, 0.17, 0.15, 0.12])


def test_default_bound_is_the_paper_workspace():
    np.testing.assert_array_equal(workspace_bound(), BOUND)


def test_loop_is_closed():
    trajectory = FourierTrajectory.random(np.random.default_rng(0))
    np.testing.assert_allclose(trajectory.evaluate([0.0]), trajectory.evaluate([1.0]), atol=1e-15)
    np.testing.assert_allclose(trajectory.evaluate([0.3]), trajectory.evaluate([2.3]), atol=1e-15)
    waypoints = trajectory.offsets(9)
    assert waypoints.shape == (9, 6)
    np.testing.assert_allclose(waypoints[0], waypoints[-1], atol=1e-15)
    assert np.linalg.norm(waypoints[0] - waypoints[4]) > 1e-3  # not a constant


def test_only_harmonics_1_2_4_carry_energy():
    trajectory = FourierTrajectory.random(np.random.default_rng(1))
    samples = trajectory.evaluate(np.arange(64) / 64)  # one period, no repeated end point
    power = np.abs(np.fft.rfft(samples, axis=0)) ** 2
    others = [k for k in range(power.shape[0]) if k not in HARMONICS]
    assert np.all(power[list(HARMONICS)] > 1e-8)
    assert np.all(power[others] < 1e-20)


def test_a_single_coefficient_is_that_harmonic_in_bound_units():
    c = np.zeros(SHAPE)
    c[1, 1, 2] = 0.5  # y, sine, harmonic 4
    phase = np.linspace(0, 1, 33)
    y = FourierTrajectory(c).evaluate(phase)[:, 1]
    np.testing.assert_allclose(y, 0.5 * BOUND[1] * np.sin(2 * np.pi * 4 * phase), atol=1e-15)


def test_random_loops_stay_inside_the_workspace():
    rng = np.random.default_rng(2)
    extremes = np.zeros(6)
    for _ in range(1000):
        trajectory = FourierTrajectory.random(rng)
        assert np.all(FourierTrajectory.amplitude_sums(trajectory.coefficients) <= 1 + 1e-12)
        offsets = np.abs(trajectory.offsets(41))
        assert np.all(offsets <= BOUND + 1e-12)
        extremes = np.maximum(extremes, offsets.max(axis=0))
    assert np.all(extremes > 0.8 * BOUND)  # the loops use most of the workspace, not a shrunken corner


def test_small_coefficients_are_kept_and_large_ones_scaled_per_dof():
    c = np.zeros(SHAPE)
    c[0, 0, 0], c[0, 1, 0] = 0.3, 0.4  # x: amplitude 0.5, kept
    c[3, 0, :] = [1.0, 1.0, 2.0]  # roll: amplitude sum 4, scaled by 1/4
    fitted = FourierTrajectory(c).coefficients
    np.testing.assert_array_equal(fitted[0], c[0])
    np.testing.assert_allclose(fitted[3], c[3] / 4)
    np.testing.assert_allclose(FourierTrajectory(c).evaluate([0.0])[0, 3], BOUND[3])


def test_same_seed_same_trajectory():
    a, b, c = (random_trajectory_policy(seed=s) for s in (3, 3, 4))
    np.testing.assert_array_equal(a.waypoints, b.waypoints)
    assert not np.allclose(a.waypoints, c.waypoints)
    env = SimpleNamespace(config=MdpConfig())  # reset reads only the workspace
    a.reset(env, np.random.default_rng(11))
    b.reset(env, np.random.default_rng(11))
    np.testing.assert_array_equal(a.waypoints, b.waypoints)
    first = a.waypoints.copy()
    a.reset(env, np.random.default_rng(12))
    assert not np.allclose(first, a.waypoints)  # redrawn per episode


def test_loop_scales_to_the_env_workspace():
    policy = random_trajectory_policy(num_waypoints=11, redraw=False)
    small = MdpConfig(workspace=Workspace(position=(0.04, 0.05, 0.04), orientation=(0.085, 0.075, 0.06)))
    before = policy.waypoints.copy()
    policy.reset(SimpleNamespace(config=small), np.random.default_rng(0))
    np.testing.assert_allclose(policy.waypoints, before / 2, atol=1e-15)


@pytest.mark.parametrize(
    "coefficients, match",
    [(np.zeros(35), "36 finite"), (np.zeros((6, 3, 2)), "36 finite"), (np.full(SHAPE, np.nan), "36 finite")],
)
def test_bad_coefficients_are_refused(coefficients, match):
    with pytest.raises(ValueError, match=match):
        FourierTrajectory(coefficients)


def test_too_few_waypoints_are_refused():
    with pytest.raises(ValueError, match="num_waypoints"):
        FourierTrajectory(np.zeros(SHAPE)).offsets(1)


@pytest.mark.parametrize("task", ["intrinsic", "extrinsic"])
def test_model_based_policy_loads_the_committed_params(task):
    entry = yaml.safe_load(DEFAULT_PARAMS_FILE.read_text())["paper"][task]
    policy = model_based_policy(task, "paper")
    assert policy.name == f"model-based learned trajectory ({task})"
    # The file stores 6 decimals: a DoF rounded just past an amplitude sum of 1 is rescaled by < 1e-5.
    np.testing.assert_allclose(policy.trajectory.coefficients, np.array(entry["coefficients"]), atol=1e-5)
    assert policy.waypoints.shape == (entry["num_waypoints"], 6)
    assert entry["training_seeds"] and min(entry["training_seeds"]) >= 20  # disjoint from evaluation seeds 0..19
    assert np.all(np.abs(policy.waypoints) <= BOUND + 1e-12)


def test_missing_params_file_names_the_file_and_the_fix(tmp_path):
    missing = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError, match=r"nope\.yaml not found.*fit_model_based_trajectory\.py"):
        model_based_policy("intrinsic", params_file=missing)


@pytest.mark.parametrize(
    "text, match",
    [
        ("paper: {intrinsic: {coefficients: [1, 2, 3]}}\n", "paper.intrinsic.coefficients is malformed"),
        (
            "paper: {extrinsic: {coefficients: []}}\n",
            "no model-based trajectory fitted for the intrinsic task in workspace 'paper'",
        ),
        ("practitioner: {intrinsic: {coefficients: []}}\n", "no model-based trajectory fitted for the intrinsic"),
        ("paper: [unclosed\n", "cannot read"),
    ],
)
def test_malformed_params_file_names_the_file_and_the_fix(tmp_path, text, match):
    path = tmp_path / "params.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match) as info:
        model_based_policy("intrinsic", params_file=path)
    assert str(path) in str(info.value) and "fit_model_based_trajectory.py" in str(info.value)


def test_unknown_task_is_refused():
    with pytest.raises(ConfigError, match="task must be one of"):
        model_based_policy("calibrate-everything")


def test_paper_workspace_has_no_joint_fit_and_says_how_to_make_one():
    with pytest.raises(
        ConfigError,
        match=r"no model-based trajectory fitted for the joint task in workspace 'paper'.*--workspace paper --tasks joint",  # noqa: E501
    ):
        model_based_policy("joint", "paper")


@pytest.mark.parametrize("option", ["random_trajectory", "model_based"])
def test_policy_configs_instantiate_from_any_directory(option, tmp_path, monkeypatch):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=[f"policy={option}", "workspace=paper"]).policy
    monkeypatch.chdir(tmp_path)  # the params file resolves from the package, not the working directory
    assert cfg.paper_two_trajectories and cfg.name
    for task in ("intrinsic", "extrinsic"):
        policy = hydra.utils.instantiate(cfg[task])
        assert isinstance(policy, Policy) and isinstance(policy, FourierTrajectoryPolicy)
        assert not policy.stop_at_coverage


@pytest.fixture(scope="module")
def env():
    sim, sensor, task, mdp = env_parts("intrinsic", "paper")
    e = CalibrationEnv(sim, sensor, task, **{**mdp, "max_steps": 20, "terminate_on_coverage": False})
    yield e
    e.close()


@pytest.mark.parametrize(
    "make_policy",
    [
        lambda: random_trajectory_policy(num_waypoints=8),
        lambda: model_based_policy("intrinsic", "paper", num_waypoints=8),
    ],
    ids=["random", "model_based"],
)
def test_an_episode_visits_every_waypoint(env, make_policy):
    policy = make_policy()
    obs, _ = env.reset(seed=5)
    policy.reset(env, np.random.default_rng(5))
    visited = []
    while not policy.finished and env.steps < policy.max_steps:
        obs, *_ = env.step(policy.act(obs, env))
        visited.append(env.pose_offset)
    assert policy.finished
    assert env.steps <= len(policy.waypoints) + 1  # one step per waypoint, and the step that finds the last reached
    visited = np.array(visited)
    for waypoint in policy.waypoints:
        position = np.linalg.norm(visited[:, :3] - waypoint[:3], axis=1)
        angle = np.abs(visited[:, 3:] - waypoint[3:]).max(axis=1)
        assert np.any((position <= 2e-3) & (angle <= 2e-3)), f"waypoint {waypoint} not visited"
