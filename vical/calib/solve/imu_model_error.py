"""The IMU's scales and axis misalignments, which the default IMU model (``calibrated``) does not have: tested for
at the solution, and their effect on the estimates counted in their uncertainty where the data show them or the
IMU's grade says they may be there.

A real gyro reads its rates scaled and sheared by a few tenths of a percent (``vical.data.imu_model``: ``M_g``),
and its accelerometer its specific forces (``M_a``). The ``calibrated`` model takes the readings as exact up to
noise and bias, so the extrinsic absorbs the part of ``M_g`` and ``M_a`` that the motion excites, and windows of
one recording that turn about different axes land on different rotations: on the real dev set the three 10 s
windows' rot_x drifted by 4 of their sigmas, and with the gyro corrected by the scales and misalignment that
``--imu-model scale-misalignment`` found on 30 s they agreed (docs/calibration.md, "Real data"). Estimating them
in every solve is slow (a re-preintegration per IMU factor and parameter at every linearisation) and short
recordings do not excite them; so the solve keeps the ``calibrated`` model, and ``imu_model_error`` asks the data,
at the solution, what they show of each sensor's six terms (``SENSORS``: gyro, accelerometer):

- ``B``, the whitened IMU residuals' Jacobian on the six entries of ``M`` (three scales, three misalignments:
  Kalibr's lower-triangular ``M``), from each factor's Jacobian on its first bias (``reading_jacobian``; for the
  gyro the forward differences over re-preintegrations it replaces agree to 1e-4 in the test statistic on the
  real dev set, at a fifth of the time);
- the step a Gauss-Newton solve with ``M`` free would take from ``M = I`` with every other variable profiled out
  (the Schur complement of the linearised system), its covariance under the measured noise levels widened by its
  cluster-robust one (``vical.calib.solve.robust_covariance``), and the score statistic
  ``theta^T Sigma^-1 theta`` (Hotelling's ``T^2`` over the windows where the sensor has no such error:
  ``evidence_threshold``);
- where that statistic passes the 1-in-1000 level (``FALSE_ALARM``), the estimates stay as solved (the
  references a user compares with are calibrated with the ``calibrated`` model too) and their covariance
  gains ``S (theta theta^T + Sigma) S^T``, ``S`` their first-order shift per unit of ``M``: the expected
  square of the error the unmodelled terms leave in them;
- below it, the data have not ruled the terms out: the covariance gains ``S (theta_p theta_p^T + Sigma_p) S^T``
  with the IMU grade's 1-sigma ``Sigma_g`` (``vical.data.imu_grade``) as the prior:
  ``K = Sigma_g (Sigma_g + Sigma)^-1``, ``theta_p = K theta``, ``Sigma_p = Sigma_g - K Sigma_g`` (the posterior
  given what the data show). It is zero for a ``calibrated`` grade (an ideal IMU's results keep their
  uncertainty), tends to the grade's own spread where the data show nothing (a short window) and to the
  significant case's term where they determine the terms well. The two sensors are profiled one at a time
  (their cross terms are left out: each sensor's step is found with the other's terms at zero).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
import scipy.linalg
from scipy.special import betaincinv, gammaincinv

from vical.calib.solve.imu_integration import cumulative_angle, interpolate
from vical.calib.solve.robust_covariance import LinearSystem, cluster_robust, widen
from vical.data.imu_grade import ImuGrade
from vical.data.imu_model import ImuIntrinsics

PREINTEGRATED_ROWS = 9  # an IMU factor's error: rotation, position, velocity, then the biases' random walk
FALSE_ALARM = 0.001  # how often an ideal sensor is called scaled


@dataclass(frozen=True)
class Sensor:
    """One of the IMU's two sensors, as the tests see it.

    Attributes:
        name: as the warnings say it.
        key: ``ImuIntrinsics.parameter_names``'s prefix and ``ImuGrade``'s (``gyro``, ``accel``).
        bias_columns: (3,) its first bias's columns in an IMU factor's Jacobian (poses and velocities: 18, then
            the first bias: accelerometer, gyro).
        entries: (6,) its scales and misalignments in ``ImuIntrinsics.vector``.
    """

    name: str
    key: str
    bias_columns: np.ndarray
    entries: np.ndarray

    def prior(self, grade: ImuGrade | None) -> np.ndarray:
        """(6, 6) the grade's covariance of the entries (zero: none declared, or ``calibrated``)."""
        scale, misalignment = (0.0, 0.0) if grade is None else grade.terms(self.key)
        return np.diag([scale**2] * 3 + [misalignment**2] * 3)


GYRO = Sensor("gyro", "gyro", np.arange(21, 24), np.arange(6, 12))
ACCEL = Sensor("accelerometer", "accel", np.arange(18, 21), np.arange(0, 6))
SENSORS = (GYRO, ACCEL)
GYRO_ENTRIES = GYRO.entries


