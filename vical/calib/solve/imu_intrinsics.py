"""IMU intrinsics (scale, misalignment, g-sensitivity) as a variable of the camera-IMU graph.

With the intrinsics ``theta`` (``vical.data.ImuIntrinsics.vector``) a variable, each IMU factor's
preintegrated measurement depends on it: the readings are corrected (``ImuIntrinsics.correct``)
before the rotation-compensated midpoint preintegration. ``IntrinsicImuFactor`` wraps GTSAM's C++
``CombinedImuFactorWithGravityDirection`` built from the measurement at the current ``theta``: its
error and its Jacobians on the states are the C++ factor's (analytic), its Jacobian on ``theta`` is a
forward difference over re-preintegrations (``theta`` enters only through the measurement, so the
states' linearisation is untouched). The biases are those of the corrected readings.

The readings of an interval are kept at its knots (the interval's ends and the samples inside), so
a correction costs one small matrix product and one preintegration.
"""

from __future__ import annotations

import gtsam
import numpy as np

from vical.calib.errors import CalibrationError, CalibrationSettingError
from vical.calib.solve.imu_integration import (
    interval_knots,
    knot_segments,
    preintegrate,
    reading_interpolant,
    readings_around,
)
from vical.data.imu_model import ImuIntrinsics

IMU_MODELS = ("calibrated", "scale-misalignment")
STATE_DIMS = (6, 3, 6, 3, 6, 6, 2)  # pose, velocity, pose, velocity, bias, bias, gravity direction
DIFFERENCE_STEP = 1e-6  # forward-difference step of theta (scales and angles ~1e-2: relative error ~1e-6)
# Weak prior on theta: a scale factor off by 5 %, an axis by 3 deg, a g-sensitivity of 0.01 (rad/s)/(m/s^2)
# would be a broken IMU; the prior only keeps unexcited directions finite.
PRIOR_SIGMAS = np.r_[np.full(3, 0.05), np.full(3, np.radians(3)), np.full(3, 0.05), np.full(6, np.radians(3))]
G_SENSITIVITY_PRIOR_SIGMA = 0.01
# Excitation needed before the intrinsics are estimated: each gyro axis turns at this RMS rate, and the
# specific force's direction spreads over all three IMU axes (the smallest eigenvalue of the mean of
# f f^T / |f|^2: 1/3 when spread evenly, 0 when it stays in a plane).
MIN_RATE_RMS = 0.2  # [rad/s]
MIN_DIRECTION_SPREAD = 0.02


def prior_sigmas(g_sensitivity: bool) -> np.ndarray:
    """(15,) or (24,) 1-sigma of the weak prior on ``theta`` (units of ``ImuIntrinsics.vector``)."""
    return np.r_[PRIOR_SIGMAS, np.full(9, G_SENSITIVITY_PRIOR_SIGMA)] if g_sensitivity else PRIOR_SIGMAS


def check_excitation(gyro: np.ndarray, accel: np.ndarray) -> None:
    """Refuse to estimate the intrinsics from a motion that does not excite them (rates, orientations)."""
    rms = np.sqrt(np.mean(gyro**2, axis=0))
    unit = accel / np.linalg.norm(accel, axis=1, keepdims=True)
    spread = float(np.linalg.eigvalsh(unit.T @ unit / len(unit))[0])
    weak = [f"the gyro's {a} axis turns at {r:.2f} rad/s RMS" for a, r in zip("xyz", rms, strict=True)]
    weak = [w for w, r in zip(weak, rms, strict=True) if r < MIN_RATE_RMS]
    if spread < MIN_DIRECTION_SPREAD:
        weak.append(f"gravity stays near one plane of the IMU (direction spread {spread:.3f})")
    if weak:
        raise CalibrationSettingError(
            f"too little motion to estimate the IMU intrinsics: {'; '.join(weak)}, below the {MIN_RATE_RMS} rad/s "
            f"RMS per axis and {MIN_DIRECTION_SPREAD} spread they need; rotate about every IMU axis and hold the "
            "sensor in several orientations, or leave {fix}",
            "imu_model",
            "'calibrated'",
            "calibrated",
        )


