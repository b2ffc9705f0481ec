"""Calibration of a camera + IMU from target observations and IMU samples (GTSAM factor graphs).

Never imports the simulator or the environment: it calibrates real recordings.
"""

from vical.calib.detection import detect_checkerboard
from vical.calib.errors import CalibrationError
from vical.calib.intrinsics import calibrate_intrinsics
from vical.calib.metrics import CalibrationErrors, calibration_errors
from vical.calib.nominal import nominal_T_cam_imu
from vical.calib.pipeline import calibrate_extrinsics, calibrate_joint, calibrate_two_stage
from vical.calib.result import CalibrationResult, ImuResiduals, ResidualStats, WeakParameter
from vical.calib.visual_inertial import ViOptions

__all__ = [
    "CalibrationError",
    "CalibrationErrors",
    "CalibrationResult",
    "ImuResiduals",
    "ResidualStats",
    "ViOptions",
    "WeakParameter",
    "calibrate_extrinsics",
    "calibrate_intrinsics",
    "calibrate_joint",
    "calibrate_two_stage",
    "calibration_errors",
    "detect_checkerboard",
    "nominal_T_cam_imu",
]
