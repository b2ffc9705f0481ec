"""Typed containers shared by the simulator, the calibrator and the file formats."""

from vical.data.imu_model import ImuIntrinsics
from vical.data.target import Target, TargetError
from vical.data.types import (
    FIRST_CAMERA,
    NS_PER_S,
    CameraFrames,
    DataError,
    ImuNoise,
    ImuSamples,
    PathProfile,
    Recording,
    SensorTruth,
    Trajectory,
    seconds_since,
)

__all__ = [
    "FIRST_CAMERA",
    "NS_PER_S",
    "CameraFrames",
    "DataError",
    "ImuIntrinsics",
    "ImuNoise",
    "ImuSamples",
    "PathProfile",
    "Recording",
    "SensorTruth",
    "Target",
    "TargetError",
    "Trajectory",
    "seconds_since",
]
