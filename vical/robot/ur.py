"""A Universal Robots arm (CB3, e-Series) as an ``Arm``, through ur_rtde (``pip install 'vical[ur]'``).

A thin adapter, written against ur_rtde's documented API and not run on a robot in this project: it
converts poses and stamps and calls the library; nothing more. Check it on your robot at low speed
before a collection, with the emergency stop at hand.

Frames. The controller reports and commands the TCP pose ``[x, y, z, rx, ry, rz]`` (metres, axis *
angle in radians) in the robot's base frame. ``T_flange_tool`` is vical's tool frame (the sensor body:
x along the optical axis, y left, z up) in the controller's TCP frame; set the TCP offset on the
teach pendant to zero to make it the flange-to-sensor transform.

Clock. Poses are stamped with the controller's timestamp (seconds since the controller started),
converted to integer nanoseconds.
"""

from __future__ import annotations

import numpy as np

from vical.data import NS_PER_S
from vical.geometry import invert_transform, make_transform, so3_exp, so3_log
from vical.robot.interfaces import Arm, ArmLimits, MotionRefused, StampedPose, check_pose

INSTALL_HINT = "URArm needs the ur-rtde package: pip install 'vical[ur]'"
# [m/s^2] how hard stop() decelerates the tool (ur_rtde's default for stopL).
STOP_DECELERATION = 10.0


def matrix_from_ur_pose(pose: list[float]) -> np.ndarray:
    """The (4, 4) transform of a UR pose ``[x, y, z, rx, ry, rz]`` (position [m], rotation vector [rad])."""
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (6,):
        raise ValueError(f"a UR pose has 6 values [x, y, z, rx, ry, rz], got shape {pose.shape}")
    return make_transform(so3_exp(pose[3:]), pose[:3])


def ur_pose_from_matrix(T: np.ndarray) -> list[float]:
    """The UR pose ``[x, y, z, rx, ry, rz]`` of the (4, 4) transform ``T`` (rotation angle in [0, pi])."""
    return [*map(float, T[:3, 3]), *map(float, so3_log(T[:3, :3]))]


class URArm(Arm):
    """The arm behind ur_rtde's control and receive interfaces: read the TCP pose, ``moveL``, stop.

    Args:
        hostname: the robot's address; the robot in remote control (e-Series) and not in a program.
        T_flange_tool: (4, 4) the tool frame in the controller's TCP frame [m] (module doc).
        speed: [m/s] tool speed of every motion (``moveL``).
        acceleration: [m/s^2] tool acceleration of every motion.
        angular_speed: [rad/s] the tool rotation speed the runner may plan with (``moveL`` does not
            take one: keep rotations small against ``speed``).
    """

    def __init__(
        self,
        hostname: str,
        T_flange_tool: np.ndarray | list | None = None,
        speed: float = 0.1,
        acceleration: float = 0.5,
        angular_speed: float = 0.5,
    ) -> None:
        try:
            import rtde_control
            import rtde_receive
        except ImportError as err:
            raise ImportError(INSTALL_HINT) from err
        self.T_flange_tool = check_pose(np.eye(4) if T_flange_tool is None else T_flange_tool, "T_flange_tool")
        self._T_tool_flange = invert_transform(self.T_flange_tool)
        self.limits = ArmLimits(speed, angular_speed, acceleration)
        self._receive = rtde_receive.RTDEReceiveInterface(hostname)
        self._control = rtde_control.RTDEControlInterface(hostname)
        self._closed = False

    def pose(self) -> StampedPose:
        t_ns = round(self._receive.getTimestamp() * NS_PER_S)
        T_base_flange = matrix_from_ur_pose(self._receive.getActualTCPPose())
        return StampedPose(t_ns, T_base_flange @ self.T_flange_tool)

    def move_to(self, T_base_tool: np.ndarray) -> StampedPose:
        goal = ur_pose_from_matrix(check_pose(T_base_tool) @ self._T_tool_flange)
        if not self._control.isPoseWithinSafetyLimits(goal):
            raise MotionRefused(
                "the goal is out of reach or beyond the robot's safety limits (planes, TCP orientation)"
            )
        if not self._control.moveL(goal, self.limits.max_speed, self.limits.max_acceleration):
            raise RuntimeError(
                "the UR controller did not complete moveL (a protective stop, a safeguard stop, or the control "
                "script is not running): check the teach pendant"
            )
        return self.pose()

    def stop(self) -> None:
        if not self._closed:
            self._control.stopL(STOP_DECELERATION)

    def close(self) -> None:
        """End ur_rtde's control script on the controller and disconnect both interfaces."""
        if self._closed:
            return
        self._closed = True
        try:
            self._control.stopScript()
            self._control.disconnect()
        finally:
            self._receive.disconnect()
