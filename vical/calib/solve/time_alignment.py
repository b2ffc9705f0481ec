"""Closed-form start for camera-IMU calibration: time offset, rotation and gyro bias.

The camera's rotation increments between consecutive frames (from PnP) must equal the gyro's
integrated over the same interval shifted by the time offset ``tau`` (``t_imu = t_cam + tau``),
rotated by ``R_cam_imu``: ``theta_cam = R_cam_imu (Theta_imu(t + tau) - b dt)``.

1. Scan ``tau`` on a 1 ms grid with a rotation-free cost (increment magnitudes agree), refine by
   a parabola through the best grid point and its neighbours.
2. ``R_cam_imu`` by Kabsch (SVD) on the increment pairs, the gyro bias by linear least squares.
3. Refine ``tau`` with the full vector cost on a 0.1 ms grid, then Kabsch and bias again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vical.calib.errors import CalibrationError, CalibrationSettingError
from vical.calib.solve.imu_integration import cumulative_angle, interpolate
from vical.geometry import so3_log

MAX_INCREMENT_GAP = 0.35  # [s] frame pairs further apart are not used (rotation may exceed pi, PnP gaps)
MIN_ROTATION_EXCITATION = 0.1  # [rad] root-sum-square of gyro increments about the second-strongest axis
COARSE_STEP = 1e-3  # [s]
FINE_STEP = 1e-4  # [s]
FINE_HALF_WIDTH = 3e-3  # [s]


@dataclass(frozen=True)
class RotationIncrements:
    """Camera rotation increments between consecutive frames.

    Attributes:
        t_start, t_end: (M,) [s] frame times (camera clock) of each increment.
        theta_cam: (M, 3) [rad] rotation vectors ``log(R_target_cam(t_start)^T R_target_cam(t_end))``.
    """

    t_start: np.ndarray
    t_end: np.ndarray
    theta_cam: np.ndarray


@dataclass(frozen=True)
class Alignment:
    """Result of the closed-form alignment.

    Attributes:
        time_offset: [s] ``tau`` with ``t_imu = t_cam + tau``.
        R_cam_imu: (3, 3) rotation of the extrinsic.
        gyro_bias: (3,) [rad/s].
        rms: [rad] RMS of the remaining increment mismatch.
    """

    time_offset: float
    R_cam_imu: np.ndarray
    gyro_bias: np.ndarray
    rms: float


def rotation_increments(times: np.ndarray, R_target_cam: np.ndarray) -> RotationIncrements:
    """Increments between consecutive frames (times (N,) [s], rotations (N, 3, 3)) closer than ``MAX_INCREMENT_GAP``."""
    keep = np.flatnonzero(np.diff(times) <= MAX_INCREMENT_GAP)
    theta = np.array([so3_log(R_target_cam[k].T @ R_target_cam[k + 1]) for k in keep]).reshape(-1, 3)
    return RotationIncrements(times[keep], times[keep + 1], theta)


def _gyro_increments(t_imu, angle, inc: RotationIncrements, taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First-order gyro increments (G, M, 3) [rad] for each shift in ``taus`` (G,), and a validity mask (G, M)."""
    ta = inc.t_start[None, :] + taus[:, None]
    tb = inc.t_end[None, :] + taus[:, None]
    valid = (ta >= t_imu[0]) & (tb <= t_imu[-1])
    a = interpolate(t_imu, angle, ta.ravel()).reshape(*ta.shape, 3)
    b = interpolate(t_imu, angle, tb.ravel()).reshape(*tb.shape, 3)
    return b - a, valid


def _parabola_minimum(x: np.ndarray, cost: np.ndarray) -> float:
    """Minimiser of the parabola through the best grid point and its neighbours (the grid point at an edge)."""
    k = int(np.nanargmin(cost))
    if k == 0 or k == len(cost) - 1 or not np.all(np.isfinite(cost[k - 1 : k + 2])):
        return float(x[k])
    c0, c1, c2 = cost[k - 1 : k + 2]
    denom = c0 - 2.0 * c1 + c2
    shift = 0.5 * (c0 - c2) / denom if denom > 0 else 0.0
    return float(x[k] + np.clip(shift, -1.0, 1.0) * (x[1] - x[0]))


