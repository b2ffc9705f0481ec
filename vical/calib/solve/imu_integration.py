"""IMU integration between arbitrary instants: midpoint segments, GTSAM preintegration, gyro angles.

Times here are float seconds relative to the recording start (IMU clock). Samples are linearly
interpolated at the interval ends so states can sit at camera times that fall between samples.
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


def midpoint_segments(
    t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, ta: float, tb: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Constant-rate segments covering ``[ta, tb]`` [s] for integration.

    Each segment between consecutive knots (``ta``, the samples inside, ``tb``) uses the mean
    angular rate and the rotation-compensated mean specific force ``(a0 + Exp(w dt) a1) / 2``,
    expressed at the segment start (second order, unlike the left-rectangle rule).

    Returns:
        dt (S,) [s], omega (S, 3) [rad/s], acc (S, 3) [m/s^2].
    """
    inside = t[(t > ta) & (t < tb)]
    knots = np.concatenate([[ta], inside, [tb]])
    return knot_segments(knots, interpolate(t, gyro, knots), interpolate(t, accel, knots))


def knot_segments(knots: np.ndarray, w: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``midpoint_segments`` of readings ``w`` (K, 3) [rad/s], ``a`` (K, 3) [m/s^2] at the times ``knots`` (K,) [s]."""
    dt = np.diff(knots)
    omega = 0.5 * (w[:-1] + w[1:])
    R = batch_so3_exp(omega * dt[:, None])
    acc = 0.5 * (a[:-1] + np.einsum("nij,nj->ni", R, a[1:]))
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
    """Preintegrated measurements of ``midpoint_segments`` output about the bias estimate ``bias``."""
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
