"""A Franka Emika Panda (FER) or Franka Research 3 as an ``Arm``, through panda-py (``pip install 'vical[franka]'``).

A thin adapter, written against panda-py's documented API and not run on a robot in this project:
it converts poses and stamps and calls the library; nothing more. Check it on your robot at low
speed before a collection (``speed_factor``), with the user stop at hand.

Frames. panda-py reports and commands the pose of libfranka's end-effector frame (``O_T_EE``: the
flange when Desk's end effector is set to none, the configured TCP otherwise) in the robot's base
frame. ``T_flange_tool`` is vical's tool frame (the sensor body: x along the optical axis, y left,
z up) in that frame; set Desk's end effector to none to make it the flange-to-sensor transform.

Clock. Poses are stamped with the robot state's ``time``: milliseconds since the robot started
(the arm controller's clock), converted to integer nanoseconds.
"""

from __future__ import annotations

import numpy as np

from vical.data import NS_PER_S
from vical.geometry import invert_transform
from vical.robot.interfaces import Arm, ArmLimits, MotionRefused, StampedPose, check_pose

INSTALL_HINT = "FrankaArm needs the panda-python package: pip install 'vical[franka]'"
# The Panda's documented Cartesian limits: translation [m/s], rotation [rad/s], translation acceleration
# [m/s^2]; panda-py's planner scales them by speed_factor.
PANDA_CARTESIAN_LIMITS = (1.7, 2.5, 13.0)
NS_PER_MS = NS_PER_S // 1000


def matrix_from_column_major(values: list[float]) -> np.ndarray:
    """The (4, 4) matrix of libfranka's 16 pose values, which are stored column by column."""
    return np.asarray(values, dtype=float).reshape(4, 4).T


class FrankaArm(Arm):
    """The arm behind panda-py's ``Panda``: read the end-effector pose, move to a pose, stop.

    Args:
        hostname: the robot's (control box) address, with FCI active and the joints unlocked.
        T_flange_tool: (4, 4) the tool frame in the library's end-effector frame [m] (module doc).
        speed_factor: fraction of the robot's limits panda-py's motion planner uses, in (0, 1].
        success_threshold: [m, rad] how close to the goal panda-py considers a motion done.
    """

    def __init__(
        self,
        hostname: str,
        T_flange_tool: np.ndarray | list | None = None,
        speed_factor: float = 0.2,
        success_threshold: float = 0.01,
    ) -> None:
        try:
            import panda_py
        except ImportError as err:
            raise ImportError(INSTALL_HINT) from err
        if not 0 < speed_factor <= 1:
            raise ValueError(f"speed_factor must be in (0, 1], got {speed_factor}")
        self.T_flange_tool = check_pose(np.eye(4) if T_flange_tool is None else T_flange_tool, "T_flange_tool")
        self._T_tool_flange = invert_transform(self.T_flange_tool)
        self._speed_factor = float(speed_factor)
        self._success_threshold = float(success_threshold)
        speed, angular, acceleration = PANDA_CARTESIAN_LIMITS
        self.limits = ArmLimits(speed * speed_factor, angular * speed_factor, acceleration * speed_factor)
        self._panda_py = panda_py
        self._panda = panda_py.Panda(hostname)

    def pose(self) -> StampedPose:
        # One robot state for both, so that the pose and its stamp come from the same control cycle.
        state = self._panda.get_state()
        T_base_flange = matrix_from_column_major(state.O_T_EE)
        return StampedPose(state.time.to_msec() * NS_PER_MS, T_base_flange @ self.T_flange_tool)

    def move_to(self, T_base_tool: np.ndarray) -> StampedPose:
        T_base_flange = check_pose(T_base_tool) @ self._T_tool_flange
        if not self._reachable(T_base_flange):
            raise MotionRefused("the goal is out of reach: panda-py's inverse kinematics finds no joint positions")
        reached = self._panda.move_to_pose(
            T_base_flange, speed_factor=self._speed_factor, success_threshold=self._success_threshold
        )
        if not reached:
            # An error (a reflex, a limit) stopped the motion: raise it; otherwise the arm rests near the
            # goal and the pose below says where.
            self._panda.raise_error()
        return self.pose()

    def _reachable(self, T_base_flange: np.ndarray) -> bool:
        """Whether panda-py's inverse kinematics finds finite joint positions near the current ones."""
        try:
            q = self._panda_py.ik(T_base_flange, q_init=self._panda.q)
        except Exception:  # some panda-py versions raise their own IK error type when there is no solution
            return False
        return bool(np.all(np.isfinite(q)))

    def stop(self) -> None:
        if self._panda is not None:
            self._panda.stop_controller()

    def close(self) -> None:
        """Drop the connection (panda-py closes it when its ``Panda`` is released)."""
        self._panda = None
