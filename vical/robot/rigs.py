"""The real rigs of ``vical-collect``: an arm and a sensor, built by the ``robot`` config group's factories.

``conf/robot/franka.yaml``, ``ur.yaml`` and ``ros.yaml`` name ``franka_realsense``, ``ur_realsense`` and
``ros``; each takes the arm's and the sensor's settings as mappings and returns a ``Rig``. A rig
knows no nominal values of its sensor (``datasheet=None``): pass ``guess.camchain`` and
``guess.imu_yaml`` to ``vical-collect``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from vical.data import SensorTruth, Target
from vical.robot.franka import FrankaArm
from vical.robot.interfaces import Arm, ViSensor
from vical.robot.realsense import RealSenseSensor
from vical.robot.ros import RosArm, RosSensor
from vical.robot.ur import URArm


@dataclass
class Rig:
    """An arm holding a camera + IMU, as ``vical-collect`` uses it.

    Attributes:
        arm, sensor: the two devices.
        datasheet: the sensor's nominal values, or None when the rig knows none.
        target: the board the rig stands before, or None: the one the config describes (``sim.board``).
    """

    arm: Arm
    sensor: ViSensor
    datasheet: SensorTruth | None = None
    target: Target | None = None

    def close(self) -> None:
        """Stop and release both devices (safe after they were closed, and when they never ran)."""
        try:
            self.sensor.stop()
            self.sensor.close()
        finally:
            self.arm.stop()
            self.arm.close()


def _rig(make_arm: Callable[[], Arm], make_sensor: Callable[[], ViSensor]) -> Rig:
    """The rig of the arm and sensor the two makers connect; the arm is released when the sensor fails."""
    arm = make_arm()
    try:
        sensor = make_sensor()
    except BaseException:
        arm.close()
        raise
    return Rig(arm, sensor)


def franka_realsense(arm: Mapping[str, Any], sensor: Mapping[str, Any]) -> Rig:
    """A Franka arm (``FrankaArm`` arguments in ``arm``) holding a RealSense (``RealSenseSensor`` in ``sensor``)."""
    return _rig(lambda: FrankaArm(**arm), lambda: RealSenseSensor(**sensor))


def ur_realsense(arm: Mapping[str, Any], sensor: Mapping[str, Any]) -> Rig:
    """A UR arm (``URArm`` arguments in ``arm``) holding a RealSense (``RealSenseSensor`` in ``sensor``)."""
    return _rig(lambda: URArm(**arm), lambda: RealSenseSensor(**sensor))


def ros(host: str, port: int, arm: Mapping[str, Any], sensor: Mapping[str, Any], timeout: float = 10.0) -> Rig:
    """An arm and a sensor behind one rosbridge at ``host:port`` (``RosArm`` and ``RosSensor`` arguments)."""
    return _rig(
        lambda: RosArm(host, port, timeout=timeout, **arm), lambda: RosSensor(host, port, timeout=timeout, **sensor)
    )
