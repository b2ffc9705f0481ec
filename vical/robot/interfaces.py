"""The arm and the visual-inertial sensor as ``vical-collect`` sees them.

Clocks. Every timestamp is an integer number of nanoseconds, each stream in its own clock:

- ``Arm.pose()`` is stamped in the arm controller's clock;
- ``ViSensor`` IMU samples are stamped in the IMU clock and camera frames in the camera clock; the
  frame stamped ``t_cam`` was exposed at IMU time ``t_cam + time_offset`` (Kalibr's sign), the
  offset the calibration estimates. A hardware-synchronised sensor (a RealSense with its global
  time off, a Kalibr-style rig) has a small constant offset; a sensor stamped by a host on arrival
  has its transport latency in it.

The runner never subtracts stamps of different clocks: it orders the arm's motions and the
sensor's data by when they were read, and leaves the camera-IMU offset to the calibrator.

Poses. ``T_base_tool`` is the (4, 4) pose of the tool frame (the sensor's body: x along the
optical axis toward the scene, y left, z up, as the simulated Panda's ``ee`` site) in the arm's
base frame, in metres. An adapter whose controller speaks of another tool frame converts.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Self

import numpy as np

from vical.data import ImuSamples

# A pose matrix further than this from a rotation + translation is refused (not re-orthonormalised).
RIGID_TOLERANCE = 1e-6


class MotionRefused(RuntimeError):
    """The arm will not move to the goal (unreachable, beyond a joint or speed limit, in collision).

    Raised before the arm moves: after it, the arm is where it was.
    """


class SensorStreamError(RuntimeError):
    """The sensor's stream broke: disconnected, a gap in the IMU or camera stream, stamps going backwards."""


def check_pose(T: np.ndarray, name: str = "T_base_tool") -> np.ndarray:
    """``T`` as a (4, 4) float rigid transform; ``ValueError`` naming ``name`` otherwise."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{name} must be a finite (4, 4) matrix, got shape {T.shape}")
    R = T[:3, :3]
    rigid = np.allclose(R @ R.T, np.eye(3), atol=RIGID_TOLERANCE) and np.linalg.det(R) > 0
    if not rigid or not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{name} is not a rigid transform (rotation + translation, last row [0, 0, 0, 1])")
    return T


@dataclass(frozen=True)
class StampedPose:
    """The tool's pose ``T_base_tool`` (4, 4) [m] at ``t_ns`` (the arm's clock)."""

    t_ns: int
    T_base_tool: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "t_ns", int(self.t_ns))
        object.__setattr__(self, "T_base_tool", check_pose(self.T_base_tool))

    @property
    def position(self) -> np.ndarray:
        """(3,) [m] the tool's position in the base frame."""
        return self.T_base_tool[:3, 3].copy()


@dataclass(frozen=True)
class ArmLimits:
    """What the arm allows its tool, as the adapter reports it (the runner plans within these).

    Attributes:
        max_speed: [m/s] tool translation speed.
        max_angular_speed: [rad/s] tool rotation speed.
        max_acceleration: [m/s^2] tool translation acceleration.
    """

    max_speed: float
    max_angular_speed: float
    max_acceleration: float

    def __post_init__(self) -> None:
        for name in ("max_speed", "max_angular_speed", "max_acceleration"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"ArmLimits.{name} must be a positive number, got {value}")
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class CameraImage:
    """One camera frame: an 8-bit grey ``image`` (H, W) stamped ``t_ns`` in the camera clock."""

    t_ns: int
    image: np.ndarray

    def __post_init__(self) -> None:
        image = np.asarray(self.image)
        if image.ndim != 2 or image.dtype != np.uint8:
            raise ValueError(f"CameraImage.image must be an 8-bit grey (H, W) array, got {image.dtype} {image.shape}")
        object.__setattr__(self, "t_ns", int(self.t_ns))
        object.__setattr__(self, "image", image)


@dataclass(frozen=True)
class CameraDetections:
    """One camera frame as a sensor that finds the board itself delivers it (a simulated sensor at corner level):
    the board's corners (K, 2) [px] and their target point ids (K,), stamped ``t_ns`` in the camera clock."""

    t_ns: int
    corners: np.ndarray
    ids: np.ndarray

    def __post_init__(self) -> None:
        corners, ids = np.asarray(self.corners, dtype=float), np.asarray(self.ids, dtype=np.int64)
        if corners.shape != (len(ids), 2):
            raise ValueError(f"CameraDetections needs corners (K, 2) for K ids, got {corners.shape} and {ids.shape}")
        object.__setattr__(self, "t_ns", int(self.t_ns))
        object.__setattr__(self, "corners", corners)
        object.__setattr__(self, "ids", ids)


