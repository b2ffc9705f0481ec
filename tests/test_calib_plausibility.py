"""vical.calib.solve.plausibility: what gives away a result the data do not support, and a gyro unit error."""

from dataclasses import replace

import numpy as np
import pytest

from vical.calib import calibrate_joint, nominal_T_cam_imu
from vical.calib.result import FramePoses, ResidualStats
from vical.calib.solve.plausibility import (
    accel_scale,
    board_scale,
    gyro_scale,
    implausibilities,
    likely_accel_unit,
    likely_gyro_unit,
    posed_frames,
    wrong_board_scale,
)
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise, ImuSamples, Target
from vical.geometry import make_transform, so3_exp, so3_log


@pytest.fixture(scope="module")
def calibrated():
    rec = make_recording(duration=6.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=8)
    result = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), rec.truth.imu_noise)
    return rec, result


def test_a_sound_result_has_nothing_against_it_and_each_sign_of_failure_is_named(calibrated):
    result = calibrated[1]
    guess = make_transform(np.eye(3), [0.05, 0.05, -0.05])
    assert implausibilities(result, guess) == []
    assert implausibilities(replace(result, iterations=0), guess) == [
        "the solve made no step from its initial guess (0 iterations)"
    ]
    stuck = result.T_cam_imu.copy()
    stuck[:3, 3] = guess[:3, 3]
    assert implausibilities(replace(result, T_cam_imu=stuck), guess) == [
        "the camera-IMU translation is exactly its initial guess"
    ]
    assert implausibilities(replace(result, status="max_iterations", iterations=50), guess) == [
        "the solve did not converge in 50 iterations (the views constrain the parameters too weakly: add views tilted "
        "30-60 deg, near the image's corners, at several distances)"
    ]
    outside = replace(result, camera=replace(result.camera, cx=833.0, cy=721.0))
    assert implausibilities(outside, guess) == [
        "the principal point (833.0, 721.0) px lies outside the 640 x 480 image"
    ]
    # IMU residuals 10x the declared noise are what real IMUs show: no evidence of a wrong setting.
    assert implausibilities(replace(result, imu_noise_scale=10.0), guess) == []
    blurred = replace(result, reprojection=ResidualStats(5.0, 5.0, 1.0, 5.5, 9.0, 100))
    assert implausibilities(blurred, guess) == ["the reprojection rms 5.5 px is 5.5x the assumed corner noise 1 px"]
    assert implausibilities(result, guess, pixel_sigma=0.05)[0].endswith("x the declared corner noise 0.05 px")
    # The truth is the nominal rig here, yet the solve moves (noisy data): it is not taken for a stuck one.
    assert implausibilities(result, nominal_T_cam_imu()) == []


def test_a_gyro_unit_error_shows_as_57_times_the_cameras_rotation(calibrated):
    rec = calibrated[0]
    posed = posed_frames(rec.frames, rec.target, rec.truth.camera)
    in_rad = gyro_scale(posed, rec.imu)
    in_deg = ImuSamples(rec.imu.t, np.degrees(rec.imu.gyro), rec.imu.accel)
    as_deg = gyro_scale(posed, in_deg)
    assert in_rad == pytest.approx(1.0, abs=0.03) and as_deg == pytest.approx(180 / np.pi, rel=0.03)
    assert likely_gyro_unit(in_rad, "rad/s") is None and likely_gyro_unit(as_deg, "rad/s") == "deg/s"
    assert likely_gyro_unit(in_rad * np.pi / 180, "deg/s") == "rad/s" and likely_gyro_unit(None, "rad/s") is None


def test_an_accelerometer_in_g_reads_gravity_as_one(calibrated):
    rec = calibrated[0]
    in_ms2 = accel_scale(rec.imu)
    as_g = accel_scale(ImuSamples(rec.imu.t, rec.imu.gyro, rec.imu.accel / 9.81))
    assert in_ms2 == pytest.approx(1.0, abs=0.05) and as_g == pytest.approx(1 / 9.81, rel=0.05)
    assert likely_accel_unit(in_ms2, "m/s^2") is None and likely_accel_unit(as_g, "m/s^2") == "g"
    assert likely_accel_unit(in_ms2 * 9.81, "g") == "m/s^2" and likely_accel_unit(as_g * 9.81, "g") is None
    assert accel_scale(ImuSamples(rec.imu.t[:0], rec.imu.gyro[:0], rec.imu.accel[:0])) is None


@pytest.fixture(scope="module")
def ten_seconds():
    return make_recording(duration=10.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=8)


