"""The gyro's scales and misalignments at the solution of a ``calibrated``-model graph
(``vical.calib.solve.imu_model_error``): the readings' Jacobian against re-preintegrated readings, the evidence
threshold against a simulation, the values found against the truth, an ideal gyro left alone, and a scaled gyro's
effect on the extrinsic counted in its uncertainty."""

import gtsam
import numpy as np
import pytest

import vical.calib.solve.imu_model_error as imu_model_error
import vical.calib.solve.vi_covariance as vi_covariance
from vical.calib import calibrate_extrinsics
from vical.calib.solve.imu_integration import preintegration_params
from vical.calib.solve.imu_intrinsics import IntervalReadings
from vical.calib.solve.imu_model_error import GYRO, GYRO_ENTRIES, evidence_threshold, reading_jacobian
from vical.calib.synthetic import make_recording
from vical.data import ImuIntrinsics, ImuNoise
from vical.geometry import rotation_angle, so3_log

# A gyro 0.8 % fast about x, 0.6 % slow about y, 0.3 % fast about z, its y and z axes leaning 0.3 deg towards x
# and z 0.2 deg towards y (the size of what the real dev set's gyro shows, docs/calibration.md "Real data").
GYRO_TRUTH = np.array([0.008, -0.006, 0.003, np.radians(0.3), np.radians(0.3), np.radians(-0.2)])


def gyro_intrinsics(entries: np.ndarray) -> ImuIntrinsics:
    theta = np.zeros(15)
    theta[GYRO_ENTRIES] = entries
    return ImuIntrinsics.from_vector(theta)


def test_the_readings_jacobian_agrees_with_re_preintegrating_corrected_readings():
    """A 50 ms interval of hand-held rates (up to 2 rad/s): the first-order Jacobian against forward differences
    over the readings corrected by each entry and preintegrated again (vical.calib.solve.imu_intrinsics)."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 0.2, 0.005)
    gyro = np.cumsum(rng.normal(0, 0.3, (len(t), 3)), axis=0) + [1.5, -1.0, 0.8]
    accel = rng.normal(0, 1.0, (len(t), 3)) + [0.3, 0.2, 9.81]
    readings = IntervalReadings(t, gyro, accel, 0.0525, 0.1025)
    params, bias = preintegration_params(ImuNoise()), gtsam.imuBias.ConstantBias()
    keys = [gtsam.symbol(c, int(i)) for c, i in ("x0", "v0", "x1", "v1", "b0", "b1", "g0")]

    def factor(theta):
        pim = readings.preintegrated(params, bias, theta)
        return gtsam.CombinedImuFactorWithGravityDirection(*keys, pim, 9.81)

    base = factor(np.zeros(15))
    values = gtsam.Values()
    values.insert(keys[0], gtsam.Pose3())
    values.insert(keys[1], np.array([0.1, 0.0, 0.0]))
    values.insert(keys[2], gtsam.Pose3(gtsam.Rot3.Expmap(np.array([0.07, -0.05, 0.04])), np.array([0.005, 0.0, 0.0])))
    values.insert(keys[3], np.array([0.1, 0.01, 0.0]))
    values.insert(keys[4], bias)
    values.insert(keys[5], bias)
    values.insert(keys[6], gtsam.Unit3(np.array([0.0, 0.0, -1.0])))
    A, _ = base.linearize(values).jacobian()
    mean_rate = (readings.knots[1:] - readings.knots[:-1]) @ (0.5 * (readings.gyro[1:] + readings.gyro[:-1])) / 0.05
    found = reading_jacobian(base, A, mean_rate, GYRO.bias_columns)
    step = 1e-6
    expected = np.empty_like(found)
    for column, entry in enumerate(GYRO_ENTRIES):
        theta = np.zeros(15)
        theta[entry] = step
        expected[:, column] = (factor(theta).whitenedError(values) - base.whitenedError(values)) / step
    np.testing.assert_allclose(found, expected, atol=0.05 * np.abs(expected).max())


def test_the_evidence_threshold_is_hotellings_over_few_windows_and_chi_square_without_them():
    """Hotelling's T^2 (6 parameters, C windows) at 1 in 1000 against a simulation of it; chi-square's 22.46
    without windows; no test with 6 windows or fewer."""
    rng = np.random.default_rng(0)
    windows = 20
    pulls = rng.standard_normal((200_000, windows, 6))
    mean = pulls.mean(axis=1)
    centred = pulls - mean[:, None]
    covariance = np.einsum("nci,ncj->nij", centred, centred) / (windows - 1) / windows
    statistic = np.einsum("ni,ni->n", mean, np.linalg.solve(covariance, mean[..., None])[..., 0])
    assert np.mean(statistic > evidence_threshold(windows)) == pytest.approx(0.001, abs=0.0004)
    assert evidence_threshold(None) == pytest.approx(22.458, abs=1e-3)
    assert evidence_threshold(6) == np.inf and evidence_threshold(7) > evidence_threshold(40) > evidence_threshold(None)


@pytest.fixture
def spy(monkeypatch):
    """The gyro's ImuModelError of every solve (the real function runs)."""
    seen = []

    def recorded(*args, **kwargs):
        found = imu_model_error.imu_model_errors(*args, **kwargs)
        seen.append(next(f for f in found if f.sensor is GYRO))
        return found

    monkeypatch.setattr(vi_covariance, "imu_model_errors", recorded)
    return seen


def calibrate(recording):
    truth = recording.truth
    return calibrate_extrinsics(recording.frames, recording.imu, recording.target, truth.camera, truth.imu_noise)


def is_gyro_warning(text: str) -> bool:
    return text.startswith("the gyro reads with a scale and axis misalignment")


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_an_ideal_gyro_shows_no_scale_and_keeps_its_uncertainty(spy, seed):
    recording = make_recording(duration=12, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=seed)
    result = calibrate(recording)
    (found,) = spy
    assert found.statistic < found.threshold and not found.significant
    assert not np.any(found.considered())
    assert not any(is_gyro_warning(w) for w in result.warnings)


def test_a_scaled_gyro_is_found_and_the_extrinsic_uncertainty_covers_what_it_shifts(spy, monkeypatch):
    recording = make_recording(
        duration=40, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=21, imu_intrinsics=gyro_intrinsics(GYRO_TRUTH)
    )
    result = calibrate(recording)
    found = spy[-1]
    assert found.significant
    sigma = np.sqrt(np.diag(found.covariance))
    assert np.all(np.abs(found.estimate - GYRO_TRUTH) < 3 * sigma), (found.estimate - GYRO_TRUTH) / sigma
    assert any(is_gyro_warning(w) for w in result.warnings)

    def rotation_mahalanobis(r) -> float:
        """The extrinsic rotation's error against the truth in its reported covariance (chi-square, 3 dof)."""
        vector = so3_log(r.T_cam_imu[:3, :3] @ recording.truth.T_cam_imu[:3, :3].T)
        _, covariance = r.block(["rot_x", "rot_y", "rot_z"])
        return float(vector @ np.linalg.solve(covariance, vector))

    # Without the gyro's effect in the covariance the same estimate lies far outside its 1-sigma ellipsoid; with
    # it, inside the 99.9 % one (chi-square, 3 degrees of freedom: 16.3).
    monkeypatch.setattr(imu_model_error, "FALSE_ALARM", 0.0)
    unwidened = calibrate(recording)
    assert rotation_angle(unwidened.T_cam_imu[:3, :3] @ result.T_cam_imu[:3, :3].T) < 1e-9  # the estimate is the same
    assert rotation_mahalanobis(unwidened) > 16.3
    assert rotation_mahalanobis(result) < 16.3
