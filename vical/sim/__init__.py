"""Simulation: the MuJoCo Panda with a camera + IMU rig in front of a checkerboard, and motion execution."""

import os

# Offscreen rendering needs an OpenGL backend chosen before mujoco is imported; EGL works headless.
os.environ.setdefault("MUJOCO_GL", "egl")


from vical.sim.kinematics import PANDA_LIMITS, IKResult, JointLimits
from vical.sim.motion import MotionResult
from vical.sim.panda import PandaSim, StepCallback
from vical.sim.scene import body_pose, build_model, camera_pose_cv, imu_pose_in_body, set_imu_pose, site_pose
from vical.sim.settings import BoardConfig, IKConfig, MotionConfig, PhysicsConfig, SimConfig

__all__ = [
    "PANDA_LIMITS",
    "BoardConfig",
    "IKConfig",
    "IKResult",
    "JointLimits",
    "MotionConfig",
    "MotionResult",
    "PandaSim",
    "PhysicsConfig",
    "SimConfig",
    "StepCallback",
    "body_pose",
    "build_model",
    "camera_pose_cv",
    "imu_pose_in_body",
    "set_imu_pose",
    "site_pose",
]
