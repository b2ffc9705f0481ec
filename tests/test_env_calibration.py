"""The calibration MDP on the real simulator and calibrator: state, rewards, termination, calibration."""

import numpy as np
import pytest
from configs import env_parts

from vical.config_checks import ConfigError
from vical.env.calibration import CalibrationEnv
from vical.env.coverage import Coverage, view_features
from vical.env.rewards import accuracy_reward
from vical.env.settings import MdpConfig
from vical.policies.base import WaypointPolicy

# Waypoints (pose offsets in the authors' box) that sweep the board over the four quadrants, change its distance
# and tilt it.
SWEEP = np.array(
    [
        [0.08, 0.05, 0.04, 0.17, 0.15, 0.12],
        [-0.08, -0.05, 0.04, -0.17, 0.15, -0.12],
        [0.08, -0.05, -0.04, 0.17, -0.15, -0.12],
        [-0.08, 0.05, -0.04, -0.17, -0.15, 0.12],
        [0.08, 0.0, 0.0, -0.17, 0.15, 0.0],
    ]
)


def make_env(task: str = "intrinsic", **overrides) -> CalibrationEnv:
    """The paper's MDP in the authors' box (the workspace its thresholds were set for)."""
    sim, sensor, task_cfg, mdp = env_parts(task, "paper")
    return CalibrationEnv(sim, sensor, task_cfg, **{**mdp, **overrides})


@pytest.fixture(scope="module")
def env():
    e = make_env()
    yield e
    e.close()


def run_sweep(env: CalibrationEnv, seed: int = 0):
    policy = WaypointPolicy(SWEEP)
    obs, _ = env.reset(seed=seed)
    policy.reset(env, np.random.default_rng(0))
    transitions = []
    while True:
        prev = obs
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, env))
        transitions.append((prev, obs, reward, info))
        if terminated or truncated:
            return transitions, terminated, truncated


def test_reset_gives_a_normalised_state_at_the_start_pose(env):
    obs, info = env.reset(seed=0)
    assert obs.shape == (24,) and obs.dtype == np.float32
    assert env.observation_space.contains(obs)
    np.testing.assert_allclose(obs[18:], 0.5, atol=1e-4)  # no offset from the start pose yet
    assert info["coverage/views"] >= 1  # the rest at the start pose sees the board
    assert obs[8] > 0.01 and obs[9] == obs[8]  # one view: A_min = A_max = its area


def test_same_seed_same_sensor_and_same_episode(env):
    actions = np.random.default_rng(5).uniform(env.action_space.low, env.action_space.high, (4, 6))

    def episode(seed):
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for a in actions:
            out.append(env.step(a)[0])
        return env.truth, np.array(out)

    truth_a, obs_a = episode(7)
    truth_b, obs_b = episode(7)
    truth_c, _ = episode(8)
    assert truth_a.camera == truth_b.camera
    np.testing.assert_array_equal(obs_a, obs_b)
    assert truth_c.camera.fx != truth_a.camera.fx


def test_another_noise_stream_records_the_same_sensor_with_other_noise(env):
    def imu(stream):
        env.reset(seed=9, options={"noise_stream": stream})
        env.step(np.array([0.1, 0.3, 1.0, 0.1, 0.0, 0.0]))
        return env.truth, env.recording().imu

    truth_a, imu_a = imu(0)
    truth_b, imu_b = imu(1)
    _, imu_c = imu(0)
    assert truth_a.camera == truth_b.camera
    np.testing.assert_allclose(truth_a.T_cam_imu, truth_b.T_cam_imu)
    np.testing.assert_array_equal(imu_a.gyro, imu_c.gyro)
    difference = imu_a.gyro - imu_b.gyro  # same motion, independent white noise
    assert 0 < np.std(difference) < 0.01


def test_step_reward_is_the_sum_of_its_terms_and_the_terms_are_measured(env):
    prev, _ = env.reset(seed=1)
    before_path = env.recording().path_length
    action = np.array([0.1, 0.4, 1.2, 0.1, -0.1, 0.05], dtype=np.float32)
    obs, reward, _, _, info = env.step(action)
    terms = {k: v for k, v in info.items() if k.startswith("reward/")}
    assert reward == pytest.approx(sum(terms.values()))
    w = env.config.reward
    np.testing.assert_allclose(
        info["reward/coverage"], w.coverage_weight * np.abs(obs[:18] - prev[:18]).sum(), rtol=1e-5
    )
    path = env.recording().path_length - before_path
    assert path > 0.05
    assert info["reward/path"] == pytest.approx(-w.path_weight * path)


