"""The information state: the calibrator's covariance predicted while data arrive, its MDP, its bad inputs."""

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from configs import composed

from vical.calib.solve.imu_model_error import ACCEL, GYRO
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.observations import collect_observations
from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint
from vical.calib.solve.visual_inertial import ViOptions
from vical.calib.synthetic import make_recording, scattered_views, wide_angle_camera
from vical.config_checks import ConfigError
from vical.data import ImuNoise, ImuSamples, Target
from vical.data.imu_grade import GRADES
from vical.env.calibration import CalibrationEnv
from vical.env.information import (
    GROUPS,
    OFFSET_NODES,
    OFFSET_WEIGHTS,
    Guess,
    InformationTracker,
    LensSpread,
    axis_ratios,
    excess,
    features,
    lens_misfits,
    quantile_factor,
)
from vical.env.lookahead import Lookahead
from vical.env.state import AXIS_SIZE, INFORMATION_SIZE, SENSOR_SIZE, sensor_features
from vical.geometry import CameraModel
from vical.rl.envs import make_env

BIASES = {"gyro_bias": [0.01, -0.02, 0.005], "accel_bias": [0.05, -0.1, 0.08]}  # [rad/s], [m/s^2]


@pytest.fixture(scope="module")
def recording():
    return make_recording(
        duration=12.0, target=Target.aprilgrid(), seed=3, time_offset=0.01, imu_noise=ImuNoise(), pixel_sigma=0.3,
        **BIASES,
    )  # fmt: skip


def calibrator_sigmas(task: str, rec) -> dict[str, float]:
    """The groups' 1-sigma as the calibrator reports them (its covariance at the solution)."""
    if task == "intrinsic":
        sig = calibrate_intrinsics(rec.frames, rec.target, "radtan", (640, 480), pixel_sigma=0.3).sigmas
    elif task == "extrinsic":
        sig = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, rec.truth.imu_noise).sigmas
    else:
        sig = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), rec.truth.imu_noise).sigmas
    out = {}
    if "fx" in sig:
        out["focal"] = np.sqrt(0.5 * (sig["fx"] ** 2 + sig["fy"] ** 2))
        out["principal_point"] = np.sqrt(0.5 * (sig["cx"] ** 2 + sig["cy"] ** 2))
    if "rot_x" in sig:
        out["time_offset"] = 1e3 * sig["time_offset"]
    return out


@pytest.mark.parametrize("task", ["intrinsic", "extrinsic", "joint"])
def test_predicted_sigmas_are_the_calibrators_when_linearised_at_its_solution(recording, task):
    """Fed frame by frame, the tracker's prediction equals the calibrator's own 1-sigma (within 15 %)."""
    rec = recording
    truth = rec.truth
    tracker = InformationTracker(task, rec.target, Guess(truth.camera, truth.T_cam_imu, truth.time_offset,
                                                         truth.imu_noise, pixel_sigma=0.3))  # fmt: skip
    observations = collect_observations(rec.frames, rec.target)
    for k in range(0, len(observations), 10):  # ten frames per env step
        tracker.add_frames(observations[k : k + 10], rec.imu)
    predicted, reported = tracker.sigmas(), calibrator_sigmas(task, rec)
    for group, sigma in reported.items():
        assert predicted[group] == pytest.approx(sigma, rel=0.15), group
    assert set(predicted) == {"intrinsic": set(GROUPS[:3]), "extrinsic": set(GROUPS[3:]), "joint": set(GROUPS)}[task]