def _masked_mean(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    count = valid.sum(axis=1)
    total = np.where(valid, values, 0.0).sum(axis=1)
    return np.where(count >= 3, total / np.maximum(count, 1), np.nan)


def _kabsch_and_bias(theta_cam: np.ndarray, theta_imu: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``R`` minimising ``sum |theta_cam - R (theta_imu - b dt)|^2`` and the bias ``b``, alternating three times."""
    b = np.zeros(3)
    for _ in range(3):
        H = (theta_imu - b * dt[:, None]).T @ theta_cam
        U, _, Vt = np.linalg.svd(H)
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
        R = Vt.T @ D @ U.T
        resid = theta_imu - theta_cam @ R  # = b dt in the IMU frame
        b = (dt @ resid) / (dt @ dt)
    return R, b


def check_rotation_excitation(
    t_imu: np.ndarray, gyro: np.ndarray, inc: RotationIncrements, offset_guess: float = 0.0
) -> None:
    """Raise when the motion rotates about fewer than two axes (the extrinsic is then unobservable).

    The gyro is read over the frame pairs shifted by ``offset_guess`` [s], where the scan starts.
    """
    angle = cumulative_angle(t_imu, gyro)
    d, valid = _gyro_increments(t_imu, angle, inc, np.array([offset_guess]))
    d = d[0][valid[0]]
    s = np.sqrt(np.linalg.svd(d.T @ d, compute_uv=False)) if len(d) else np.zeros(3)
    if s[1] < MIN_ROTATION_EXCITATION:
        raise CalibrationError(
            f"the motion does not rotate enough about two independent axes (excitation {s[1]:.3f} rad about the "
            f"second axis, need > {MIN_ROTATION_EXCITATION} rad): the camera-IMU rotation and lever arm are not "
            "observable; rotate the sensor about at least two axes while the target is in view"
        )


def align(
    t_imu: np.ndarray,
    gyro: np.ndarray,
    inc: RotationIncrements,
    max_offset: float,
    offset_guess: float = 0.0,
    estimate_offset: bool = True,
) -> Alignment:
    """Time offset, ``R_cam_imu`` and gyro bias from camera rotation increments and the gyro.

    Args:
        t_imu: (N,) [s] IMU sample times; gyro: (N, 3) [rad/s].
        inc: camera rotation increments.
        max_offset: [s] the scan covers ``offset_guess +- max_offset``.
        offset_guess: [s] centre of the scan (the offset itself when ``estimate_offset`` is False).
        estimate_offset: scan and refine the offset; else keep ``offset_guess``.
    """
    if len(inc.t_start) < 3:
        raise CalibrationError(
            "fewer than 3 pairs of consecutive frames with a target pose: the camera-IMU rotation cannot be "
            "initialised; keep the whole target in view for longer stretches of the motion"
        )
    check_rotation_excitation(t_imu, gyro, inc, offset_guess)
    angle = cumulative_angle(t_imu, gyro)
    dt = inc.t_end - inc.t_start
    tau = _scan(t_imu, angle, inc, max_offset, offset_guess) if estimate_offset else float(offset_guess)
    for _ in range(2 if estimate_offset else 0):
        d_imu, keep = _valid_pair(t_imu, angle, inc, tau)
        R, b = _kabsch_and_bias(inc.theta_cam[keep], d_imu[keep], dt[keep])
        tau = _refine(t_imu, angle, inc, tau, R, b)
    d_imu, keep = _valid_pair(t_imu, angle, inc, tau)
    if keep.sum() < 3:
        raise CalibrationError("fewer than 3 frame pairs overlap the IMU samples; the streams barely overlap in time")
    R, b = _kabsch_and_bias(inc.theta_cam[keep], d_imu[keep], dt[keep])
    rms = float(np.sqrt(np.mean(np.sum((inc.theta_cam[keep] - (d_imu[keep] - b * dt[keep, None]) @ R.T) ** 2, 1))))
    return Alignment(tau, R, b, rms)


def _scan(t_imu, angle, inc: RotationIncrements, max_offset: float, offset_guess: float) -> float:
    """Coarse offset from the rotation-free cost: increment magnitudes of camera and gyro agree."""
    taus = offset_guess + np.arange(-max_offset, max_offset + 0.5 * COARSE_STEP, COARSE_STEP)
    d, valid = _gyro_increments(t_imu, angle, inc, taus)
    magnitude_cost = _masked_mean((np.linalg.norm(d, axis=2) - np.linalg.norm(inc.theta_cam, axis=1)) ** 2, valid)
    if not np.any(np.isfinite(magnitude_cost)):
        raise CalibrationSettingError(
            "the camera frames and the IMU samples do not overlap in time for any time offset within "
            f"+-{max_offset * 1e3:.0f} ms; check that both streams are stamped with the same clock, or search "
            "further ({fix})",
            "max_time_offset", f"{2 * max_offset:g}", f"{2 * max_offset:g}",
        )  # fmt: skip
    return _parabola_minimum(taus, magnitude_cost)


def _valid_pair(t_imu, angle, inc: RotationIncrements, tau: float) -> tuple[np.ndarray, np.ndarray]:
    d, valid = _gyro_increments(t_imu, angle, inc, np.array([tau]))
    return np.where(valid[0][:, None], d[0], 0.0), valid[0]


def _vector_cost(t_imu, angle, inc: RotationIncrements, R: np.ndarray, b: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """Mean squared mismatch (G,) [rad^2] of camera and rotated, bias-corrected gyro increments per shift (G,) [s]."""
    d, valid = _gyro_increments(t_imu, angle, inc, taus)
    dt = inc.t_end - inc.t_start
    predicted = (d - b * dt[None, :, None]) @ R.T
    return _masked_mean(np.sum((predicted - inc.theta_cam[None]) ** 2, axis=2), valid)


def _refine(t_imu, angle, inc: RotationIncrements, tau: float, R: np.ndarray, b: np.ndarray) -> float:
    """``tau`` minimising the full vector mismatch on a fine grid around ``tau``."""
    taus = tau + np.arange(-FINE_HALF_WIDTH, FINE_HALF_WIDTH + 0.5 * FINE_STEP, FINE_STEP)
    return _parabola_minimum(taus, _vector_cost(t_imu, angle, inc, R, b, taus))


def increment_mismatch(
    t_imu: np.ndarray, gyro: np.ndarray, inc: RotationIncrements, R_cam_imu: np.ndarray, gyro_bias: np.ndarray,
    taus: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """RMS [rad] (G,) of ``theta_cam - R_cam_imu (Theta_imu(t + tau) - b dt)`` over the increments, per shift
    ``taus`` (G,) [s]; NaN where fewer than 3 increments overlap the IMU samples. Its minimum is the time offset."""
    return np.sqrt(_vector_cost(t_imu, cumulative_angle(t_imu, gyro), inc, R_cam_imu, gyro_bias, taus))
