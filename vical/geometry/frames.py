"""Fixed frame relations of the sensor rig (docs/conventions.md).

The camera body frame (``cam_body``: x forward along the optical axis, y left, z up, the
Gazebo/ROS convention of the paper's extrinsic distribution) and the optical frame (``cam``:
OpenCV/Kalibr, z along the optical axis, x right, y down) share their origin.
"""

from __future__ import annotations

import numpy as np

from vical.geometry.camera import CameraModel
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


def camera_frame_turn(source: CameraModel, target: CameraModel, grid: int = 21) -> np.ndarray:
    """The rotation (3, 3) that best carries ``source``'s camera frame onto ``target``'s for the same pixels:
    ``target ray ~ R @ source ray`` over a ``grid`` x ``grid`` spread of the image (Kabsch, unit rays).

    Two calibrations of one camera with different principal points put its frame's axes in different directions
    (1 px is about 1/f rad), so an extrinsic from one pairs with the other only after this turn:
    ``T_cam_imu`` in ``target``'s frame is ``make_transform(R, 0) @ T_cam_imu`` in ``source``'s.
    """
    u, v = np.meshgrid(np.linspace(0.05, 0.95, grid) * source.width, np.linspace(0.05, 0.95, grid) * source.height)
    pixels = np.c_[u.ravel(), v.ravel()]
    a, ok_a = source.bearings(pixels)
    b, ok_b = target.bearings(pixels)
    ok = ok_a & ok_b
    U, _, Vt = np.linalg.svd(b[ok].T @ a[ok])
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