@pytest.mark.parametrize("task", ["extrinsic", "joint"])
def test_predicted_axis_sigmas_are_the_calibrators_per_axis(recording, task):
    """The extrinsic's 1-sigma along each camera axis (the state's axis_uncertainty) against the calibrator's rot_x ..
    trans_z (within 15 %); the largest of each is at most the group's (its worst direction)."""
    rec, truth = recording, recording.truth
    tracker = InformationTracker(task, rec.target, Guess(truth.camera, truth.T_cam_imu, truth.time_offset,
                                                         truth.imu_noise, pixel_sigma=0.3))  # fmt: skip
    observations = collect_observations(rec.frames, rec.target)
    for k in range(0, len(observations), 10):
        tracker.add_frames(observations[k : k + 10], rec.imu)
    if task == "extrinsic":
        sig = calibrate_extrinsics(rec.frames, rec.imu, rec.target, truth.camera, truth.imu_noise).sigmas
    else:
        sig = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), truth.imu_noise).sigmas
    reported = [np.degrees(sig[f"rot_{a}"]) for a in "xyz"] + [1e3 * sig[f"t_{a}"] for a in "xyz"]
    np.testing.assert_allclose(tracker.axis_sigmas(), reported, rtol=0.15)
    groups = tracker.sigmas()
    assert tracker.axis_sigmas()[:3].max() <= groups["rotation"] * (1 + 1e-9)
    assert tracker.axis_sigmas()[3:].max() <= groups["translation"] * (1 + 1e-9)
    assert InformationTracker("intrinsic", rec.target, Guess(truth.camera, truth.T_cam_imu, 0.0, truth.imu_noise)
                              ).axis_sigmas() is None  # fmt: skip


def test_a_declared_imu_grade_adds_what_the_calibrator_counts_for_it_where_the_data_show_nothing(recording):
    """The grade's terms as considered columns: the prediction grows by the calibrator's own ``S Sigma_g S^T`` (its
    unmodelled_imu effects at the grade's 1-sigma), within 15 % per axis; a ``calibrated`` grade adds nothing."""
    rec, truth = recording, recording.truth
    observations = collect_observations(rec.frames, rec.target)

    def predicted(grade):
        tracker = InformationTracker("extrinsic", rec.target, Guess(truth.camera, truth.T_cam_imu, truth.time_offset,
                                                                    truth.imu_noise, 0.3, imu_grade=grade))  # fmt: skip
        for k in range(0, len(observations), 10):
            tracker.add_frames(observations[k : k + 10], rec.imu)
        names, cov = tracker.covariance()
        at = [i for i, name in enumerate(names) if name == "E"]
        return cov[np.ix_(at, at)]

    grade = GRADES["consumer"]
    result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, truth.camera, truth.imu_noise,
                                  options=ViOptions(imu_grade=grade))  # fmt: skip
    at = [result.parameter_names.index(n) for n in ("rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z")]
    sensors = {"gyro": GYRO, "accelerometer": ACCEL}
    counted = sum(t.effect[at] @ sensors[t.sensor].prior(grade) @ t.effect[at].T for t in result.unmodelled_imu)
    added = predicted(grade) - predicted(None)
    np.testing.assert_allclose(np.sqrt(np.diag(added)), np.sqrt(np.diag(counted)), rtol=0.15)
    np.testing.assert_array_equal(predicted(GRADES["calibrated"]), predicted(None))


def test_more_data_never_increases_the_predicted_sigma(recording):
    rec = recording
    guess = Guess(rec.truth.camera, rec.truth.T_cam_imu, 0.0, rec.truth.imu_noise, pixel_sigma=0.3)
    tracker = InformationTracker("joint", rec.target, guess)
    observations = collect_observations(rec.frames, rec.target)
    before = tracker.sigmas()  # the priors only: finite
    assert all(np.isfinite(v) and v > 0 for v in before.values())
    for k in range(0, len(observations), 15):
        tracker.add_frames(observations[k : k + 15], rec.imu)
        after = tracker.sigmas()
        assert all(after[g] <= before[g] * (1 + 1e-9) for g in after)
        before = after
    assert after["rotation"] < 0.05 and after["time_offset"] < 0.1  # [deg], [ms]: determined by 12 s of motion


def test_one_frame_alone_predicts_from_its_view_and_the_priors(recording):
    """The first inertial state's velocity has no factor until the next frame's IMU links it: a step that adds one
    frame alone predicts without it (it knows nothing and shares nothing), the same as before the frame's IMU
    state existed, and no smaller than after the second frame."""
    rec = recording
    guess = Guess(rec.truth.camera, rec.truth.T_cam_imu, 0.0, rec.truth.imu_noise, pixel_sigma=0.3)
    tracker = InformationTracker("joint", rec.target, guess)
    observations = collect_observations(rec.frames, rec.target)
    tracker.add_frames(observations[5:6], rec.imu)
    one = tracker.sigmas()
    assert all(np.isfinite(v) and v > 0 for v in one.values())
    tracker.add_frames(observations[6:7], rec.imu)
    two = tracker.sigmas()
    assert all(two[g] <= one[g] * (1 + 1e-6) for g in one) and two["focal"] < one["focal"]


