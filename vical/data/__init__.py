"""Typed containers shared by the simulator, the calibrator and the file formats."""

from vical.data.camera_frames import CameraFrames
from vical.data.errors import DataError
from vical.data.imu import ImuNoise, ImuSamples
from vical.data.imu_model import ImuIntrinsics
from vical.data.sample_arrays import NS_PER_S, median_rate_hz, seconds_since
from vical.data.sensor_recording import FIRST_CAMERA, Recording
from vical.data.sensor_truth import SensorTruth
from vical.data.target import Target, TargetError
from vical.data.trajectory import PathProfile, Trajectory

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
    "median_rate_hz",
    "seconds_since",
]
