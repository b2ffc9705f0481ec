"""The simulated Panda and sensor behind vical.robot's interfaces: poses, motions, streams, faults, refusals."""

import numpy as np
import pytest
from configs import env_parts

from vical.calib.detection.aprilgrid import detect_aprilgrid
from vical.data import NS_PER_S
from vical.env.calibration import CalibrationEnv
from vical.geometry import transform_error, transform_points
from vical.robot import MotionRefused, StampedPose
from vical.robot.interfaces import check_pose
from vical.sim import SimConfig
from vical.sim.adapters import RigFaults, SimRig
from vical.sim.sampling import SensorSampling

SIM, SENSOR, TASK, MDP = env_parts("joint")


def make_rig(seed: int = 3, **faults) -> SimRig:
    return SimRig(SimConfig.from_mapping(SIM), SensorSampling.from_config(SENSOR), seed, True, RigFaults(**faults))


@pytest.fixture(scope="module")
def rig():
    rig = make_rig()
    yield rig
    rig.close()


def shifted(pose: StampedPose, dx: float, dz: float = 0.0) -> np.ndarray:
    """The tool pose moved by ``dx`` along base x and ``dz`` along base z [m], orientation kept."""
    T = pose.T_base_tool.copy()
    T[:3, 3] += [dx, 0.0, dz]
    return T


def test_the_arm_reports_the_tool_pose_and_reaches_its_goal(rig):
    before = rig.arm.pose()
    np.testing.assert_allclose(before.T_base_tool, rig.sim.ee_pose())
    goal = shifted(before, -0.05, 0.03)
    after = rig.arm.move_to(goal)
    assert after.t_ns > before.t_ns
    rotation_rad, translation_m = transform_error(after.T_base_tool, goal)
    assert translation_m < 2e-3 and rotation_rad < np.radians(0.2)
    assert rig.arm.limits.max_speed == pytest.approx(1.7 * rig.sim.cfg.motion.velocity_scale)


def test_the_sensor_streams_rendered_frames_and_imu_samples_of_the_motion(rig):
    sensor = rig.sensor
    sensor.start()
    before_ns, period = rig.sim.time_ns, round(NS_PER_S / sensor.imu_rate_hz)
    resting = sensor.read()  # nothing new: the simulation rests one camera period
    assert rig.sim.time_ns - before_ns == pytest.approx(NS_PER_S / sensor.camera_rate_hz, abs=1e6)
    # The rest's samples in order, one an IMU period, to its end. The last may come with the next read (its reading
    # integrates past it), and one at the rest's start with this one (the end of a motion another test made).
    t = resting.imu.t
    assert len(resting.frames) == 1 and np.all(np.diff(t) == period)
    assert before_ns <= t[0] <= before_ns + period and rig.sim.time_ns - period <= t[-1] <= rig.sim.time_ns
    assert np.abs(resting.imu.gyro - rig.truth.gyro_bias).max() < 0.05
    rig.arm.move_to(shifted(rig.arm.pose(), 0.06))
    data = sensor.read()
    assert len(data.frames) >= 5 and len(data.imu) >= 100
    width, height = sensor.image_size
    assert all(f.image.shape == (height, width) for f in data.frames)
    np.testing.assert_allclose(np.diff([f.t_ns for f in data.frames]), NS_PER_S / sensor.camera_rate_hz)
    np.testing.assert_allclose(np.diff(data.imu.t), NS_PER_S / sensor.imu_rate_hz)
    assert np.linalg.norm(data.imu.accel, axis=1).mean() == pytest.approx(9.81, abs=0.5)
    # The real detector on the rendered images finds the corners the camera model projects (truth: analytic).
    camera, target = rig.truth.camera, rig.recorder.target
    found = 0
    for frame in data.frames[::3]:
        corners, ids = detect_aprilgrid(frame.image, target)
        if len(ids) < 8:
            continue
        exposure = frame.t_ns + round(rig.truth.time_offset * NS_PER_S)
        T_world_cam = camera_pose_at(rig, exposure)
        T_cam_board = np.linalg.inv(T_world_cam) @ rig.sim.T_world_board
        projected, _ = camera.project(transform_points(T_cam_board, target.points[ids]))
        assert np.median(np.linalg.norm(corners - projected, axis=1)) < 0.5
        found += 1
    assert found >= 2
    again = sensor.read()  # everything was delivered once: the next read is the next camera period
    assert again.frames[0].t_ns > data.frames[-1].t_ns and again.imu.t[0] > data.imu.t[-1]