def test_features_and_excess():
    ratios = {"focal": 100.0, "principal_point": 1.0, "rotation": 0.01}
    f = features(ratios)
    assert f.shape == (len(GROUPS),)
    assert f[GROUPS.index("focal")] == pytest.approx(1.0) and f[GROUPS.index("principal_point")] == pytest.approx(0.5)
    assert f[GROUPS.index("rotation")] == pytest.approx(0.0) and f[GROUPS.index("time_offset")] == 0.0
    assert excess(ratios) == pytest.approx(np.log(100.0))
    assert excess(ratios, cap=10.0) == pytest.approx(np.log(10.0))  # the reward's: the priors pay nothing
    # a floor of 0.25 pays shrinking every group to a quarter of its tolerance: focal 100 -> 0.25 (ln 400),
    # principal point 1 -> 0.25 (ln 4), rotation already below (0)
    assert excess(ratios, floor=0.25) == pytest.approx(np.log(400.0) + np.log(4.0))
    # an outside weight of 3 counts focal's e-folds above its tolerance (ln 100) three times, those below
    # it (ln 4) and the principal point's (ln 4, all below) once
    assert excess(ratios, floor=0.25, outside_weight=3.0) == pytest.approx(3 * np.log(100.0) + 2 * np.log(4.0))
    assert excess(ratios, cap=10.0, outside_weight=3.0) == pytest.approx(3 * np.log(10.0))
    assert quantile_factor("time_offset", 0.9) == pytest.approx(1.6449, abs=1e-4)  # one dimension: the normal's
    assert quantile_factor("rotation", 0.9) == pytest.approx(2.5003, abs=1e-4)  # three: sqrt(chi2_3(0.9))


def information_env(task: str = "joint", *overrides: str) -> CalibrationEnv:
    return make_env(composed("train", ["env=information", f"task={task}", *overrides])["env"])


def test_information_mdp_rewards_shrinking_uncertainty_and_stops_when_good_enough():
    env = information_env("joint", "env.max_steps=40")
    try:
        obs, info = env.reset(seed=5)
        assert obs.shape == (INFORMATION_SIZE,) and env.observation_space.contains(obs)
        start = info["information/excess"]
        assert start > 5  # the priors are far from the tolerances
        rng = np.random.default_rng(0)
        total = {"information": 0.0, "path": 0.0, "time": 0.0}
        for _ in range(40):
            obs, reward, terminated, truncated, info = env.step(
                rng.uniform(env.action_space.low, env.action_space.high)
            )
            for term in total:
                total[term] += info[f"reward/{term}"]
            assert reward == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward/")))
            if terminated or truncated:
                break
        assert terminated and info["reward/terminal"] == 100.0  # random motion gets there within 40 steps
        assert info["information/excess"] == 0.0 and all(info[f"information/{g}_ratio"] <= 1 for g in GROUPS)
        assert total["information"] == pytest.approx(40.0 * start)  # every e-fold paid once
        assert total["path"] < 0 and total["time"] < 0
        assert "calib/error_pct" not in info  # the information MDP needs no solve
        assert info["discount"] == 1.0  # no path discount unless asked for
        figure = env.trajectory_figure(np.stack([obs, obs]), np.zeros((1, 6)))  # TensorBoard's episode image
        assert len(figure.axes) == 2 and len(figure.axes[0].lines) == len(GROUPS) + 1  # groups and tolerance
    finally:
        env.close()