@pytest.mark.parametrize("declared_over_true", [1.0, 1.1, 0.7, 1.6, 0.5])
def test_the_boards_scale_is_the_cameras_accelerations_over_the_imus(ten_seconds, declared_over_true):
    """A board declared k times its true size makes every camera position, and acceleration, k times too large."""
    rec = ten_seconds
    true = rec.target
    declared = Target.checkerboard(true.rows, true.cols, true.row_spacing * declared_over_true)
    truth = rec.truth
    posed = posed_frames(rec.frames, declared, truth.camera)
    found = board_scale(posed, rec.imu, truth.T_cam_imu[:3, :3], truth.time_offset)
    # the camera centre's ratio carries the 12 cm lever arm's share (+7 %); fitted, the lever arm takes it out
    assert found.centre[0] == pytest.approx(1.07 * declared_over_true, rel=0.03)
    assert found.lever_arm[0] == pytest.approx(declared_over_true, rel=0.05)
    assert wrong_board_scale(found) == (declared_over_true > 1.5 or declared_over_true < 1 / 1.5)


def turning_in_place(declared_over_true: float, seconds: float = 10.0):
    """A camera that mostly turns about its own centre (1 m before the board; the centre sways 3 cm), its IMU
    10 cm off: the camera's PnP poses at 20 Hz (positions k times the truth) and the IMU's specific force and rate at
    200 Hz, from the exact kinematics (derivatives by central differences of a 2 kHz trajectory)."""
    fine = np.arange(0.0, seconds, 5e-4)
    angles = 0.4 * np.sin(2 * np.pi * np.outer(fine, [0.31, 0.53, 0.23]) + [0.0, 1.0, 2.0])
    R_board_cam = np.array([so3_exp(a) for a in angles]) @ np.diag([1.0, -1.0, -1.0])  # looking at the board (-z)
    centre = np.array([0.2, 0.2, 1.0]) + 0.03 * np.sin(2 * np.pi * np.outer(fine, [0.41, 0.29, 0.37]))
    lever = np.array([0.1, 0.0, 0.02])  # the IMU in the camera frame
    p_imu = centre + R_board_cam @ lever
    accel_board = np.gradient(np.gradient(p_imu, fine, axis=0), fine, axis=0)
    gravity = np.array([0.0, -9.81, 0.0])  # the board hangs on a wall
    force = np.einsum("nji,nj->ni", R_board_cam, accel_board - gravity)  # R_cam_imu = I: the IMU's axes the camera's
    imu_every, frame_every = 10, 100
    t_ns = np.round(fine * 1e9).astype(np.int64)
    at = np.arange(0, len(fine), imu_every)
    ahead, behind = np.minimum(at + 1, len(fine) - 1), np.maximum(at - 1, 0)
    gyro = np.array([so3_log(R_board_cam[b].T @ R_board_cam[a]) for a, b in zip(ahead, behind, strict=True)])
    gyro /= (fine[ahead] - fine[behind])[:, None]  # the body rate by central differences
    imu = ImuSamples(t_ns[at], gyro, force[at])
    T_cam_board = np.tile(np.eye(4), (len(fine[::frame_every]), 1, 1))
    R = R_board_cam[::frame_every]
    T_cam_board[:, :3, :3] = np.transpose(R, (0, 2, 1))
    T_cam_board[:, :3, 3] = -np.einsum("nji,nj->ni", R, centre[::frame_every] * declared_over_true)
    return FramePoses(t_ns[::frame_every], T_cam_board), imu


@pytest.mark.parametrize("declared_over_true", [1.0, 2.0])
def test_a_camera_turning_about_itself_is_no_evidence_of_a_wrong_board(declared_over_true):
    """The IMU swinging around a camera that turns in place reads accelerations the camera centre does not have:
    the centre's ratio alone reads far off (a camera on a robot's wrist turning first, as vical-collect's
    policy does, gave 0.37); with the lever arm fitted the board's true size shows."""
    posed, imu = turning_in_place(declared_over_true)
    found = board_scale(posed, imu, np.eye(3), 0.0)
    assert found.lever_arm[0] == pytest.approx(declared_over_true, rel=0.02)
    assert abs(np.log(found.centre[0] / declared_over_true)) > np.log(1.5)
    if declared_over_true == 1.0:  # the centre's ratio alone would call the right board 3x too large
        assert not wrong_board_scale(found)


def test_an_intrinsic_solve_stopped_far_from_its_minimum_is_named_a_failure():
    """A start three times the true focal length with two iterations allowed: the solve stops unconverged, and
    that alone fails the result."""
    from vical.calib.solve.intrinsics import calibrate_intrinsics

    rec = make_recording(duration=4.0, pixel_sigma=0.3, seed=2)
    truth = rec.truth.camera
    far = replace(truth, fx=3 * truth.fx, fy=3 * truth.fy)
    result = calibrate_intrinsics(rec.frames, rec.target, "radtan", initial_camera_guess=far, max_iterations=2)
    assert result.status == "max_iterations"
    assert implausibilities(result)[0].startswith("the solve did not converge in 2 iterations")
