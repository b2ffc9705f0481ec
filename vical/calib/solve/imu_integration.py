"""IMU integration between arbitrary instants: Simpson segments of the motion's cubic interpolant from the
readings (interval means), GTSAM preintegration, gyro angles.

Times here are float seconds relative to the recording start (IMU clock). Readings are interpolated at the
interval ends so states can sit at camera times that fall between samples.
"""

from __future__ import annotations

import gtsam
import numpy as np

from vical.data import ImuNoise

INTEGRATION_SIGMA = 1e-4  # [m/s^2/sqrt(Hz)] integration noise: position from velocity is nearly exact


def batch_so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of rotation vectors (N, 3) [rad] (Rodrigues, series for tiny angles)."""
    theta = np.linalg.norm(w, axis=1)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


def interpolate(t: np.ndarray, x: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """Linear interpolation of samples ``x`` (N, D) at times ``t`` (N,) [s] to query times ``tq`` (Q,)."""
    j = np.clip(np.searchsorted(t, tq) - 1, 0, len(t) - 2)
    s = ((tq - t[j]) / (t[j + 1] - t[j]))[:, None]
    return x[j] * (1.0 - s) + x[j + 1] * s


def cubic_interpolate(t: np.ndarray, x: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """Point values ``x`` (N, D) at times ``t`` (N,) [s] at query times ``tq`` (Q,): the cubic through the four
    samples around each query's sample interval (Lagrange; any spacing), linear for fewer than four samples."""
    if len(t) < 4:
        return interpolate(t, x, tq)
    j = _stencils(t, tq)
    return np.einsum("qi,qid->qd", _lagrange_weights(t[j], tq), x[j])