def test_sensor_features_are_the_declared_board_lens_and_imu():
    paper_imu, wide = ImuNoise(), CameraModel.from_hfov(1.6, distortion="ds", dist=np.array([-0.2, 0.6]))
    guess = Guess(CameraModel.from_hfov(1.0), np.eye(4), 0.0, paper_imu)
    # Kalibr's 6 x 6 aprilgrid of 88 mm tags: 6 tags and 5 gaps of 0.3 tags, 0.66 m a side; a pinhole of 1 rad
    np.testing.assert_allclose(
        sensor_features(Target.aprilgrid(), guess),
        [0.0, 6 * 0.088 + 5 * 0.3 * 0.088, 1.0 / np.pi, 0.0, 0.5, 0.5],
        atol=1e-6,
    )
    # a checkerboard of 6 x 7 inner corners 5 cm apart (its larger side 6 gaps: 0.3 m), the wide-angle lens's rays of
    # its image edges 1.6 rad apart, an IMU 10x noisier in acceleration and 100x in rotation rate
    noisy = dataclasses.replace(
        paper_imu, accel_noise_density=10 * paper_imu.accel_noise_density,
        gyro_noise_density=100 * paper_imu.gyro_noise_density,
    )  # fmt: skip
    features = sensor_features(Target.checkerboard(6, 7, 0.05), Guess(wide, np.eye(4), 0.0, noisy))
    np.testing.assert_allclose(features, [1.0, 0.3, 1.6 / np.pi, 1.0, 0.5 + 1 / 4, 0.5 + 2 / 4], atol=1e-6)


def test_the_sensor_context_extends_the_state_with_each_episodes_declared_sensor():
    practitioner = ("joint", "sensor=practitioner", "task.camera_model=sensor", "env.max_steps=3")
    plain = information_env(*practitioner)
    context = information_env(*practitioner, "env.information.sensor_context=true")
    try:
        assert context.observation_space.shape == (INFORMATION_SIZE + SENSOR_SIZE,)
        kinds = set()
        for seed in (40000, 40003):  # an aprilgrid with a pinhole, a checkerboard with a wide-angle lens
            obs, _ = context.reset(seed=seed)
            plain_obs, _ = plain.reset(seed=seed)
            datasheet = context.product.datasheet
            expected = sensor_features(context.target, Guess(datasheet.camera, np.eye(4), 0.0, datasheet.imu_noise))
            np.testing.assert_array_equal(obs[INFORMATION_SIZE:], expected.astype(np.float32))
            np.testing.assert_array_equal(obs[:INFORMATION_SIZE], plain_obs)  # the same state, the context after it
            action = np.full(6, 0.02, dtype=np.float32)
            obs, *_ = context.step(action)
            plain_obs, *_ = plain.step(action)
            np.testing.assert_array_equal(obs[INFORMATION_SIZE:], expected.astype(np.float32))  # fixed per episode
            np.testing.assert_array_equal(obs[:INFORMATION_SIZE], plain_obs)
            kinds.add((context.target.kind, datasheet.camera.distortion))
        assert kinds == {("aprilgrid", "radtan"), ("checkerboard", "ds")}
    finally:
        plain.close()
        context.close()


def test_the_axis_uncertainty_extends_the_state_with_the_extrinsics_axes_and_their_prediction():
    env = information_env("joint", "env.information.axis_uncertainty=true", "env.max_steps=3")
    try:
        assert env.observation_space.shape == (INFORMATION_SIZE + AXIS_SIZE,)
        obs, _ = env.reset(seed=3)
        for _ in range(2):
            obs, *_ = env.step(np.full(6, 0.05, dtype=np.float32))
            tracker = env.state.information
            s = env.config.information
            ratios = axis_ratios(tracker.axis_sigmas(), "joint", s.tolerances, s.confidence)
            np.testing.assert_allclose(obs[INFORMATION_SIZE:], 0.5 + np.log10(ratios) / 4, atol=1e-6)
            rotation, translation = (GROUPS.index(g) for g in ("rotation", "translation"))
            assert obs[INFORMATION_SIZE : INFORMATION_SIZE + 3].max() <= obs[rotation] + 1e-6  # the worst axis at most
            assert obs[INFORMATION_SIZE + 3 :].max() <= obs[translation] + 1e-6
        # a prediction carries the axes its step would leave, in the same units
        prediction = Lookahead(env.state, env.frame, env.pose_offset, env.config, env.step_timing).predict(np.zeros(6))
        assert prediction.axes.shape == (AXIS_SIZE,) and np.all((prediction.axes > 0) & (prediction.axes < 1))
    finally:
        env.close()
    intrinsic = information_env("intrinsic", "env.information.axis_uncertainty=true")
    try:
        obs, _ = intrinsic.reset(seed=3)
        np.testing.assert_array_equal(obs[INFORMATION_SIZE:], np.zeros(AXIS_SIZE))  # no extrinsic: 0, as its groups
    finally:
        intrinsic.close()