@dataclass(frozen=True)
class SensorData:
    """What arrived from the sensor since the last read: camera frames (images, or the board's corners where the
    sensor detects them) and IMU samples, each in stamp order."""

    frames: list[CameraImage | CameraDetections]
    imu: ImuSamples

    @classmethod
    def empty(cls) -> SensorData:
        return cls([], ImuSamples.concatenate([]))


class Device(ABC):
    """What an arm and a sensor share: ``stop`` and ``close``, and a ``with`` block that calls both on leaving
    (normally, by an exception or Ctrl-C)."""

    @abstractmethod
    def stop(self) -> None:
        """Stop what the device is doing (safe to call at any time)."""

    @abstractmethod
    def close(self) -> None:
        """Release the device (after ``stop``)."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self.stop()
        finally:
            self.close()


class Arm(Device):
    """A robot arm that moves the sensor: read the tool pose, move it, stop.

    Use it as a context manager: leaving the block (normally, by an exception or Ctrl-C) stops the
    arm and closes the connection.
    """

    limits: ArmLimits

    @abstractmethod
    def pose(self) -> StampedPose:
        """The tool's current pose (module doc: frames and clock)."""

    @abstractmethod
    def move_to(self, T_base_tool: np.ndarray) -> StampedPose:
        """Move the tool to ``T_base_tool`` (4, 4) within ``limits``; block until it rests; return the pose reached.

        Raises ``MotionRefused`` without moving when the goal cannot be executed.
        """

    @abstractmethod
    def stop(self) -> None:
        """Stop any motion now (safe to call at any time, also when the arm rests)."""

    @abstractmethod
    def close(self) -> None:
        """Release the connection (after ``stop``)."""


class ViSensor(Device):
    """A camera + IMU: start streaming, read what arrived, stop (module doc: clocks).

    Attributes:
        image_size: (width, height) [px] of the camera frames.
        camera_rate_hz, imu_rate_hz: the nominal rates of the two streams.
        paced_by_reads: its time passes only as it is read (a simulation), not with the wall clock: a loop that reads
            it while it waits for something else (a policy deciding) moves its clock by however long that takes.
    """

    image_size: tuple[int, int]
    camera_rate_hz: float
    imu_rate_hz: float
    paced_by_reads: bool = False

    @abstractmethod
    def start(self) -> None:
        """Start both streams; data arriving from now on is returned by ``read``."""

    @abstractmethod
    def read(self) -> SensorData:
        """Everything that arrived since the last ``read`` (or ``start``), without waiting.

        Raises ``SensorStreamError`` when a stream broke.
        """

    @abstractmethod
    def stop(self) -> None:
        """Stop both streams (safe to call at any time)."""

    @abstractmethod
    def close(self) -> None:
        """Release the device (after ``stop``)."""


@dataclass(frozen=True)
class Guidance:
    """What ``vical-guide`` shows the person who holds the sensor (``vical.collection.guide``).

    Attributes:
        T_board_body: (4, 4) where to hold the sensor's body next, in the board's frame (the frame a person and a
            hand-held sensor share); None once the guide is done.
        words: the instruction ("move 20 cm closer, tilt the top away 25 deg"; "done" at the end).
        ratios: each parameter group's predicted error over its tolerance (the goal is every ratio <= 1).
        elapsed_s: [s] of recording so far.
        done: stop moving: the calibration is predicted good enough, or (``words`` say which group and why) out of
            reach in the time left.
    """

    T_board_body: np.ndarray | None
    words: str
    ratios: dict[str, float]
    elapsed_s: float
    done: bool = False


class Person(ABC):
    """Someone who holds the sensor and follows guidance: a page in a browser, lines on a terminal, a model."""

    @abstractmethod
    def show(self, guidance: Guidance) -> None:
        """Tell the person what to do next (returns at once; the guide watches the sensor for the rest)."""

    def gone(self) -> str | None:
        """Why the person can no longer be guided (a page's tab closed), or None while they can."""
        return None