def camera_pose_at(rig: SimRig, t_ns: int) -> np.ndarray:
    """The simulator's camera pose (OpenCV convention) at IMU time ``t_ns``, from the truth of the recording."""
    rec = rig.recorder.recording()
    k = int(np.argmin(np.abs(rec.trajectory.t - t_ns)))
    assert abs(int(rec.trajectory.t[k]) - t_ns) <= NS_PER_S / 100
    T_world_imu = rec.trajectory.T_world_imu[k]
    return T_world_imu @ np.linalg.inv(rig.truth.T_cam_imu)


def test_an_unreachable_goal_is_refused_before_anything_moves(rig):
    before = rig.arm.pose()
    with pytest.raises(MotionRefused, match="out of reach"):
        rig.arm.move_to(shifted(before, 2.0))
    after = rig.arm.pose()
    assert after.t_ns == before.t_ns
    np.testing.assert_array_equal(after.T_base_tool, before.T_base_tool)
    with pytest.raises(ValueError, match="not a rigid transform"):
        check_pose(np.diag([1.0, 2.0, 1.0, 1.0]))


def test_latency_tracking_error_and_an_imu_gap():
    rig = make_rig(seed=4, latency=0.2, tracking_noise_m=1e-3, tracking_noise_rad=np.radians(0.05), imu_gap=(0.3, 0.5))
    try:
        rig.sensor.start()
        start = rig.arm.pose()
        goal = shifted(start, 0.08)
        reached = rig.arm.move_to(goal)
        np.testing.assert_allclose(reached.T_base_tool, rig.sim.ee_pose())  # it reports where it is
        _, error_m = transform_error(reached.T_base_tool, goal)
        assert 1e-4 < error_m < 6e-3  # off by the tracking error, not by more
        imu = rig.sensor.read().imu
        t = (imu.t - start.t_ns) / NS_PER_S
        # The command latency: the arm rests for 0.2 s first (the sensor streams its resting rates).
        resting = t < 0.18
        assert resting.sum() > 10
        assert np.abs(imu.gyro[resting] - rig.truth.gyro_bias).max() < 0.05
        gap = np.diff(imu.t) / NS_PER_S
        assert gap.max() == pytest.approx(0.5, abs=0.02) and t[np.argmax(gap)] == pytest.approx(0.3, abs=0.02)
    finally:
        rig.close()


def test_a_rig_holds_the_sensor_the_env_draws_for_the_same_seed():
    rig = make_rig(seed=11)
    env = CalibrationEnv(SIM, SENSOR, TASK, **MDP)
    try:
        env.reset(seed=11)
        assert rig.truth.camera == env.truth.camera
        np.testing.assert_array_equal(rig.truth.T_cam_imu, env.truth.T_cam_imu)
        assert rig.truth.time_offset == env.truth.time_offset
        np.testing.assert_allclose(rig.arm.pose().T_base_tool, env.sim.ee_pose(), atol=1e-9)
    finally:
        env.close()
        rig.close()


def test_bad_faults_are_refused():
    with pytest.raises(ValueError, match=r"RigFaults\.latency"):
        RigFaults(latency=-1.0)
    with pytest.raises(ValueError, match=r"RigFaults\.imu_gap"):
        RigFaults(imu_gap=(0.1,))