def test_a_floor_pays_groups_below_tolerance_and_a_path_discount_is_reported_per_step():
    env = information_env(
        "joint",
        "env.information.excess_floor=0.5",
        "env.information.outside_weight=2",
        "env.reward.path_discount=0.25",
    )
    try:
        _, info = env.reset(seed=5)
        start, ratios = info["information/excess"], {g: info[f"information/{g}_ratio"] for g in GROUPS}
        # e-folds from a ratio of 0.5 up to 1 count once, from 1 up to the cap of 10 twice
        inside = sum(np.log(min(max(r, 0.5), 1.0) / 0.5) for r in ratios.values())
        outside = sum(np.log(min(max(r, 1.0), 10.0)) for r in ratios.values())
        assert outside > 0.0 and start == pytest.approx(inside + 2.0 * outside)
        rng = np.random.default_rng(1)
        paid, discounts, paths = 0.0, [], []
        for _ in range(12):
            _, _, terminated, truncated, info = env.step(rng.uniform(env.action_space.low, env.action_space.high))
            paid += info["reward/information"]
            paths.append(-info["reward/path"] / 5.0)  # the information MDP's 5 per metre
            discounts.append(info["discount"])
            if terminated or truncated:
                break
        assert paid == pytest.approx(40.0 * (start - info["information/excess"]))
        assert info["information/excess"] >= 0.0
        np.testing.assert_allclose(discounts, 0.25 ** np.array(paths), rtol=1e-9)
        assert min(discounts) < 0.95  # the random steps moved
    finally:
        env.close()


def test_the_intrinsic_task_tracks_the_camera_only():
    env = information_env("intrinsic")
    try:
        obs, info = env.reset(seed=2)
        assert set(k.removeprefix("information/").removesuffix("_ratio") for k in info if "ratio" in k) == set(
            GROUPS[:3]
        )
        assert np.all(obs[3:6] == 0.0)  # rotation, translation, time offset: not the task's
    finally:
        env.close()


def test_a_declared_decentring_joins_the_joint_state_and_is_refused_where_no_intrinsics_are_estimated():
    """env.information.center_offset_std: the joint task's lens spread (the offset's, the sensor distribution's
    coefficients) keeps the intrinsic groups' prediction above the plain one after the same steps; the extrinsic
    task, which estimates no intrinsics, refuses it by key."""
    ratios = []
    for std in (0.0, 0.05):
        env = information_env("joint", f"env.information.center_offset_std={std}")
        try:
            env.reset(seed=2)
            for _ in range(6):
                *_, info = env.step(np.full(env.action_space.shape, 0.5, dtype=np.float32))
            spread = env.unwrapped.state.information.guess.lens_spread
            ratios.append({g: info[f"information/{g}_ratio"] for g in GROUPS})
        finally:
            env.close()
    assert spread is not None and spread.center_offset_px == pytest.approx([0.05 * 640, 0.05 * 480])
    assert spread.coefficient_std == pytest.approx([0.02, 0.02, 0.001, 0.001])  # conf/sensor/paper.yaml
    for group in ("focal", "principal_point"):
        assert ratios[1][group] > ratios[0][group]
    env = information_env("extrinsic", "env.information.center_offset_std=0.05")
    try:
        with pytest.raises(ConfigError, match=r"env\.information\.center_offset_std is 0\.05.*set it to 0"):
            env.reset(seed=2)
    finally:
        env.close()


