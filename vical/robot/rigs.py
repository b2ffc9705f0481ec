"""The real rigs of ``vical-collect`` (an arm and a sensor, built by the ``robot`` config group's factories) and the
sensors a person holds for ``vical-guide`` (the ``person`` group's).

``conf/robot/franka.yaml``, ``ur.yaml`` and ``ros.yaml`` name ``franka_realsense``, ``ur_realsense`` and
``ros``; each takes the arm's and the sensor's settings as mappings and returns a ``Rig``.
``conf/person/realsense.yaml`` and ``ros.yaml`` name ``realsense_in_hand`` and ``ros_in_hand``: a ``HeldSensor``.
Neither knows nominal values of its sensor (``datasheet=None``): pass ``guess.camchain`` and ``guess.imu_yaml``.
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


@dataclass
class HeldSensor:
    """A camera + IMU a person holds, as ``vical-guide`` uses it (the person is shown the guidance on the page).

    Attributes:
        sensor: the device.
        datasheet: the sensor's nominal values, or None when it knows none.
        target: the board, or None: the one the config describes (``sim.board``).
    """

    sensor: ViSensor
    datasheet: SensorTruth | None = None
    target: Target | None = None

    def close(self) -> None:
        """Stop and release the sensor (safe after it was closed, and when it never ran)."""
        self.sensor.stop()
        self.sensor.close()


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


def realsense_in_hand(sensor: Mapping[str, Any]) -> HeldSensor:
    """A RealSense (``RealSenseSensor`` arguments in ``sensor``) in a person's hand."""
    return HeldSensor(RealSenseSensor(**sensor))


def ros_in_hand(host: str, port: int, sensor: Mapping[str, Any], timeout: float = 10.0) -> HeldSensor:
    """A sensor on ROS topics behind rosbridge at ``host:port`` (``RosSensor`` arguments) in a person's hand."""
    return HeldSensor(RosSensor(host, port, timeout=timeout, **sensor))
