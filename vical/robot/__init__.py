"""Robot-agnostic interfaces of an arm and a visual-inertial sensor, the two things ``vical-collect`` drives.

Imports ``geometry`` and ``data`` only: an adapter for a real arm or sensor needs nothing of the
simulator, and the simulated adapters (``vical.sim.adapters``) implement these same interfaces.
"""

from vical.robot.interfaces import (
    Arm,
    ArmLimits,
    CameraImage,
    MotionRefused,
    SensorData,
    SensorStreamError,
    StampedPose,
    ViSensor,
)

__all__ = [
    "Arm",
    "ArmLimits",
    "CameraImage",
    "MotionRefused",
    "SensorData",
    "SensorStreamError",
    "StampedPose",
    "ViSensor",
]