def test_the_goal_can_be_the_scored_groups_and_the_declared_decentring_the_sensor_distributions():
    """goal_groups=scored: the joint task ends and is paid on rotation, translation and time offset only (its
    intrinsics stay in the state); center_offset_std=null: the task's own draw of decentred lenses, none in the
    intrinsic task, which draws none."""
    overrides = ("env.information.goal_groups=scored", "env.information.center_offset_std=null")
    env = information_env("joint", *overrides)
    try:
        obs, _ = env.reset(seed=2)
        state = env.unwrapped.state
        assert set(state.goal_ratios) == {"rotation", "translation", "time_offset"}
        assert np.all(obs[:6] > 0.0)  # every group is observed
        assert state.excess == pytest.approx(excess(state.goal_ratios, 10.0, 1.0, 1.0))
        assert state.goal_reached == all(state.ratios[g] <= 1.0 for g in state.goal_ratios)
        assert state.information.guess.lens_spread.center_offset_px == pytest.approx([32.0, 24.0])
    finally:
        env.close()
    env = information_env("intrinsic", *overrides)
    try:
        env.reset(seed=2)
        state = env.unwrapped.state
        assert state.information.guess.lens_spread is None
        assert set(state.goal_ratios) == set(GROUPS[:3])
    finally:
        env.close()


def test_a_task_mix_draws_each_episodes_task_by_its_seed():
    """``+experiment=train_information_policy``: joint and intrinsic episodes, the same task for the same seed."""
    env = make_env(composed("train", ["+experiment=train_information_policy"])["env"])
    single = information_env("joint")
    try:
        drawn = {}
        for seed in range(8):
            obs, info = env.reset(seed=seed)
            drawn[seed] = env.task.name
            tracked = {k.removeprefix("information/").removesuffix("_ratio") for k in info if "ratio" in k}
            assert tracked == (set(GROUPS) if env.task.name == "joint" else set(GROUPS[:3]))
            assert np.all(obs[3:6] > 0.0) == (env.task.name == "joint")  # the intrinsic task leaves them at 0
            assert env.recording().metadata["task"] == env.task.name
            if env.task.name == "joint":  # the task is drawn after the seeds: the sensor is the single task's
                single.reset(seed=seed)
                assert env.truth.camera == single.truth.camera
        assert set(drawn.values()) == {"joint", "intrinsic"}
        assert [(env.reset(seed=s), env.task.name)[1] for s in drawn] == list(drawn.values())
    finally:
        env.close()
        single.close()


def test_a_task_mix_that_is_not_a_mapping_of_tasks_is_refused_by_key():
    with pytest.raises(ConfigError, match=r"env\.task_mix must map task names"):
        information_env("joint", "+env.task_mix=[intrinsic]")
    with pytest.raises(ConfigError, match=r"task\.calibrate"):
        information_env("joint", "+env.task_mix={other: {name: other, calibrate: fisheye}}")


def test_a_final_step_limit_reports_a_zero_discount_on_its_step_only():
    env = information_env("joint", "env.max_steps=3", "env.step_limit_final=true", "env.reward.path_discount=0.25")
    try:
        env.reset(seed=5)
        rng = np.random.default_rng(1)
        steps = [env.step(rng.uniform(env.action_space.low, env.action_space.high)) for _ in range(3)]
        assert [(terminated, truncated) for _, _, terminated, truncated, _ in steps] == [(False, False)] * 2 + [
            (False, True)
        ]
        for _, _, _, _, info in steps[:2]:  # before the limit: the path's discount
            assert info["discount"] == pytest.approx(0.25 ** (-info["reward/path"] / 5.0)) and info["discount"] > 0
        assert steps[2][4]["discount"] == 0.0  # nothing past the limit is valued
    finally:
        env.close()
    with pytest.raises(ConfigError, match=r"env\.step_limit_final.*env\.state=information"):
        information_env("joint", "env.state=coverage", "env.step_limit_final=true")


