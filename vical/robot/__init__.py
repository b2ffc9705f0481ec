"""Robot-agnostic interfaces of an arm, a visual-inertial sensor and a person who holds one: what ``vical-collect``
and ``vical-guide`` drive.

Imports ``geometry`` and ``data`` only: an adapter for a real arm or sensor needs nothing of the
simulator, and the simulated adapters (``vical.sim.adapters``) implement these same interfaces.
"""

from vical.robot.interfaces import (
    Arm,
    ArmLimits,
    CameraDetections,
    CameraImage,
    Guidance,
    MotionRefused,
    Person,
    SensorData,
    SensorStreamError,
    StampedPose,
    ViSensor,
)

__all__ = [
    "Arm",
    "ArmLimits",
    "CameraDetections",
    "CameraImage",
    "Guidance",
    "MotionRefused",
    "Person",
    "SensorData",
    "SensorStreamError",
    "StampedPose",
    "ViSensor",
]
