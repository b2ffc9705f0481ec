"""The synthetic generator the calibrator is tested on: exact IMU, Kalibr's time-offset sign, nominal rig."""

import numpy as np
import pytest

from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.synthetic import GRAVITY, Excitation, euler_body_rates, imu_kinematics, make_recording
from vical.data import NS_PER_S, Target
from vical.geometry import R_CAM_BODY, euler_to_matrix, so3_log


def test_euler_body_rates_match_finite_differences():
    rng = np.random.default_rng(0)
    e0, de, dde = rng.normal(size=3) * 0.5, rng.normal(size=3), rng.normal(size=3)
    h = 1e-5

    def angles(t):
        return e0 + de * t + 0.5 * dde * t * t

    omega, domega = euler_body_rates(angles(0.0)[None], de[None], dde[None])
    R0, R1 = euler_to_matrix(angles(-h)), euler_to_matrix(angles(h))
    assert np.allclose(so3_log(R0.T @ R1) / (2 * h), omega[0], atol=1e-8)
    w_plus = euler_body_rates(angles(h)[None], (de + dde * h)[None], dde[None])[0][0]
    w_minus = euler_body_rates(angles(-h)[None], (de - dde * h)[None], dde[None])[0][0]
    assert np.allclose((w_plus - w_minus) / (2 * h), domega[0], atol=1e-6)


def test_imu_is_the_exact_derivative_of_the_trajectory():
    target, T_cam_imu = Target.checkerboard(), nominal_T_cam_imu()
    t, h = np.array([1.3, 4.7]), 1e-4
    T, v, gyro, accel = imu_kinematics(Excitation(), target, T_cam_imu, t)
    Tm = imu_kinematics(Excitation(), target, T_cam_imu, t - h)[0]
    Tp = imu_kinematics(Excitation(), target, T_cam_imu, t + h)[0]
    a_world = (Tp[:, :3, 3] - 2 * T[:, :3, 3] + Tm[:, :3, 3]) / h**2
    assert np.allclose(np.einsum("nji,nj->ni", T[:, :3, :3], a_world - GRAVITY), accel, atol=1e-5)
    assert np.allclose((Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h), v, atol=1e-7)
    for k in range(2):
        assert np.allclose(so3_log(Tm[k, :3, :3].T @ Tp[k, :3, :3]) / (2 * h), gyro[k], atol=1e-7)


@pytest.mark.parametrize("offset", [-0.03, 0.02])
def test_frame_stamped_t_cam_shows_the_pose_at_imu_time_t_cam_plus_offset(offset):
    rec = make_recording(duration=3.0, time_offset=offset)
    k = int(np.flatnonzero(rec.frames.num_detections)[5])
    t_exposure = (rec.frames.t[k] - rec.imu.t[0]) / NS_PER_S + offset
    T_world_imu = imu_kinematics(Excitation(), rec.target, rec.truth.T_cam_imu, np.array([t_exposure]))[0][0]
    T_cam_target = rec.truth.T_cam_imu @ np.linalg.inv(T_world_imu) @ rec.T_world_target
    p = rec.target.points @ T_cam_target[:3, :3].T + T_cam_target[:3, 3]
    uv, _ = rec.truth.camera.project(p)
    assert np.abs(uv - rec.frames.corners[k]).max() < 1e-9


def test_nominal_rig_matches_the_documented_mounting():
    T = nominal_T_cam_imu()
    R_body_imu = euler_to_matrix([0.0, 0.0, 1.57])
    assert np.allclose(T[:3, :3], R_CAM_BODY @ R_body_imu)
    assert np.allclose(T[:3, 3], R_CAM_BODY @ [0.06, 0.0, -0.10])
    # The camera's optical axis is the body's x axis: forward.
    assert np.allclose(R_CAM_BODY @ [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])


def test_accelerometer_reads_gravity_up_and_board_stays_in_view():
    rec = make_recording(duration=10.0)
    mean_specific_force = np.mean(np.linalg.norm(rec.imu.accel, axis=1))
    assert 8.0 < mean_specific_force < 12.0
    assert np.mean(rec.frames.num_detections == rec.target.num_points) > 0.6
    assert set(np.unique(rec.frames.num_detections)) <= {0, rec.target.num_points}