@pytest.mark.parametrize(
    "override, key",
    [
        ("env.information.tolerances.focal_px=0", "env.information.tolerances.focal_px"),
        ("env.information.tolerances.time_offset_ms=-0.1", "env.information.tolerances.time_offset_ms"),
        ("env.information.confidence=1.0", "env.information.confidence"),
        ("env.information.excess_cap=1", "env.information.excess_cap"),
        ("env.information.excess_floor=0", "env.information.excess_floor"),
        ("env.information.excess_floor=1.5", "env.information.excess_floor"),
        ("env.information.outside_weight=0.5", "env.information.outside_weight"),
        ("env.information.center_offset_std=-0.01", "env.information.center_offset_std"),
        ("env.information.goal_groups=some", "env.information.goal_groups"),
        ("env.information.sensor_context=maybe", "env.information.sensor_context"),
        ("env.information.axis_uncertainty=1.5", "env.information.axis_uncertainty"),
        ("env.reward.path_discount=0", "env.reward.path_discount"),
        ("env.reward.path_discount=1.2", "env.reward.path_discount"),
        ("env.state=coverage_and_more", "env.state"),
    ],
)
def test_bad_information_settings_are_refused_by_key(override, key):
    # make_env raises the env's own ConfigError (not Hydra's wrapper of it): vical-train prints it as one line
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        information_env("joint", override)


