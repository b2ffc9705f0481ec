"""IMU intrinsics (scale, misalignment, g-sensitivity): the model, their recovery in the camera-IMU graphs within
the reported 3 sigma, the hint when the motion leaves them weak, and the refusal when it cannot excite them."""

import numpy as np
import pytest

from vical.calib import ViOptions, calibrate_extrinsics, calibrate_joint
from vical.calib.errors import CalibrationSettingError
from vical.calib.synthetic import Excitation, make_recording
from vical.data import ImuIntrinsics, ImuNoise

NAMES = ImuIntrinsics.parameter_names()
SCALES = [n for n in NAMES if "_scale_" in n]
ANGLES = [n for n in NAMES if "_scale_" not in n]
ESTIMATE = ViOptions(imu_model="scale-misalignment")


def sensor_intrinsics(seed: int = 3) -> ImuIntrinsics:
    """Scales within +-1 %, misalignments and the gyro's rotation within +-0.5 deg."""
    rng = np.random.default_rng(seed)
    scales = rng.uniform(-0.01, 0.01, 3), rng.uniform(-0.01, 0.01, 3)
    angles = rng.uniform(-1, 1, (3, 3)) * np.radians(0.5)
    return ImuIntrinsics.from_vector(np.concatenate([scales[0], angles[0], scales[1], angles[1], angles[2]]))


