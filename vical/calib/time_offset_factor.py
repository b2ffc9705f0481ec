"""The one Python factor per frame that carries the camera-IMU time offset.

The IMU state ``X_i`` (pose in the target frame) sits at IMU time ``s_i = t_cam_i + tau0``; the
frame was exposed at ``t_cam_i + tau0 + delta``. Its pose there, ``P_i``, follows from the body
twist (angular rate ``omega_i`` from the gyro, linear ``R_i^T v_i``) to first order in ``delta``::

    P_i = X_i * Exp([omega_i; R_i^T v_i] * delta)

(the neglected ``0.5 a delta^2`` is 5 um at 1 ms). All projection factors attach to ``P_i`` and
stay C++; only this factor (one per frame) runs in Python.
"""

from __future__ import annotations

import gtsam
import numpy as np

TIE_SIGMA = 1e-5  # [rad, m] tightness of the tie between the exposure pose and the shifted state


def _error(omega: np.ndarray, this: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None) -> np.ndarray:
    key_p, key_x, key_v, key_d = this.keys()
    P, X = values.atPose3(key_p), values.atPose3(key_x)
    v, delta = values.atVector(key_v), float(values.atVector(key_d)[0])
    R = X.rotation().matrix()
    xi = np.concatenate([omega, R.T @ v])
    E = gtsam.Pose3.Expmap(xi * delta)
    error = gtsam.Pose3.Logmap(X.compose(E).between(P))
    if jacobians is not None:
        # First-order Jacobians (exact at zero error, where the solution lies).
        jacobians[0] = np.eye(6)
        jacobians[1] = -E.inverse().AdjointMap()
        jv = np.zeros((6, 3))
        jv[3:] = -R.T * delta
        jacobians[2] = jv
        jacobians[3] = -xi.reshape(6, 1)
    return error


def time_offset_factor(key_exposure: int, key_state: int, key_velocity: int, key_delta: int, omega: np.ndarray):
    """``CustomFactor`` tying the exposure pose to the IMU state shifted by the time-offset correction.

    Args:
        key_exposure, key_state: ``Pose3`` keys (IMU pose at exposure, IMU state pose).
        key_velocity: ``Vector3`` key [m/s] (target frame); key_delta: ``Vector1`` key [s].
        omega: (3,) [rad/s] bias-corrected gyro rate at the state time, IMU frame.
    """
    omega = np.asarray(omega, dtype=float).copy()
    noise = gtsam.noiseModel.Isotropic.Sigma(6, TIE_SIGMA)
    keys = [key_exposure, key_state, key_velocity, key_delta]
    return gtsam.CustomFactor(noise, keys, lambda this, values, jac: _error(omega, this, values, jac))
