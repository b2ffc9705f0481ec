"""The gyro's scale and axis misalignment, which the default IMU model (``calibrated``) does not have: tested for at
the solution, and where the data show them, their effect on the estimates counted in their uncertainty.

A real gyro reads its rates scaled and sheared by a few tenths of a percent (``vical.data.imu_model``: ``M_g``).
The ``calibrated`` model takes the readings as exact up to noise and bias, so the extrinsic rotation absorbs the
part of ``M_g`` that the motion excites, and windows of one recording that turn about different axes land on
different rotations: on the real dev set the three 10 s windows' rot_x drifted by 4 of their sigmas, and with the
gyro corrected by the scales and misalignment that ``--imu-model scale-misalignment`` found on 30 s they agreed
(docs/calibration.md, "Real data"). Estimating ``M_g`` in every solve is slow (a re-preintegration per IMU factor
and parameter at every linearisation) and short recordings do not excite it; so the solve keeps the
``calibrated`` model, and ``gyro_model_error`` asks the data, at the solution, whether they show ``M_g``:

- ``B``, the whitened IMU residuals' Jacobian on the six entries of ``M_g`` (three scales, three
  misalignments: Kalibr's lower-triangular gyro ``M``), from each factor's Jacobian on its gyro bias
  (``reading_jacobian``; the forward differences over re-preintegrations it replaces agree to 1e-4 in the
  test statistic on the real dev set, at a fifth of the time);
- the step a Gauss-Newton solve with ``M_g`` free would take from ``M_g = I`` with every other variable
  profiled out (the Schur complement of the linearised system), its covariance under the measured noise
  levels widened by its cluster-robust one (``vical.calib.solve.robust_covariance``), and the score
  statistic ``theta^T Sigma^-1 theta`` (Hotelling's ``T^2`` over the windows where the gyro has no such
  error: ``evidence_threshold``);
- where that statistic passes the 1-in-1000 level (``FALSE_ALARM``), the estimates stay as solved (the
  references a user compares with are calibrated with the ``calibrated`` model too) and their covariance
  gains ``S (theta theta^T + Sigma) S^T``, ``S`` their first-order shift per unit of ``M_g``: the expected
  square of the error the unmodelled gyro leaves in them. Below that level nothing changes: an ideal gyro's
  results keep their uncertainty.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
import scipy.linalg
from scipy.special import betaincinv, gammaincinv

from vical.calib.solve.imu_integration import cumulative_angle, interpolate
from vical.calib.solve.robust_covariance import LinearSystem, cluster_robust, widen
from vical.data.imu_model import ImuIntrinsics

FIRST_GYRO_BIAS = np.arange(21, 24)  # an IMU factor's columns: poses and velocities (18), first bias (acc, gyro)
PREINTEGRATED_ROWS = 9  # its error: rotation, position, velocity, then the biases' random walk
GYRO_ENTRIES = np.arange(6, 12)  # the gyro's scales and misalignments in ImuIntrinsics.vector
FALSE_ALARM = 0.001  # how often an ideal gyro is called scaled


@dataclass(frozen=True)
class GyroModelError:
    """What the residuals say of the gyro's scales and misalignments (``GYRO_ENTRIES``).

    Attributes:
        estimate: (6,) the step from the ideal gyro: scales - 1 (x, y, z), misalignments (yx, zx, zy) [rad].
        covariance: (6, 6) its covariance.
        statistic: ``estimate^T covariance^-1 estimate``.
        threshold: the statistic an ideal gyro exceeds with probability ``FALSE_ALARM`` (``evidence_threshold``).
        sensitivity: (K, 6) the first-order shift of the solve's variables (the keys' tangent columns) per unit of
            the gyro's entries, were they corrected.
    """

    estimate: np.ndarray
    covariance: np.ndarray
    statistic: float
    threshold: float
    sensitivity: np.ndarray

    @property
    def significant(self) -> bool:
        return self.statistic > self.threshold

    def considered(self) -> np.ndarray:
        """(K, K) the covariance its effect adds to the solve's variables (zero where not significant)."""
        if not self.significant:
            return np.zeros((len(self.sensitivity),) * 2)
        spread = np.outer(self.estimate, self.estimate) + self.covariance
        return self.sensitivity @ spread @ self.sensitivity.T