@dataclass(frozen=True)
class ImuModelError:
    """What the residuals say of one sensor's scales and misalignments (``Sensor.entries``).

    Attributes:
        sensor: which (``SENSORS``).
        estimate: (6,) the step from the ideal sensor: scales - 1 (x, y, z), misalignments (yx, zx, zy) [rad].
        covariance: (6, 6) its covariance.
        statistic: ``estimate^T covariance^-1 estimate``.
        threshold: the statistic an ideal sensor exceeds with probability ``FALSE_ALARM`` (``evidence_threshold``).
        sensitivity: (K, 6) the first-order shift of the solve's variables (the keys' tangent columns) per unit of
            the sensor's entries, were they corrected.
        prior: (6, 6) the IMU grade's covariance of the entries (``Sensor.prior``; zero: ``calibrated``).
    """

    sensor: Sensor
    estimate: np.ndarray
    covariance: np.ndarray
    statistic: float
    threshold: float
    sensitivity: np.ndarray
    prior: np.ndarray

    @property
    def significant(self) -> bool:
        return self.statistic > self.threshold

    def considered(self) -> np.ndarray:
        """(K, K) the covariance the entries' effect adds to the solve's variables: the data's where significant,
        else the grade's given the data (zero for a ``calibrated`` grade)."""
        return self.sensitivity @ self.spread() @ self.sensitivity.T

    def spread(self) -> np.ndarray:
        """(6, 6) the expected square of the entries the solve leaves uncorrected (module docstring)."""
        if self.significant:
            return np.outer(self.estimate, self.estimate) + self.covariance
        if not np.any(self.prior):
            return np.zeros_like(self.prior)
        gain = np.linalg.solve(self.prior + self.covariance, self.prior).T  # Sigma_g (Sigma_g + Sigma)^-1
        posterior = self.prior - gain @ self.prior
        mean = gain @ self.estimate
        return np.outer(mean, mean) + 0.5 * (posterior + posterior.T)


def imu_model_errors(
    system: LinearSystem,
    linear: gtsam.GaussianFactorGraph,
    imu_factors: list,
    state_times: np.ndarray,
    imu: tuple[np.ndarray, np.ndarray, np.ndarray],
    keys: list[int],
    grade: ImuGrade | None = None,
) -> list[ImuModelError]:
    """``imu_model_error`` of each sensor (``SENSORS``) that it can test; ``imu``: t, gyro, accel (N, 3)."""
    t, *readings = imu
    found = [
        imu_model_error(sensor, system, linear, imu_factors, state_times, (t, r), keys, sensor.prior(grade))
        for sensor, r in zip(SENSORS, readings, strict=True)
    ]
    return [f for f in found if f is not None]


def imu_model_error(
    sensor: Sensor,
    system: LinearSystem,
    linear: gtsam.GaussianFactorGraph,
    imu_factors: list,
    state_times: np.ndarray,
    imu: tuple[np.ndarray, np.ndarray],
    keys: list[int],
    prior: np.ndarray | None = None,
) -> ImuModelError | None:
    """Test the solution of a ``calibrated``-model graph for one sensor's scales and misalignments.

    Args:
        sensor: which (``GYRO``, ``ACCEL``).
        system: the graph's normal equations at the solution (``LinearSystem``; its factors in the graph's order).
        linear: the graph linearised at the solution.
        imu_factors: the graph's IMU factors ``(n, factor, dt)`` (graph factors 0..N-1, factor n between states
            n and n + 1 at ``state_times`` (S,) [s], IMU clock).
        imu: the sensor's samples the factors were preintegrated from: t (N,) [s], readings (N, 3) [rad/s, m/s^2].
        keys: the variables whose sensitivity is wanted.
        prior: (6, 6) the IMU grade's covariance of the entries (``Sensor.prior``); None: ``calibrated``.

    Returns:
        None where the information is singular.
    """
    if system.singular or not imu_factors:
        return None
    P, m = system.size, len(sensor.entries)
    C, Cs = np.zeros((P, m)), np.zeros((P, m))  # A^T B and sum_k s_k A_k^T B_k
    BtB, BtBs, Btb = np.zeros((m, m)), np.zeros((m, m)), np.zeros(m)
    window_pulls = np.zeros((system.gradients.shape[1], m))
    means = mean_readings(imu[0], imu[1], state_times)
    for n, factor, _ in imu_factors:
        A, b = linear.at(n).jacobian()
        B = reading_jacobian(factor, A, means[n], sensor.bias_columns)
        index = system.factor_columns(linear.at(n))
        s = system.variance_scale[n]
        AtB, BtB_n = A.T @ B, B.T @ B
        C[index] += AtB
        Cs[index] += s * AtB
        BtB += BtB_n
        BtBs += s * BtB_n
        Btb += B.T @ b
        if system.window[n] >= 0:
            window_pulls[system.window[n]] += B.T @ b
    Y = system.solve(C)  # H^-1 C: the other variables' shift per unit of the sensor's entries
    information = BtB - C.T @ Y
    try:
        inverse = np.linalg.inv(information)
    except np.linalg.LinAlgError:
        return None
    estimate = inverse @ (Btb - Y.T @ system.gradient)
    # The profiled score psi = (B - A Y)^T b: its variance under the measured noise levels, and per window.
    score_variance = BtBs - Cs.T @ Y - Y.T @ Cs + Y.T @ (system.M @ Y)
    model = inverse @ score_variance @ inverse
    pulls = window_pulls - system.gradients.T @ Y
    covariance = _widened(model, cluster_robust(pulls), inverse)
    # The test: the windows' scores about their mean (Hotelling's T^2; about zero, as the covariance above, a
    # sensor's true scale would inflate its own yardstick).
    tested = _widened(model, cluster_robust(pulls - pulls.mean(axis=0)), inverse)
    try:
        statistic = float(estimate @ np.linalg.solve(tested, estimate))
    except np.linalg.LinAlgError:
        return None
    threshold = evidence_threshold(len(pulls) if len(pulls) >= 2 else None)
    prior = np.zeros((m, m)) if prior is None else prior
    return ImuModelError(sensor, estimate, covariance, statistic, threshold, -Y[system.key_columns(keys)], prior)