def test_predicted_sigmas_of_a_double_sphere_camera_are_the_calibrators():
    """The tracker sizes its camera block by the model: a ds camera's 6 parameters, as the calibrator's 1-sigma."""
    camera = wide_angle_camera("ds", 180.0)
    frames, _ = scattered_views(camera, Target.checkerboard(), 30, pixel_sigma=0.3, seed=2)
    sig = calibrate_intrinsics(frames, Target.checkerboard(), "ds", (640, 480), pixel_sigma=0.3).sigmas
    guess = Guess(camera, np.eye(4), 0.0, ImuNoise(), pixel_sigma=0.3)
    tracker = InformationTracker("intrinsic", Target.checkerboard(), guess)
    no_imu = ImuSamples(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    tracker.add_frames(collect_observations(frames, Target.checkerboard()), no_imu)
    predicted = tracker.sigmas()
    assert len(tracker.covariance()[0]) == 6
    assert predicted["focal"] == pytest.approx(np.sqrt(0.5 * (sig["fx"] ** 2 + sig["fy"] ** 2)), rel=0.15)
    assert predicted["principal_point"] == pytest.approx(np.sqrt(0.5 * (sig["cx"] ** 2 + sig["cy"] ** 2)), rel=0.15)


@pytest.mark.integration
def test_honesty_script_runs_the_shipped_policy_to_its_stop_and_judges_it(tmp_path):
    """experiments/information_honesty.py with a learned policy: its own stop, the final errors within a few
    predicted sigma, and the stop judged by the evaluation's scored groups."""
    script = Path(__file__).resolve().parents[1] / "experiments" / "information_honesty.py"
    args = [sys.executable, str(script), "--sensors", "1", "--task", "intrinsic", "--policy", "learned"]
    out = subprocess.run(args, capture_output=True, text=True, check=True, cwd=tmp_path).stdout
    assert re.search(r"sensor 30000: stopped after \d+ steps", out)
    worst = [float(m) for m in re.findall(r"median \|z\| [\d.]+  max ([\d.]+)", out)]
    assert len(worst) == 4 and max(worst) < 4.0  # fx, fy, cx, cy
    assert re.search(r"tolerances met when stopped: [01] of 1 \(", out)
    # The paper's workspace ships a policy of the coverage state: refused in one line.
    coverage = subprocess.run([*args, "workspace=paper"], capture_output=True, text=True, cwd=tmp_path)
    assert coverage.returncode != 0 and "Traceback" not in coverage.stderr
    assert "was trained on the env's coverage state" in coverage.stderr
    unknown = subprocess.run([*args[:-1], "nonsense"], capture_output=True, text=True, cwd=tmp_path)
    assert unknown.returncode != 0 and unknown.stderr.strip().endswith("the choices are the files of conf/<group>/")
    assert "Could not find 'policy/nonsense'" in unknown.stderr and "Traceback" not in unknown.stderr


@pytest.mark.parametrize("model", ["radtan", "equidistant"])
def test_lens_misfit_columns_rebuild_any_decentred_lens_of_the_spread(model):
    """At each offset node, the columns combine linearly into the misfit of any lens of the spread: its projection
    with the distortion centre offset minus the centred projection (CameraModel's own), to 1e-9 px."""
    camera = CameraModel.from_hfov(1.0, 640, 480, np.array([-0.05, 0.01, 0.0, 0.0]), model)
    std = np.array([0.02, 0.02, 0.001, 0.0])  # the last coefficient has no spread: no column
    spread = LensSpread(np.array([30.0, 20.0]), std)
    rng = np.random.default_rng(4)
    points = np.c_[rng.uniform(-0.3, 0.3, (25, 2)), rng.uniform(0.4, 1.0, 25)]
    columns = lens_misfits(camera, points, spread)  # the guess's lens, then each coefficient with a spread
    assert columns.shape == (50, spread.columns(camera)) == (50, len(OFFSET_NODES) * 4)
    z = np.r_[rng.standard_normal(3), 0.0]
    lens = camera.with_intrinsics(camera.fx, camera.fy, camera.cx, camera.cy, camera.dist + std * z)
    nodes = len(OFFSET_NODES)
    for node, (offset, weight) in enumerate(zip(OFFSET_NODES * spread.center_offset_px, OFFSET_WEIGHTS, strict=True)):
        decentred = dataclasses.replace(lens, distortion_center_offset=offset)
        expected = (decentred.project(points)[0] - lens.project(points)[0]).reshape(-1)
        fields = columns[:, node::nodes] / np.sqrt(weight)  # field-major
        assert fields[:, 0] + fields[:, 1:] @ z[:3] == pytest.approx(expected, abs=1e-9)
    assert np.abs(expected).max() > 0.1  # [px] a misfit that matters


def test_a_declared_lens_spread_predicts_the_bias_that_solves_of_decentred_lenses_show():
    """The considered part of the prediction (with the spread minus without) equals the second moment of the biases
    OpenCV's calibration leaves when the lens is decentred to each offset node (noise-free views), within 10 %."""
    target = Target.checkerboard()
    lens = CameraModel.from_hfov(1.0, 640, 480, np.array([0.03, -0.02, 0.002, 0.001]), "radtan")
    spread = LensSpread(np.array([30.0, 20.0]), np.zeros(4))
    frames, poses = scattered_views(lens, target, 20, seed=2)
    observations = collect_observations(frames, target)
    no_imu = ImuSamples(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    predicted = []
    for lens_spread in (spread, None):
        tracker = InformationTracker("intrinsic", target, Guess(lens, np.eye(4), 0.0, ImuNoise(), 0.3, lens_spread))
        tracker.add_frames(observations, no_imu)
        predicted.append(tracker.covariance()[1][:4, :4])
    second_moment = np.zeros((4, 4))
    for offset, weight in zip(OFFSET_NODES * spread.center_offset_px, OFFSET_WEIGHTS, strict=True):
        bias = (
            opencv_intrinsics(dataclasses.replace(lens, distortion_center_offset=offset), target, poses)
            - lens.intrinsics
        )
        second_moment += weight * np.outer(bias, bias)
    considered = np.sqrt(np.diag(predicted[0] - predicted[1]))
    assert considered == pytest.approx(np.sqrt(np.diag(second_moment)), rel=0.1)
    assert considered.min() > 0.1  # [px] a bias as large as the noise's 1-sigma: it matters
    with pytest.raises(ValueError, match="one per radtan coefficient"):
        InformationTracker(
            "intrinsic", target, Guess(lens, np.eye(4), 0.0, ImuNoise(), 0.3, LensSpread([30, 20], [0.1]))
        )
    with pytest.raises(ValueError, match="extrinsic task takes the intrinsics as given"):
        InformationTracker("extrinsic", target, Guess(lens, np.eye(4), 0.0, ImuNoise(), 0.3, spread))


def opencv_intrinsics(camera: CameraModel, target: Target, poses: list[np.ndarray]) -> np.ndarray:
    """``[fx, fy, cx, cy]`` OpenCV's radtan calibration finds from ``camera``'s noise-free views at ``poses``."""
    images = [camera.project(target.points @ T[:3, :3].T + T[:3, 3])[0].astype(np.float32) for T in poses]
    start = np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1.0]])
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    _, K, *_ = cv2.calibrateCamera([target.points.astype(np.float32)] * len(poses), images, (640, 480), start,
                                   np.r_[camera.dist, 0.0], flags=flags, criteria=criteria)  # fmt: skip
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
