"""Fixed frame relations of the sensor rig (docs/conventions.md).

The camera body frame (``cam_body``: x forward along the optical axis, y left, z up, the
Gazebo/ROS convention of the paper's extrinsic distribution) and the optical frame (``cam``:
OpenCV/Kalibr, z along the optical axis, x right, y down) share their origin.
"""

from __future__ import annotations

import numpy as np

from vical.geometry.transforms import invert_transform, make_transform

# Body forward -> optical z, body left -> optical -x, body up -> optical -y.
R_CAM_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
T_CAM_BODY = make_transform(R_CAM_BODY, np.zeros(3))


def cam_imu_from_body_imu(T_body_imu: np.ndarray) -> np.ndarray:
    """``T_cam_imu`` (4, 4) of an IMU whose pose in the camera body frame is ``T_body_imu`` (4, 4)."""
    return T_CAM_BODY @ T_body_imu


def body_imu_from_cam_imu(T_cam_imu: np.ndarray) -> np.ndarray:
    """``T_body_imu`` (4, 4) from the camera-IMU extrinsic ``T_cam_imu`` (4, 4)."""
    return invert_transform(T_CAM_BODY) @ T_cam_imu
