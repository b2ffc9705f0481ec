"""The calibrator on recordings made by the simulator (not only on its own synthetic generator).

These tests tie the simulator's conventions (time-offset sign, frames, IMU timing, rendered
corners) to the calibrator's: a flipped sign, an inverted transform or a timing skew between
the simulated IMU and camera fails them.
"""

from dataclasses import replace

import numpy as np
import pytest

from vical.calib.detection.checkerboard import detect_checkerboard
from vical.calib.metrics import calibration_errors
from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint
from vical.data import ImuNoise
from vical.geometry import euler_to_matrix, make_transform, so3_log
from vical.sim import PandaSim
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import SensorSampling, sample_sensor


def excitation(cycles: int, angle: float = 0.25, shift: float = 0.07) -> list[np.ndarray]:
    """End-effector goals (4, 4) relative to home: rotations about each body axis both ways, with translations."""
    goals = []
    for k in range(cycles):
        flip = 1.0 if k % 2 == 0 else -1.0
        for axis in range(3):
            for sign in (1.0, -1.0):
                rpy, p = np.zeros(3), np.zeros(3)
                rpy[axis] = sign * angle
                p[(axis + 1) % 3] = flip * sign * shift
                p[(axis + 2) % 3] = -0.5 * flip * sign * shift
                goals.append(make_transform(euler_to_matrix(rpy), p))
    return goals


def record(sampling: SensorSampling, truth, cycles: int, seed: int, detector=None):
    sim = PandaSim()
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling, detector, render_size=(704, 528))
    try:
        sim.reset()
        recorder.start(truth, np.random.default_rng(seed))
        T_home = sim.ee_pose()
        for goal in excitation(cycles):
            result = sim.move_to(T_home @ goal, observer=recorder)
            assert result.reached, result.message
            recorder.add_motion(result)
        return recorder.recording()
    finally:
        recorder.close()


@pytest.mark.parametrize("offset_ms", [-30.0, 0.0, 5.0, 30.0])
def test_time_offset_recovered_with_the_simulators_sign(offset_ms):
    sampling = SensorSampling()
    truth = replace(sample_sensor(sampling, np.random.default_rng(11)), time_offset=offset_ms * 1e-3)
    recording = record(sampling, truth, cycles=5, seed=3)
    assert recording.duration > 20.0  # a 20 s well-excited recording

    result = calibrate_extrinsics(recording.frames, recording.imu, recording.target, truth.camera, truth.imu_noise)

    assert result.time_offset * 1e3 == pytest.approx(offset_ms, abs=0.5)
    errors = calibration_errors(result, truth)
    assert errors.rotation_deg < 0.2 and errors.translation_mm < 10.0


def test_noise_free_simulation_has_no_timing_skew_between_imu_and_camera():
    """Ideal sensors: the estimated offset and extrinsic are limited only by discretisation."""
    sampling = replace(SensorSampling(), pixel_noise_px=0.0)
    truth = replace(
        sample_sensor(sampling, np.random.default_rng(5)),
        time_offset=0.0123,
        imu_noise=ImuNoise(0.0, 0.0, 0.0, 0.0, 200.0),
    )
    recording = record(sampling, truth, cycles=3, seed=0)

    result = calibrate_extrinsics(recording.frames, recording.imu, recording.target, truth.camera, ImuNoise())

    errors = calibration_errors(result, truth)
    assert errors.time_offset_ms < 0.05
    assert errors.rotation_deg < 0.01 and errors.translation_mm < 1.5


def test_joint_calibration_of_rendered_images_within_reported_uncertainty():
    """MuJoCo renders, the lens warp distorts, OpenCV detects; one graph recovers everything."""
    sampling = replace(SensorSampling(), backend="render")
    truth = replace(sample_sensor(sampling, np.random.default_rng(7)), time_offset=0.012)
    recording = record(sampling, truth, cycles=2, seed=7, detector=detect_checkerboard)
    assert (recording.frames.num_detections > 0).mean() > 0.8

    result = calibrate_joint(recording.frames, recording.imu, recording.target, "radtan", (640, 480), truth.imu_noise)

    errors = calibration_errors(result, truth)
    assert errors.intrinsic_pct < 1.0 and errors.time_offset_ms < 0.5
    assert errors.rotation_deg < 0.2 and errors.translation_mm < 15.0
    # Honest uncertainty: each intrinsic and translation error within 4 sigma of what the graph reports.
    sig = result.sigmas
    for k, name in enumerate(["fx", "fy", "cx", "cy"]):
        assert errors.intrinsic_abs_px[k] < 4 * sig[name], name
    for k, name in enumerate(["t_x", "t_y", "t_z"]):
        assert abs(result.T_cam_imu[k, 3] - truth.T_cam_imu[k, 3]) < 4 * sig[name], name


@pytest.mark.integration
def test_rendered_images_errors_within_three_reported_sigma():
    """The detector's noise on rendered images is no simulated Gaussian: the reported 1-sigma must still hold.

    Over five sensors, the camera parameters and the extrinsic (15 per sensor) lie within 3 sigma for
    at least 95 % of them.
    """
    sampling = replace(SensorSampling(), backend="render")
    z = []
    for seed in range(20, 25):
        truth = replace(sample_sensor(sampling, np.random.default_rng(seed)), time_offset=0.006)
        recording = record(sampling, truth, cycles=2, seed=seed, detector=detect_checkerboard)
        result = calibrate_joint(
            recording.frames, recording.imu, recording.target, "radtan", (640, 480), truth.imu_noise
        )
        rotation = so3_log(result.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T)
        error = np.r_[
            result.camera.parameters - truth.camera.parameters,
            rotation,
            result.T_cam_imu[:3, 3] - truth.T_cam_imu[:3, 3],
            result.time_offset - truth.time_offset,
        ]
        names = result.parameter_names[:8] + ["rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "time_offset"]
        z.append(np.abs(error) / np.array([result.sigma(n) for n in names]))
    z = np.concatenate(z)
    assert np.mean(z <= 3.0) >= 0.95, np.round(z, 1)