def check_model(imu_model: str, g_sensitivity: bool) -> None:
    if imu_model not in IMU_MODELS:
        raise CalibrationError(f"calibration option imu_model must be one of {IMU_MODELS}, got {imu_model!r}")
    if g_sensitivity and imu_model == "calibrated":
        raise CalibrationError("calibration option g_sensitivity needs imu_model 'scale-misalignment'")


class IntervalReadings:
    """The raw readings of one IMU interval at its knots, corrected on demand."""

    def __init__(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, ta: float, tb: float) -> None:
        w = readings_around(t, ta, tb)
        self.knots = interval_knots(t[w], ta, tb)
        self.gyro = reading_interpolant(t[w], gyro[w], self.knots)
        self.accel = reading_interpolant(t[w], accel[w], self.knots)

    def preintegrated(self, params, bias: gtsam.imuBias.ConstantBias, theta: np.ndarray):
        gyro, accel = ImuIntrinsics.from_vector(theta).correct(self.gyro, self.accel)
        return preintegrate(params, bias, knot_segments(self.knots, gyro, accel))


class IntrinsicImuFactor:
    """One IMU interval's factor with the intrinsics key: a ``gtsam.CustomFactor`` (``factor``) plus the
    ``error`` and ``measurement`` that the noise levels and residual statistics read."""

    def __init__(self, keys: list[int], theta_key: int, readings: IntervalReadings, params, bias, gravity: float):
        self.keys, self.theta_key = list(keys), theta_key
        self.readings, self.params, self.bias, self.gravity = readings, params, bias, gravity
        self._cache: tuple[bytes, gtsam.CombinedImuFactorWithGravityDirection] | None = None
        unit = gtsam.noiseModel.Unit.Create(15)
        self.factor = gtsam.CustomFactor(unit, [*self.keys, theta_key], self._error)

    def _imu_factor(self, theta: np.ndarray) -> gtsam.CombinedImuFactorWithGravityDirection:
        tag = theta.tobytes()
        if self._cache is None or self._cache[0] != tag:
            pim = self.readings.preintegrated(self.params, self.bias, theta)
            self._cache = (tag, gtsam.CombinedImuFactorWithGravityDirection(*self.keys, pim, self.gravity))
        return self._cache[1]

    def _error(self, _, values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
        theta = values.atVector(self.theta_key)
        base = self._imu_factor(theta)
        error = base.whitenedError(values)
        if H is None:
            return error
        A = base.linearize(values).jacobian()[0]
        edges = np.cumsum((0, *STATE_DIMS))
        for k in range(len(self.keys)):
            H[k] = A[:, edges[k] : edges[k + 1]]
        H[len(self.keys)] = self._theta_jacobian(theta, values, error)
        return error

    def _theta_jacobian(self, theta: np.ndarray, values: gtsam.Values, error: np.ndarray) -> np.ndarray:
        J = np.empty((15, len(theta)))
        for j in range(len(theta)):
            shifted = theta.copy()
            shifted[j] += DIFFERENCE_STEP
            pim = self.readings.preintegrated(self.params, self.bias, shifted)
            moved = gtsam.CombinedImuFactorWithGravityDirection(*self.keys, pim, self.gravity)
            J[:, j] = (moved.whitenedError(values) - error) / DIFFERENCE_STEP
        return J

    def error(self, values: gtsam.Values) -> float:
        return self.factor.error(values)

    def measurement(self, values: gtsam.Values) -> gtsam.PreintegratedCombinedMeasurements:
        """The preintegrated measurement at the intrinsics in ``values``."""
        return self._imu_factor(values.atVector(self.theta_key)).preintegratedMeasurements()