def _widened(model: np.ndarray, robust_score: np.ndarray | None, inverse: np.ndarray) -> np.ndarray:
    """The estimate's covariance under the noise model, widened by the cluster-robust one of its score."""
    return model if robust_score is None else widen(model, inverse @ robust_score @ inverse)


def evidence_threshold(windows: int | None) -> float:
    """The statistic an ideal sensor exceeds with probability ``FALSE_ALARM``: chi-square with 6 degrees of freedom
    under the noise model, Hotelling's ``T^2`` where the covariance is the cluster-robust one of ``windows``
    windows (estimated from them, so with heavier tails: 31.7 for 40 windows, 20 s, against chi-square's 22.5)."""
    p, level = len(GYRO.entries), 1.0 - FALSE_ALARM
    if windows is None:
        return float(2.0 * gammaincinv(p / 2, level))  # chi-square's quantile
    if windows <= p:
        return float("inf")  # too few windows to tell a scale from the noise
    # F(p, C - p)'s quantile through the regularised incomplete beta function (scipy.stats costs 0.3 s to import)
    x = betaincinv(p / 2, (windows - p) / 2, level)
    quantile = (windows - p) * x / (p * (1.0 - x)) if x < 1.0 else float("inf")
    return float(p * (windows - 1) / (windows - p) * quantile)


def mean_readings(t: np.ndarray, readings: np.ndarray, state_times: np.ndarray) -> np.ndarray:
    """(S - 1, 3) the mean raw reading between consecutive states (trapezoid integral)."""
    integral = interpolate(t, cumulative_angle(t, readings), state_times)
    return np.diff(integral, axis=0) / np.diff(state_times)[:, None]


def reading_jacobian(factor, A: np.ndarray, mean_reading: np.ndarray, bias_columns: np.ndarray) -> np.ndarray:
    """(15, 6) the IMU factor's whitened error per unit of a sensor's entries, to first order in the changes
    within the interval: correcting the readings by ``M`` changes them by ``-E_j w`` (``E_j`` the entry's unit
    matrix, ``w`` the reading), which the preintegration sees as a bias of ``+E_j w_mean``: the factor's Jacobian
    on the sensor's first bias (``bias_columns``), without the bias random walk's rows (a reading does not move
    the bias)."""
    R = factor.noiseModel().R()
    on_bias = scipy.linalg.solve_triangular(R, A[:, bias_columns], lower=False)  # unwhitened (15, 3)
    on_bias[PREINTEGRATED_ROWS:] = 0.0
    w = mean_reading
    changes = np.array([[w[0], 0, 0], [0, w[1], 0], [0, 0, w[2]], [0, w[0], 0], [0, 0, w[0]], [0, 0, w[1]]]).T
    return R @ (on_bias @ changes)


def imu_model_warnings(found: list[ImuModelError]) -> list[str]:
    """A note per sensor whose residuals show scales or misalignments, with the values they show."""
    return [_warning(f) for f in found if f.significant]


def _warning(found: ImuModelError) -> str:
    sigma = np.sqrt(np.diag(found.covariance))
    names = ImuIntrinsics.parameter_names()
    sensor = found.sensor
    scales = ", ".join(
        f"{names[e].removeprefix(sensor.key + '_scale_')} {100 * v:+.2f} +- {100 * s:.2f} %"
        for e, v, s in zip(sensor.entries[:3], found.estimate[:3], sigma[:3], strict=True)
    )
    shears = ", ".join(
        f"{names[e].removeprefix(sensor.key + '_misalign_')} {np.degrees(v):+.2f} +- {np.degrees(s):.2f} deg"
        for e, v, s in zip(sensor.entries[3:], found.estimate[3:], sigma[3:], strict=True)
    )
    return (
        f"the {sensor.name} reads with a scale and axis misalignment that the calibrated IMU model does not have "
        f"(scales {scales}; misalignments {shears}; test statistic {found.statistic:.1f}, above the "
        f"{found.threshold:.1f} an ideal {sensor.name} exceeds once in {1 / FALSE_ALARM:.0f} recordings): the "
        "extrinsic absorbs it as far as the motion excites each axis, and the 1-sigma include what it can shift the "
        "estimates by. --imu-model scale-misalignment estimates it, given rotations about every axis and several "
        "orientations of the sensor"
    )