def test_the_workspace_bounds_the_pose(env):
    env.reset(seed=2)
    for _ in range(4):  # push along +y and rotate about z as far as the action allows
        env.step(np.array([0.3, np.pi / 2, np.pi / 2, 0.0, 0.0, 0.4]))
    bound = np.r_[env.config.workspace.position, env.config.workspace.orientation]
    offset = env.pose_offset
    assert offset[1] == pytest.approx(bound[1], abs=1e-3)
    assert offset[5] == pytest.approx(bound[5], abs=1e-3)
    assert np.all(np.abs(offset) <= bound + 1e-3)


def test_coverage_state_is_the_range_of_the_recorded_views(env):
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(5):
        obs = env.step(rng.uniform(env.action_space.low, env.action_space.high))[0]
    cov = Coverage(env.config.workspace, env.config.thresholds, env.config.view_novelty)
    cam = env.truth.camera
    for corners, ids in zip(*env.recorder.detections_since(0), strict=True):
        view = view_features(corners, ids, env.target, cam.width, cam.height)
        if view is not None:
            cov.add_view(view)
    np.testing.assert_allclose(obs[:12], cov.vector()[:12], atol=1e-6)


def test_complete_coverage_terminates_and_pays_for_an_accurate_calibration():
    env = make_env(thresholds={"skew_range": 0.03})  # the sweep tilts less than the paper's threshold needs
    transitions, terminated, truncated = run_sweep(env)
    env.close()
    assert terminated and not truncated
    *_, info = transitions[-1]
    assert info["calib/failed"] == 0.0
    assert info["calib/error_pct"] < 1.0  # the intrinsic error of the paper [%]
    assert info["reward/terminal"] == 100.0
    assert info["reward/accuracy"] == pytest.approx(accuracy_reward(info["calib/error_pct"], env.config.reward))
    assert all("calib/error_pct" not in t[3] for t in transitions[:-1])  # one calibration per episode


def test_termination_without_the_solve_pays_only_the_bonus():
    env = make_env(thresholds={"skew_range": 0.03}, calibrate_on_termination=False)
    transitions, terminated, _ = run_sweep(env)
    env.close()
    *_, info = transitions[-1]
    assert terminated
    assert not any(key.startswith("calib/") for key in info)
    assert info["reward/terminal"] == 100.0 and info["reward/accuracy"] == 0.0


def test_step_limit_truncates_without_calibrating_unless_asked():
    for calibrate in (False, True):
        env = make_env(max_steps=2, calibrate_on_truncation=calibrate)
        env.reset(seed=4)
        env.step(np.array([0.08, 0.0, 1.5, 0.1, 0.1, 0.1]))
        _, _, terminated, truncated, info = env.step(np.array([-0.08, 0.0, 1.5, -0.1, 0.0, -0.1]))
        env.close()
        assert truncated and not terminated
        assert ("calib/error_pct" in info) == calibrate
        assert "reward/terminal" not in info  # only the terminal condition is paid


def test_bad_config_is_refused_by_name():
    with pytest.raises(ConfigError, match=r"unknown setting.*max_stepz"):
        MdpConfig.from_config({"max_stepz": 3})
    with pytest.raises(ConfigError, match=r"env.thresholds.area_range must be a number in \(0.0, 1.0\]"):
        MdpConfig.from_config({"thresholds": {"area_range": -0.1}})
    with pytest.raises(ConfigError, match=r"env\.action_scale must be 6 finite numbers > 0"):
        MdpConfig.from_config({"action_scale": [0.3, 1.0]})
    sim, sensor, _, mdp = env_parts("intrinsic", "paper")
    with pytest.raises(ConfigError, match=r"task\.calibrate"):
        CalibrationEnv(sim, sensor, {"calibrate": "everything"}, **mdp)


def test_step_before_reset_is_refused():
    env = make_env()
    with pytest.raises(RuntimeError, match="before reset"):
        env.step(np.zeros(6))
    env.close()
