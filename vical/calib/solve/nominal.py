"""The nominal camera-IMU rig: the initial extrinsic guess when the caller gives none.

The IMU sits in the camera body frame (x forward, y left, z up) at ``(0.06, 0, -0.10)`` m with
roll = pitch = 0 and yaw = 1.57 rad (``euler_to_matrix``, ``Rz(yaw) Ry(pitch) Rx(roll)``): the
mean of the sensors the simulator samples. ``T_cam_imu = T_cam_body @ T_body_imu`` with the fixed
optical-from-body rotation of ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from vical.geometry import cam_imu_from_body_imu, euler_to_matrix, make_transform

NOMINAL_IMU_POSITION_BODY = np.array([0.06, 0.0, -0.10])  # [m] IMU origin in the camera body frame
NOMINAL_IMU_RPY_BODY = np.array([0.0, 0.0, 1.57])  # [rad] roll, pitch, yaw of the IMU in the body frame


def nominal_T_cam_imu(
    position_body: np.ndarray = NOMINAL_IMU_POSITION_BODY, rpy_body: np.ndarray = NOMINAL_IMU_RPY_BODY
) -> np.ndarray:
    """(4, 4) ``T_cam_imu`` of an IMU at ``position_body`` [m], Euler angles ``rpy_body`` [rad], in the camera body."""
    T_body_imu = make_transform(euler_to_matrix(np.asarray(rpy_body, float)), np.asarray(position_body, float))
    return cam_imu_from_body_imu(T_body_imu)