def test_the_model_inverts_and_its_parameters_round_trip():
    rng = np.random.default_rng(0)
    theta = rng.normal(0.0, 0.01, 24)
    intrinsics = ImuIntrinsics.from_vector(theta)
    np.testing.assert_allclose(intrinsics.vector(g_sensitivity=True), theta, atol=1e-15)
    gyro, accel = rng.normal(size=(50, 3)), rng.normal(size=(50, 3)) * 9.81
    measured_gyro, measured_accel = intrinsics.distort(gyro, accel)
    np.testing.assert_allclose(measured_accel, accel @ intrinsics.M_accel.T)  # Kalibr's a = M_a a_i
    expected = (intrinsics.M_gyro @ intrinsics.C_gyro_i @ gyro.T + intrinsics.A_gyro @ intrinsics.C_gyro_i @ accel.T).T
    np.testing.assert_allclose(measured_gyro, expected)  # Kalibr's w = M_g C w_i + A C a_i
    back = intrinsics.correct(measured_gyro, measured_accel)
    np.testing.assert_allclose(back[0], gyro, atol=1e-12)
    np.testing.assert_allclose(back[1], accel, atol=1e-12)
    assert ImuIntrinsics().is_identity() and not intrinsics.is_identity()
    np.testing.assert_allclose(ImuIntrinsics.from_dict(intrinsics.to_dict()).vector(True), theta, atol=1e-15)
    with pytest.raises(ValueError, match="M_accel must be lower triangular"):
        ImuIntrinsics(M_accel=np.array([[1.0, 0.01, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))


@pytest.fixture(scope="module")
def recording():
    """20 s of the synthetic motion with a miscalibrated IMU, noisy IMU and corners."""
    return make_recording(
        duration=20, imu_noise=ImuNoise(), pixel_sigma=0.2, seed=1, imu_intrinsics=sensor_intrinsics()
    )


def assert_recovered(result, truth: ImuIntrinsics) -> None:
    """Every intrinsic parameter within 3 sigma of the truth, the sigmas small enough to mean something."""
    estimate, covariance = result.block(NAMES)
    sigma = np.sqrt(np.diag(covariance))
    error = estimate - truth.vector()
    assert np.all(np.abs(error) < 3 * sigma), dict(zip(NAMES, np.round(error / sigma, 2), strict=True))
    scale = np.array([n in SCALES for n in NAMES])
    assert np.all(sigma[scale] < 0.002)  # 0.2 %: a 1 % scale error is 5 sigma
    assert np.all(sigma[~scale] < np.radians(0.1))  # a 0.5 deg misalignment is 5 sigma
    recovered = result.imu_intrinsics
    np.testing.assert_allclose(recovered.M_accel, truth.M_accel, atol=0.002)
    np.testing.assert_allclose(recovered.M_gyro @ recovered.C_gyro_i, truth.M_gyro @ truth.C_gyro_i, atol=0.002)


def test_scale_and_misalignment_are_recovered_with_the_extrinsic(recording):
    truth = recording.truth
    result = calibrate_extrinsics(
        recording.frames, recording.imu, recording.target, truth.camera, truth.imu_noise, options=ESTIMATE
    )
    assert_recovered(result, truth.imu_intrinsics)
    assert result.parameter_names[-15:] == NAMES
    rotation_error = np.degrees(np.linalg.norm(_rotation_vector(result.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T)))
    assert rotation_error < 0.1
    # The same data calibrated as if the IMU were exact: the extrinsic rotation absorbs the misalignment.
    exact = calibrate_extrinsics(recording.frames, recording.imu, recording.target, truth.camera, truth.imu_noise)
    unmodelled = np.degrees(np.linalg.norm(_rotation_vector(exact.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T)))
    assert unmodelled > 2 * rotation_error


def test_scale_and_misalignment_are_recovered_in_the_joint_graph(recording):
    truth = recording.truth
    result = calibrate_joint(
        recording.frames, recording.imu, recording.target, "radtan", (640, 480), truth.imu_noise, options=ESTIMATE
    )
    assert_recovered(result, truth.imu_intrinsics)
    assert result.parameter_names[:4] == ["fx", "fy", "cx", "cy"]


def test_the_gyros_g_sensitivity_is_recovered_when_asked_for():
    base = sensor_intrinsics()
    A = np.random.default_rng(0).normal(0.0, 1e-3, (3, 3))  # [(rad/s)/(m/s^2)], ~0.6 deg/s per g
    truth = ImuIntrinsics(base.M_accel, base.M_gyro, base.C_gyro_i, A)
    rec = make_recording(duration=20, imu_noise=ImuNoise(), pixel_sigma=0.2, seed=1, imu_intrinsics=truth)
    options = ViOptions(imu_model="scale-misalignment", g_sensitivity=True)
    result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, ImuNoise(), options=options)
    names = ImuIntrinsics.parameter_names(g_sensitivity=True)
    estimate, covariance = result.block(names)
    sigma = np.sqrt(np.diag(covariance))
    assert np.all(np.abs(estimate - truth.vector(g_sensitivity=True)) < 3 * sigma)
    assert np.all(sigma[15:] < 3e-4)  # a third of the simulated entries' spread
    np.testing.assert_allclose(result.imu_intrinsics.A_gyro, A, atol=5e-4)


def test_known_intrinsics_correct_the_readings_when_not_estimated(recording):
    truth = recording.truth
    known = ViOptions(imu_intrinsics=truth.imu_intrinsics)
    result = calibrate_extrinsics(
        recording.frames, recording.imu, recording.target, truth.camera, truth.imu_noise, options=known
    )
    error = np.degrees(np.linalg.norm(_rotation_vector(result.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T)))
    assert error < 0.1 and result.imu_intrinsics is truth.imu_intrinsics
    assert not any(n in result.parameter_names for n in NAMES)


def test_a_short_motion_names_the_weak_intrinsics_with_a_hint():
    short = make_recording(duration=6, imu_noise=ImuNoise(), pixel_sigma=0.2, seed=2)
    result = calibrate_extrinsics(short.frames, short.imu, short.target, short.truth.camera, options=ESTIMATE)
    weak = {w.name: w for w in result.weak_parameters}
    intrinsics = [n for n in weak if n in NAMES]
    assert intrinsics, [w.name for w in result.weak_parameters]
    for name in intrinsics:
        assert weak[name].sigma > weak[name].threshold
        assert "IMU" in weak[name].hint


def test_too_little_motion_is_refused_naming_the_option():
    no_yaw = Excitation(angle_amplitudes=np.array([[0.35, 0.10], [0.40, 0.10], [0.0, 0.0]]))
    rec = make_recording(duration=10, excitation=no_yaw)
    with pytest.raises(CalibrationSettingError, match="too little motion to estimate the IMU intrinsics") as refused:
        calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, options=ESTIMATE)
    message = str(refused.value)
    assert "the gyro's y axis turns at 0.17 rad/s RMS" in message and "imu_model='calibrated'" in message
    assert refused.value.spelled("--imu-model calibrated").endswith("or leave --imu-model calibrated")


def test_g_sensitivity_needs_the_scale_misalignment_model():
    with pytest.raises(ValueError, match="g_sensitivity needs imu_model 'scale-misalignment'"):
        ViOptions(g_sensitivity=True)
    with pytest.raises(ValueError, match="imu_model must be one of"):
        ViOptions(imu_model="scale-misalignment-size-effect")


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    return axis if angle < 1e-12 else axis * angle / np.sin(angle)
