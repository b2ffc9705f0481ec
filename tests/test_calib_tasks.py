"""Calibration tasks: the solve each runs and the score it reports, on synthetic recordings."""

import re
from dataclasses import replace

import numpy as np
import pytest

from vical.calib.metrics import extrinsic_relative_error, intrinsic_relative_error
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.visual_inertial import ViOptions
from vical.calib.synthetic import make_recording
from vical.calib.tasks import CalibrationTask, calibrate_task, run_task
from vical.config_checks import ConfigError
from vical.data import ImuNoise, SensorTruth
from vical.data.imu_grade import GRADES


@pytest.fixture(scope="module")
def recording():
    rec = make_recording(duration=8.0, imu_noise=ImuNoise(), pixel_sigma=0.2, seed=1)
    assert rec.truth is not None
    return rec


def test_intrinsic_task_is_the_intrinsic_solve_scored_by_the_intrinsic_error(recording):
    task = CalibrationTask(name="intrinsic", calibrate="intrinsic", error_metric="intrinsic_relative")
    outcome = run_task(task, recording)
    direct = calibrate_intrinsics(recording.frames, recording.target, "radtan", (640, 480))
    np.testing.assert_allclose(outcome.result.camera.intrinsics, direct.camera.intrinsics)
    assert outcome.score == pytest.approx(intrinsic_relative_error(direct.camera, recording.truth.camera))
    assert 0 < outcome.score < 0.5
    assert outcome.result.T_cam_imu is None


def test_extrinsic_task_uses_the_true_intrinsics_and_scores_the_extrinsic(recording):
    task = CalibrationTask(name="extrinsic", calibrate="extrinsic")
    outcome = run_task(task, recording)
    assert outcome.result.camera == recording.truth.camera
    expected = extrinsic_relative_error(outcome.result.T_cam_imu, recording.truth.T_cam_imu)
    assert outcome.score == pytest.approx(expected)
    assert outcome.score < 1.0
    assert outcome.errors.time_offset_ms is not None


def test_time_offset_follows_the_task(recording):
    fixed = calibrate_task(CalibrationTask(calibrate="extrinsic", estimate_time_offset=False), recording)
    estimated = calibrate_task(CalibrationTask(calibrate="extrinsic", estimate_time_offset=True), recording)
    assert fixed.time_offset == 0.0  # stays at the initial value
    assert estimated.time_offset != 0.0  # noisy data: the estimate moves off the exact truth 0


def test_the_sensors_declared_imu_grade_enters_the_sigmas_as_a_calibrate_grade_would(recording):
    task = CalibrationTask(calibrate="extrinsic")
    perfect = calibrate_task(task, recording)  # make_recording's IMU is perfect and declares so
    consumer = replace(recording, truth=replace(recording.truth, imu_grade=GRADES["consumer"]))
    declared = calibrate_task(task, consumer)
    np.testing.assert_allclose(declared.covariance, calibrate_task(task, recording, options=ViOptions(
        imu_grade=GRADES["consumer"])).covariance)  # fmt: skip
    assert declared.sigma("rot_x") > perfect.sigma("rot_x")
    assert not any(np.any(t.covariance()) for t in perfect.unmodelled_imu)


def test_a_joint_result_says_its_rotation_is_relative_to_its_principal_point_and_how_to_pair_other_intrinsics(
    recording,
):
    """The note's numbers: 1 px of principal point turns the frame by about 1 / f rad, and rho is the covariance's."""
    result = calibrate_task(CalibrationTask(calibrate="joint"), recording)
    [note] = [w for w in result.warnings if "relative to this calibration's principal point" in w]
    turn = re.search(r"cx by 1 px turns it (\S+) deg about y, cy by 1 px (\S+) deg about x", note)
    assert float(turn[1]) == pytest.approx(np.degrees(1 / result.camera.fx), abs=6e-4)
    assert float(turn[2]) == pytest.approx(np.degrees(1 / result.camera.fy), abs=6e-4)
    at = {n: i for i, n in enumerate(result.parameter_names)}
    C = result.covariance
    rho = C[at["cx"], at["rot_y"]] / np.sqrt(C[at["cx"], at["cx"]] * C[at["rot_y"], at["rot_y"]])
    assert f"rho = {rho:+.2f}" in note
    assert "--task extrinsic --intrinsics <camchain.yaml>, or --task two_stage" in note
    extrinsic = calibrate_task(CalibrationTask(calibrate="extrinsic"), recording)
    assert not any("principal point" in w for w in extrinsic.warnings)  # given intrinsics: nothing to pair


def test_two_stage_takes_the_intrinsics_from_the_given_frames(recording):
    other = make_recording(duration=6.0, imu_noise=ImuNoise(), pixel_sigma=0.2, seed=2)
    task = CalibrationTask(calibrate="two_stage")
    result = calibrate_task(task, recording, intrinsic_frames=other.frames)
    first_stage = calibrate_intrinsics(other.frames, other.target, "radtan", (640, 480))
    np.testing.assert_allclose(result.camera.intrinsics, first_stage.camera.intrinsics)


def test_bad_task_settings_are_refused_by_name():
    with pytest.raises(ConfigError, match=r"task\.calibrate must be one of"):
        CalibrationTask(calibrate="everything")
    with pytest.raises(ConfigError, match="needs a camera-IMU solve"):
        CalibrationTask(calibrate="intrinsic", error_metric="extrinsic_relative")
    with pytest.raises(ConfigError, match="unknown setting"):
        CalibrationTask.from_config({"name": "x", "metric": "intrinsic_relative"})
    with pytest.raises(
        ConfigError,
        match=r"task\.camera_model must be one of \['radtan', 'equidistant', 'ds', 'eucm', 'omni', 'omni-radtan', "
        r"'sensor'\]",
    ):
        CalibrationTask(camera_model="kb4")
    assert CalibrationTask(camera_model="ds").camera_model == "ds"


def test_scoring_needs_the_truth(recording):
    with pytest.raises(ConfigError, match="sensor truth"):
        run_task(
            CalibrationTask(calibrate="intrinsic", error_metric="intrinsic_relative"), replace(recording, truth=None)
        )
    assert isinstance(recording.truth, SensorTruth)