def gyro_model_error(
    system: LinearSystem,
    linear: gtsam.GaussianFactorGraph,
    values: gtsam.Values,
    imu_factors: list,
    state_times: np.ndarray,
    imu: tuple[np.ndarray, np.ndarray],
    keys: list[int],
) -> GyroModelError | None:
    """Test the solution of a ``calibrated``-model graph for the gyro's scales and misalignments.

    Args:
        system: the graph's normal equations at the solution (``LinearSystem``; its factors in the graph's order).
        linear: the graph linearised at the solution; values: the solution.
        imu_factors: the graph's IMU factors ``(n, factor, dt)`` (graph factors 0..N-1, factor n between states
            n and n + 1 at ``state_times`` (S,) [s], IMU clock).
        imu: the IMU samples the factors were preintegrated from: t (N,) [s], gyro (N, 3) [rad/s].
        keys: the variables whose sensitivity is wanted.

    Returns:
        None where the information is singular.
    """
    if system.singular or not imu_factors:
        return None
    P, m = system.size, len(GYRO_ENTRIES)
    C, Cs = np.zeros((P, m)), np.zeros((P, m))  # A^T B and sum_k s_k A_k^T B_k
    BtB, BtBs, Btb = np.zeros((m, m)), np.zeros((m, m)), np.zeros(m)
    window_pulls = np.zeros((system.gradients.shape[1], m))
    mean_rates = _mean_rates(imu[0], imu[1], state_times)
    for n, factor, _ in imu_factors:
        A, b = linear.at(n).jacobian()
        B = reading_jacobian(factor, A, mean_rates[n])
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
    Y = system.solve(C)  # H^-1 C: the other variables' shift per unit of the gyro's entries
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
    # gyro's true scale would inflate its own yardstick).
    tested = _widened(model, cluster_robust(pulls - pulls.mean(axis=0)), inverse)
    try:
        statistic = float(estimate @ np.linalg.solve(tested, estimate))
    except np.linalg.LinAlgError:
        return None
    threshold = evidence_threshold(len(pulls) if len(pulls) >= 2 else None)
    return GyroModelError(estimate, covariance, statistic, threshold, -Y[system.key_columns(keys)])


def _widened(model: np.ndarray, robust_score: np.ndarray | None, inverse: np.ndarray) -> np.ndarray:
    """The estimate's covariance under the noise model, widened by the cluster-robust one of its score."""
    return model if robust_score is None else widen(model, inverse @ robust_score @ inverse)


def evidence_threshold(windows: int | None) -> float:
    """The statistic an ideal gyro exceeds with probability ``FALSE_ALARM``: chi-square with 6 degrees of freedom
    under the noise model, Hotelling's ``T^2`` where the covariance is the cluster-robust one of ``windows``
    windows (estimated from them, so with heavier tails: 31.7 for 40 windows, 20 s, against chi-square's 22.5)."""
    p, level = len(GYRO_ENTRIES), 1.0 - FALSE_ALARM
    if windows is None:
        return float(2.0 * gammaincinv(p / 2, level))  # chi-square's quantile
    if windows <= p:
        return float("inf")  # too few windows to tell a scale from the noise
    # F(p, C - p)'s quantile through the regularised incomplete beta function (scipy.stats costs 0.3 s to import)
    x = betaincinv(p / 2, (windows - p) / 2, level)
    quantile = (windows - p) * x / (p * (1.0 - x)) if x < 1.0 else float("inf")
    return float(p * (windows - 1) / (windows - p) * quantile)


def _mean_rates(t: np.ndarray, gyro: np.ndarray, state_times: np.ndarray) -> np.ndarray:
    """(S - 1, 3) [rad/s] the mean raw gyro reading between consecutive states (trapezoid integral)."""
    angle = interpolate(t, cumulative_angle(t, gyro), state_times)
    return np.diff(angle, axis=0) / np.diff(state_times)[:, None]


def reading_jacobian(factor, A: np.ndarray, mean_rate: np.ndarray) -> np.ndarray:
    """(15, 6) the IMU factor's whitened error per unit of the gyro's entries, to first order in the rotation
    within the interval: correcting the readings by ``M_g`` changes them by ``-E_j w`` (``E_j`` the entry's unit
    matrix), which the preintegration sees as a gyro bias of ``+E_j w_mean``: the factor's Jacobian on its first
    gyro bias, without the bias random walk's rows (a reading does not move the bias)."""
    R = factor.noiseModel().R()
    on_bias = scipy.linalg.solve_triangular(R, A[:, FIRST_GYRO_BIAS], lower=False)  # unwhitened (15, 3)
    on_bias[PREINTEGRATED_ROWS:] = 0.0
    w = mean_rate
    changes = np.array([[w[0], 0, 0], [0, w[1], 0], [0, 0, w[2]], [0, w[0], 0], [0, 0, w[0]], [0, 0, w[1]]]).T
    return R @ (on_bias @ changes)


def gyro_model_warning(found: GyroModelError | None) -> list[str]:
    """A note when the residuals show the gyro's scales or misalignments, with the values they show."""
    if found is None or not found.significant:
        return []
    sigma = np.sqrt(np.diag(found.covariance))
    names = ImuIntrinsics.parameter_names()
    scales = ", ".join(
        f"{names[e].removeprefix('gyro_scale_')} {100 * v:+.2f} +- {100 * s:.2f} %"
        for e, v, s in zip(GYRO_ENTRIES[:3], found.estimate[:3], sigma[:3], strict=True)
    )
    shears = ", ".join(
        f"{names[e].removeprefix('gyro_misalign_')} {np.degrees(v):+.2f} +- {np.degrees(s):.2f} deg"
        for e, v, s in zip(GYRO_ENTRIES[3:], found.estimate[3:], sigma[3:], strict=True)
    )
    return [
        f"the gyro reads with a scale and axis misalignment that the calibrated IMU model does not have (scales "
        f"{scales}; misalignments {shears}; test statistic {found.statistic:.1f}, above the {found.threshold:.1f} an "
        f"ideal gyro exceeds once in {1 / FALSE_ALARM:.0f} recordings): the extrinsic rotation absorbs it as far as "
        "the motion turns about each axis, and the 1-sigma include what it can shift the estimates by. "
        "--imu-model scale-misalignment estimates it, given rotations about every axis and several orientations of "
        "the sensor"
    ]
