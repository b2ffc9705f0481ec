"""Calibration of a camera + IMU from target observations and IMU samples (GTSAM factor graphs).

Never imports the simulator or the environment: it calibrates real recordings. By stage: ``detection`` (the
target in images), ``noise`` (an IMU's noise from a static recording), ``solve`` (the pipeline and its graphs),
``report`` (the outputs people read); the typed result (``result``, ``frame_log``), the errors against the truth
(``metrics``), the paper's tasks (``tasks``) and synthetic recordings (``synthetic``) beside them.
"""

from vical.calib.detection.checkerboard import detect_checkerboard
from vical.calib.errors import CalibrationError
from vical.calib.metrics import CalibrationErrors, calibration_errors
from vical.calib.result import CalibrationResult, ImuResiduals, ResidualStats, WeakParameter
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint, calibrate_two_stage
from vical.calib.solve.visual_inertial import ViOptions

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
