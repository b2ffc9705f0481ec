"""Honest uncertainty with effects the calibrator does not model: |error| <= 3 sigma for >= 95 % of parameters.

A rolling shutter (each image row exposed at its own time) and an IMU noisier than its declared
densities bias the estimates in ways no noise model of the solve describes. Before the
cluster-robust widening, 14 % (extrinsic) and 19 % (joint) of the parameters of six recordings
with a 5 ms rolling shutter lay beyond 3 sigma (rot_y up to 4.9 sigma, cx up to 7.8 sigma).
The render backend's detector noise is checked in tests/test_sim_calib_integration.py.
"""

import numpy as np
import pytest

from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise, Target
from vical.geometry import so3_log

BIASES = {"gyro_bias": [0.01, -0.02, 0.005], "accel_bias": [0.05, -0.1, 0.08]}  # [rad/s], [m/s^2]
EXTRINSIC = ["rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "time_offset"]
EFFECTS = {
    "rolling shutter 5 ms": {"line_delay": 0.005 / 480},
    "rolling shutter 15 ms": {"line_delay": 0.015 / 480},
    "IMU 3x noisier than declared": {"imu_noise": ImuNoise().scaled(3.0)},
}


def z_scores(result, truth, joint: bool) -> np.ndarray:
    """Errors over the reported 1-sigma: extrinsic rotation (camera frame), translation, time offset (+ camera).

    A global-shutter model of a rolling shutter times the image's middle row (the readout's mean): its time offset
    is compared with that row's.
    """
    rotation = so3_log(result.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T)
    middle_row = truth.time_offset + truth.line_delay * truth.camera.height / 2
    error = np.r_[rotation, result.T_cam_imu[:3, 3] - truth.T_cam_imu[:3, 3], result.time_offset - middle_row]
    names = list(EXTRINSIC)
    if joint:
        error = np.r_[error, result.camera.parameters - truth.camera.parameters]
        names += result.parameter_names[:8]
    return error / np.array([result.sigma(n) for n in names])


def calibrate(seed: int, joint: bool, **effect):
    kwargs = {"imu_noise": ImuNoise(), **effect}
    rec = make_recording(
        duration=20.0, camera_rate_hz=20.0, target=Target.aprilgrid(), seed=seed, time_offset=0.01,
        pixel_sigma=0.3, **BIASES, **kwargs,
    )  # fmt: skip
    declared = ImuNoise()  # the paper's densities, whatever the recording's IMU really had
    if joint:
        return calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), declared), rec.truth
    return calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, declared), rec.truth


@pytest.mark.integration
@pytest.mark.parametrize("effect", list(EFFECTS))
def test_errors_stay_within_three_reported_sigma_despite_unmodelled_effects(effect):
    z = []
    for seed, joint in ((0, False), (1, False), (2, True), (3, True)):
        result, truth = calibrate(seed, joint, **EFFECTS[effect])
        z.append(np.abs(z_scores(result, truth, joint)))
    z = np.concatenate(z)
    assert np.mean(z <= 3.0) >= 0.95, np.round(z, 1)


@pytest.mark.integration
def test_the_widened_parameters_are_named():
    result, _ = calibrate(0, False, line_delay=0.015 / 480)
    note = next(w for w in result.warnings if "widened" in w)
    assert "rot_y" in note and "time_offset" in note


def test_a_correct_noise_model_is_not_widened_much():
    """Without unmodelled effects the reported sigma stays the noise model's: |z| behaves as a standard normal."""
    z = np.concatenate([np.abs(z_scores(*calibrate(seed, False), joint=False)) for seed in range(4)])
    assert 0.45 < np.median(z) < 0.9  # a standard normal's median |z| is 0.674
    assert np.mean(z <= 3.0) >= 0.95
