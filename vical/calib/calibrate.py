"""Kept for imports written before the pipeline moved: ``vical.calib.pipeline`` holds these."""

from vical.calib.pipeline import (  # noqa: F401
    JOINT_START_VIEWS,
    RigCalibration,
    calibrate_extrinsics,
    calibrate_joint,
    calibrate_rig,
    calibrate_two_stage,
)
