"""Pure geometry: rigid transforms, rotation parameterisations and camera models."""

from vical.geometry.camera import CAMERA_MODELS, COEFFICIENT_NAMES, DISTORTION_MODELS, CameraModel, CameraModelError
from vical.geometry.frames import R_CAM_BODY, T_CAM_BODY, body_imu_from_cam_imu, cam_imu_from_body_imu
from vical.geometry.transforms import (
    euler_to_matrix,
    interpolate_transform,
    invert_transform,
    make_transform,
    matrix_to_euler,
    matrix_to_quat,
    quat_to_matrix,
    rotation_angle,
    skew,
    slerp_rotation,
    so3_exp,
    so3_log,
    step_pose,
    transform_error,
    transform_points,
)

__all__ = [
    "CAMERA_MODELS",
    "COEFFICIENT_NAMES",
    "DISTORTION_MODELS",
    "R_CAM_BODY",
    "T_CAM_BODY",
    "CameraModel",
    "CameraModelError",
    "body_imu_from_cam_imu",
    "cam_imu_from_body_imu",
    "euler_to_matrix",
    "interpolate_transform",
    "invert_transform",
    "make_transform",
    "matrix_to_euler",
    "matrix_to_quat",
    "quat_to_matrix",
    "rotation_angle",
    "skew",
    "slerp_rotation",
    "so3_exp",
    "so3_log",
    "step_pose",
    "transform_error",
    "transform_points",
]