def reading_interpolant(t: np.ndarray, x: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """The motion (Q, D) at query times ``tq`` (Q,) [s] that IMU readings ``x`` (N, D) at times ``t`` (N,) [s]
    sampled: the ``cubic_interpolate`` of their ``point_values``.

    Why a cubic and why the point values: integrating the linear interpolant of the readings (the trapezoid rule)
    shrinks a motion of frequency f sampled every h by (2 pi f h)^2 / 12 and taking interval means for point values
    by another (2 pi f h)^2 / 24 (0.8 % and 0.4 % for a hand's 10 Hz tremor at 200 Hz), errors the motion's
    amplitude scales and the extrinsic's translation absorbs; these are of fourth order.
    """
    if len(t) < 4:
        return interpolate(t, x, tq)
    return cubic_interpolate(t, point_values(x), tq)


def point_values(x: np.ndarray) -> np.ndarray:
    """The motion (N, D) at the stamps of readings ``x`` (N, D), each the motion's mean over its sample interval
    centred on its stamp (an IMU's decimation filter: EuRoC's ADIS16448 averages its internal 819.2 Hz samples):
    ``x_k - (x_{k+1} - 2 x_k + x_{k-1}) / 24`` to fourth order; the first and last reading keep their value. The
    correction sums to the readings' own integral over whole intervals, so it adds no noise to it."""
    points = x.copy()
    points[1:-1] -= (x[2:] - 2.0 * x[1:-1] + x[:-2]) / 24.0
    return points


def _stencils(t: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """(Q, 4) indices of the four samples around each query's sample interval (clamped at the ends)."""
    first = np.clip(np.searchsorted(t, tq) - 2, 0, len(t) - 4)
    return first[:, None] + np.arange(4)


def _lagrange_weights(nodes: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """(Q, 4) weights of the cubic through ``nodes`` (Q, 4) [s] at ``tq`` (Q,)."""
    weights = np.ones((len(tq), 4))
    for i in range(4):
        for m in range(4):
            if m != i:
                weights[:, i] *= (tq - nodes[:, m]) / (nodes[:, i] - nodes[:, m])
    return weights


def interval_knots(t: np.ndarray, ta: float, tb: float) -> np.ndarray:
    """Knots (4 S + 1,) [s] integrating ``[ta, tb]``: its ends and the samples inside cut it into S pieces,
    each cut into quarters (two Simpson steps per piece)."""
    return _quarters(_piece_ends(t, np.array([ta, tb])))


def readings_around(t: np.ndarray, ta: float, tb: float) -> slice:
    """The readings ``reading_interpolant`` needs for queries in ``[ta, tb]`` [s]: the cubics' four and their
    neighbours (a recording's IMU grows with it; the information state integrates one frame's interval at a time)."""
    return slice(max(int(np.searchsorted(t, ta)) - 3, 0), min(int(np.searchsorted(t, tb)) + 3, len(t)))


def _piece_ends(t: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The increasing ``times`` [s] and the sample times ``t`` between the first and the last, sorted, once each."""
    return np.union1d(t[(t > times[0]) & (t < times[-1])], times)


def _quarters(ends: np.ndarray) -> np.ndarray:
    quarters = ends[:-1, None] + np.diff(ends)[:, None] * np.arange(4) / 4.0
    return np.append(quarters.ravel(), ends[-1])


def interval_segments(
    t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, ta: float, tb: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Constant-rate segments covering ``[ta, tb]`` [s] for integration: ``knot_segments`` of the motion's
    ``reading_interpolant`` at ``interval_knots``."""
    return segments_between(t, gyro, accel, np.array([ta, tb]))[0]


def segments_between(
    t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, times: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``interval_segments`` of every interval between consecutive increasing ``times`` (S,) [s] (S - 1 of
    them), computed in one pass."""
    w = readings_around(t, times[0], times[-1])
    t, gyro, accel = t[w], gyro[w], accel[w]
    ends = _piece_ends(t, times)
    knots = _quarters(ends)
    dt, omega, acc = knot_segments(knots, reading_interpolant(t, gyro, knots), reading_interpolant(t, accel, knots))
    cuts = 2 * np.searchsorted(ends, times[1:-1])  # two segments per piece between ends
    return list(zip(np.split(dt, cuts), np.split(omega, cuts), np.split(acc, cuts), strict=True))


def knot_segments(knots: np.ndarray, w: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments of readings ``w`` (K, 3) [rad/s], ``a`` (K, 3) [m/s^2] at ``interval_knots`` ``knots`` (K,) [s].

    Each pair of knot intervals is one segment with Simpson's means: the angular rate's, and the specific
    force's rotated into the segment's start by the mean rate (exact for a cubic reading over a steady
    turn; GTSAM holds each segment's values constant, which leaves a position error of the segment's length
    squared times the change of the acceleration over the whole interval, / 12).

    Returns:
        dt (S,) [s], omega (S, 3) [rad/s], acc (S, 3) [m/s^2].
    """
    start, mid, end = slice(0, -2, 2), slice(1, -1, 2), slice(2, None, 2)
    dt = knots[end] - knots[start]
    omega = (w[start] + 4.0 * w[mid] + w[end]) / 6.0
    half = batch_so3_exp(omega * (0.5 * dt)[:, None])
    full = half @ half
    acc = (a[start] + 4.0 * np.einsum("nij,nj->ni", half, a[mid]) + np.einsum("nij,nj->ni", full, a[end])) / 6.0
    return dt, omega, acc


def preintegration_params(noise: ImuNoise) -> gtsam.PreintegrationCombinedParams:
    """GTSAM parameters from Kalibr's continuous-time densities (gravity is set by the factor)."""
    p = gtsam.PreintegrationCombinedParams.MakeSharedU(9.81)
    p.setGyroscopeCovariance(np.eye(3) * noise.gyro_noise_density**2)  # [(rad/s)^2 / Hz]
    p.setAccelerometerCovariance(np.eye(3) * noise.accel_noise_density**2)  # [(m/s^2)^2 / Hz]
    p.setBiasOmegaCovariance(np.eye(3) * noise.gyro_random_walk**2)  # [(rad/s^2)^2 / Hz]
    p.setBiasAccCovariance(np.eye(3) * noise.accel_random_walk**2)  # [(m/s^3)^2 / Hz]
    p.setIntegrationCovariance(np.eye(3) * INTEGRATION_SIGMA**2)
    return p


def preintegrate(
    params: gtsam.PreintegrationCombinedParams,
    bias: gtsam.imuBias.ConstantBias,
    segments: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> gtsam.PreintegratedCombinedMeasurements:
    """Preintegrated measurements of ``interval_segments`` output about the bias estimate ``bias``."""
    pim = gtsam.PreintegratedCombinedMeasurements(params, bias)
    for dt, w, a in zip(*segments, strict=True):
        if dt > 0:
            pim.integrateMeasurement(a, w, dt)
    return pim


def cumulative_angle(t: np.ndarray, gyro: np.ndarray) -> np.ndarray:
    """Running integral (N, 3) [rad] of the angular rate (trapezoid rule), zero at the first sample.

    Differences of it approximate rotation vectors over short windows (first order: good for a
    time-offset scan, not for the final estimate).
    """
    steps = 0.5 * (gyro[1:] + gyro[:-1]) * np.diff(t)[:, None]
    return np.vstack([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
