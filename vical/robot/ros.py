"""An arm and a camera + IMU driven over ROS through rosbridge, with roslibpy (``pip install 'vical[ros]'``).

No ROS installation is needed on this side: roslibpy speaks rosbridge's websocket protocol, and
rosbridge (``rosbridge_server``) runs on the robot's ROS machine. Thin adapters, written against
roslibpy's documented API and not run against a robot in this project: they convert messages and
call the library; nothing more. Check them on your setup at low speed before a collection.

Messages arrive as rosbridge's JSON: dicts, with ``uint8[]`` fields (image data) as base64 strings.

``RosSensor`` subscribes to a ``sensor_msgs/Image`` (``mono8``, ``rgb8``, ``bgr8``; converted to grey)
or ``sensor_msgs/CompressedImage`` topic and a ``sensor_msgs/Imu`` topic. Clocks: each message's
``header.stamp``, as its driver sets it: a driver that stamps on the host when data arrive puts its
transport latency into the camera-IMU offset.

``RosArm`` reads the tool's flange pose from a ``geometry_msgs/PoseStamped`` topic (stamped in the
arm driver's clock) and moves by publishing a ``PoseStamped`` goal, for the robot's own controller
(a Cartesian pose controller, a motion planner's goal topic) to execute; it waits until the reported
pose is within tolerance of the goal. ``T_flange_tool`` is vical's tool frame (the sensor body: x
along the optical axis, y left, z up) in the frame whose pose the topic reports.
"""

from __future__ import annotations

import base64
import threading
from collections import deque
from collections.abc import Mapping
from typing import Any

import cv2
import numpy as np

from vical.data import NS_PER_S, ImuSamples
from vical.geometry import invert_transform, make_transform, matrix_to_quat, quat_to_matrix, transform_error
from vical.robot.interfaces import (
    Arm,
    ArmLimits,
    CameraImage,
    MotionRefused,
    SensorData,
    SensorStreamError,
    StampedPose,
    ViSensor,
    check_pose,
)

INSTALL_HINT = "the ROS adapters need the roslibpy package: pip install 'vical[ros]'"
# Channels of the raw image encodings decoded; anything else is refused with this list.
ENCODING_CHANNELS = {"mono8": 1, "rgb8": 3, "bgr8": 3}
TO_GREY = {"rgb8": cv2.COLOR_RGB2GRAY, "bgr8": cv2.COLOR_BGR2GRAY}


def _import_roslibpy() -> Any:
    try:
        import roslibpy
    except ImportError as err:
        raise ImportError(INSTALL_HINT) from err
    return roslibpy


def connect(roslibpy: Any, host: str, port: int, timeout: float) -> Any:
    """A running roslibpy connection to rosbridge at ``host:port``; ``ConnectionError`` after ``timeout`` [s]."""
    client = roslibpy.Ros(host=host, port=int(port))
    try:
        client.run(timeout=timeout)
    except Exception as err:  # roslibpy raises a plain Exception when the connection times out
        raise ConnectionError(
            f"no rosbridge at ws://{host}:{port} within {timeout} s: is rosbridge_server running?"
        ) from err
    return client


# ----------------------------------------------------------------------------- message conversions


def message_bytes(data: str | list[int] | bytes) -> bytes:
    """The bytes of a ``uint8[]`` field: rosbridge sends base64 text in JSON, a list of ints otherwise."""
    if isinstance(data, str):
        return base64.b64decode(data)
    return bytes(data)


def stamp_ns(stamp: Mapping[str, int]) -> int:
    """Integer nanoseconds of a header stamp, ROS 1 (``secs``, ``nsecs``) or ROS 2 (``sec``, ``nanosec``)."""
    if "secs" in stamp:
        return int(stamp["secs"]) * NS_PER_S + int(stamp["nsecs"])
    return int(stamp["sec"]) * NS_PER_S + int(stamp["nanosec"])


def grey_from_image_message(msg: Mapping[str, Any]) -> np.ndarray:
    """The 8-bit grey (H, W) image of a ``sensor_msgs/Image`` dict in ``mono8``, ``rgb8`` or ``bgr8``."""
    encoding = msg["encoding"]
    if encoding not in ENCODING_CHANNELS:
        raise SensorStreamError(
            f"image encoding {encoding!r} is not decoded; publish one of {sorted(ENCODING_CHANNELS)}"
        )
    height, width, step = int(msg["height"]), int(msg["width"]), int(msg["step"])
    channels = ENCODING_CHANNELS[encoding]
    rows = np.frombuffer(message_bytes(msg["data"]), np.uint8)
    if rows.size < height * step or step < width * channels:
        raise SensorStreamError(f"a {width}x{height} {encoding} image with step {step} holds {rows.size} bytes")
    # Rows may be padded beyond width * channels bytes: keep the pixels of each row.
    pixels = rows[: height * step].reshape(height, step)[:, : width * channels].reshape(height, width, channels)
    if channels == 1:
        return pixels[:, :, 0].copy()
    return cv2.cvtColor(pixels, TO_GREY[encoding])


def grey_from_compressed_message(msg: Mapping[str, Any]) -> np.ndarray:
    """The 8-bit grey (H, W) image of a ``sensor_msgs/CompressedImage`` dict (jpeg, png)."""
    image = cv2.imdecode(np.frombuffer(message_bytes(msg["data"]), np.uint8), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise SensorStreamError(f"a compressed image (format {msg.get('format')!r}) did not decode")
    return image


def vector(msg: Mapping[str, float]) -> np.ndarray:
    """The (3,) array of a ``geometry_msgs/Vector3`` dict."""
    return np.array([msg["x"], msg["y"], msg["z"]], dtype=float)


def matrix_from_pose_message(pose: Mapping[str, Any]) -> np.ndarray:
    """The (4, 4) transform of a ``geometry_msgs/Pose`` dict (position [m], quaternion x, y, z, w)."""
    q = pose["orientation"]
    return make_transform(quat_to_matrix([q["w"], q["x"], q["y"], q["z"]]), vector(pose["position"]))


def pose_message_from_matrix(T: np.ndarray) -> dict[str, Any]:
    """The ``geometry_msgs/Pose`` dict of the (4, 4) transform ``T``."""
    w, x, y, z = matrix_to_quat(T[:3, :3])
    px, py, pz = map(float, T[:3, 3])
    return {"position": {"x": px, "y": py, "z": pz}, "orientation": {"x": x, "y": y, "z": z, "w": w}}


# ----------------------------------------------------------------------------- the sensor


class RosSensor(ViSensor):
    """A camera + IMU publishing over ROS (module doc: topics and clocks).

    Args:
        host, port: rosbridge's websocket address.
        image_topic: the camera's ``sensor_msgs/Image`` topic (or ``CompressedImage`` with ``compressed``).
        imu_topic: the IMU's ``sensor_msgs/Imu`` topic.
        image_size: (width, height) [px] of the images (others are a broken stream).
        camera_rate_hz, imu_rate_hz: [Hz] the nominal rates of the two topics.
        compressed: the image topic is a ``sensor_msgs/CompressedImage``.
        timeout: [s] to connect to rosbridge.
    """

    def __init__(
        self,
        host: str,
        port: int,
        image_topic: str,
        imu_topic: str,
        image_size: tuple[int, int],
        camera_rate_hz: float,
        imu_rate_hz: float,
        compressed: bool = False,
        timeout: float = 10.0,
    ) -> None:
        roslibpy = _import_roslibpy()
        width, height = image_size
        self.image_size = (int(width), int(height))
        self.camera_rate_hz = float(camera_rate_hz)
        self.imu_rate_hz = float(imu_rate_hz)
        self._decode = grey_from_compressed_message if compressed else grey_from_image_message
        self._client = connect(roslibpy, host, port, timeout)
        image_type = "sensor_msgs/CompressedImage" if compressed else "sensor_msgs/Image"
        self._image_topic = roslibpy.Topic(self._client, image_topic, image_type)
        self._imu_topic = roslibpy.Topic(self._client, imu_topic, "sensor_msgs/Imu")
        # Appended by roslibpy's thread, drained by read(): decoding and checks run there, where they may raise.
        self._images: deque[Mapping[str, Any]] = deque()
        self._imu: deque[Mapping[str, Any]] = deque()
        self._streaming = False
        self._closed = False
        self._last_image_ns: int | None = None
        self._last_imu_ns: int | None = None

    def start(self) -> None:
        self._images.clear()
        self._imu.clear()
        self._image_topic.subscribe(self._images.append)
        self._imu_topic.subscribe(self._imu.append)
        self._streaming = True

    def read(self) -> SensorData:
        if not self._streaming:
            return SensorData.empty()
        frames = [self._camera_image(self._images.popleft()) for _ in range(len(self._images))]
        imu = [self._imu.popleft() for _ in range(len(self._imu))]
        return SensorData(frames, self._imu_samples(imu))

    def _camera_image(self, msg: Mapping[str, Any]) -> CameraImage:
        t_ns = stamp_ns(msg["header"]["stamp"])
        if self._last_image_ns is not None and t_ns <= self._last_image_ns:
            raise SensorStreamError(f"the camera stamps went backwards: {t_ns} ns after {self._last_image_ns} ns")
        self._last_image_ns = t_ns
        image = self._decode(msg)
        if image.shape[::-1] != self.image_size:
            raise SensorStreamError(f"a {image.shape[1]}x{image.shape[0]} image arrived, {self.image_size} expected")
        return CameraImage(t_ns, image)

    def _imu_samples(self, messages: list[Mapping[str, Any]]) -> ImuSamples:
        if not messages:
            return ImuSamples.concatenate([])
        t = np.array([stamp_ns(m["header"]["stamp"]) for m in messages], np.int64)
        stamps = t if self._last_imu_ns is None else np.concatenate([[self._last_imu_ns], t])
        if np.any(np.diff(stamps) <= 0):
            raise SensorStreamError("the IMU stamps went backwards (or repeat)")
        self._last_imu_ns = int(t[-1])
        gyro = np.array([vector(m["angular_velocity"]) for m in messages])
        accel = np.array([vector(m["linear_acceleration"]) for m in messages])
        return ImuSamples(t, gyro, accel)

    def stop(self) -> None:
        if self._streaming:
            self._streaming = False
            self._image_topic.unsubscribe()
            self._imu_topic.unsubscribe()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.stop()
            self._client.close()


# ----------------------------------------------------------------------------- the arm


class RosArm(Arm):
    """An arm whose ROS driver reports a pose topic and executes pose goals (module doc).

    Args:
        host, port: rosbridge's websocket address.
        pose_topic: ``geometry_msgs/PoseStamped`` topic of the flange (or TCP) pose in the base frame.
        goal_topic: ``geometry_msgs/PoseStamped`` topic the driver takes goals from.
        base_frame: the goals' ``header.frame_id``.
        T_flange_tool: (4, 4) the tool frame in the frame the pose topic reports [m].
        limits: ``max_speed`` [m/s], ``max_angular_speed`` [rad/s], ``max_acceleration`` [m/s^2]: what
            the driver's controller holds the motion to (the runner plans within them).
        tolerance_m, tolerance_rad: how close to the goal the reported pose must come to end a motion.
        motion_timeout: [s] a motion that has not ended by then is a fault: the arm is stopped and
            ``RuntimeError`` raised.
        workspace: ``[[x, y, z] min, [x, y, z] max]`` [m] box of tool positions in the base frame; goals
            outside are refused before moving. None: no check.
        timeout: [s] to connect to rosbridge and to wait for the first pose.
    """

    def __init__(
        self,
        host: str,
        port: int,
        pose_topic: str,
        goal_topic: str,
        base_frame: str,
        limits: Mapping[str, float],
        T_flange_tool: np.ndarray | list | None = None,
        tolerance_m: float = 0.002,
        tolerance_rad: float = 0.01,
        motion_timeout: float = 10.0,
        workspace: list[list[float]] | None = None,
        timeout: float = 10.0,
    ) -> None:
        roslibpy = _import_roslibpy()
        self._message = roslibpy.Message
        self.limits = ArmLimits(**limits)
        self.T_flange_tool = check_pose(np.eye(4) if T_flange_tool is None else T_flange_tool, "T_flange_tool")
        self._T_tool_flange = invert_transform(self.T_flange_tool)
        self._base_frame = base_frame
        self._tolerance = (float(tolerance_rad), float(tolerance_m))
        self._motion_timeout = float(motion_timeout)
        self._workspace = None if workspace is None else np.asarray(workspace, dtype=float).reshape(2, 3)
        self._timeout = float(timeout)
        self._reported = threading.Condition()
        self._latest: tuple[int, dict[str, Any]] | None = None  # (stamp [ns], the Pose dict)
        self._received = 0
        self._closed = False
        self._client = connect(roslibpy, host, port, timeout)
        self._pose_topic_name = pose_topic
        self._pose_topic = roslibpy.Topic(self._client, pose_topic, "geometry_msgs/PoseStamped")
        self._goal_topic = roslibpy.Topic(self._client, goal_topic, "geometry_msgs/PoseStamped")
        self._goal_topic.advertise()
        self._pose_topic.subscribe(self._on_pose)

    def _on_pose(self, msg: Mapping[str, Any]) -> None:
        """roslibpy's callback (its own thread): keep the latest pose and wake a waiting ``move_to``."""
        with self._reported:
            self._latest = (stamp_ns(msg["header"]["stamp"]), dict(msg["pose"]))
            self._received += 1
            self._reported.notify_all()

    def pose(self) -> StampedPose:
        with self._reported:
            if not self._reported.wait_for(lambda: self._latest is not None, timeout=self._timeout):
                raise RuntimeError(f"no pose arrived on {self._pose_topic_name} within {self._timeout} s")
            t_ns, pose = self._latest
        return StampedPose(t_ns, matrix_from_pose_message(pose) @ self.T_flange_tool)

    def move_to(self, T_base_tool: np.ndarray) -> StampedPose:
        T_base_tool = check_pose(T_base_tool)
        self._check_workspace(T_base_tool[:3, 3])
        self.pose()  # a pose must have arrived, so that the wait below sees fresh ones
        with self._reported:
            received = self._received
        self._publish_goal(T_base_tool @ self._T_tool_flange)
        with self._reported:
            arrived = self._reported.wait_for(
                lambda: self._received > received and self._near(T_base_tool), timeout=self._motion_timeout
            )
        if not arrived:
            self.stop()
            rotation, translation = transform_error(self.pose().T_base_tool, T_base_tool)
            raise RuntimeError(
                f"the arm did not reach the goal within {self._motion_timeout} s (it is {1e3 * translation:.1f} mm "
                f"and {np.degrees(rotation):.1f} deg away); it was stopped at its current pose"
            )
        return self.pose()

    def _check_workspace(self, position: np.ndarray) -> None:
        if self._workspace is None:
            return
        low, high = self._workspace
        if np.any(position < low) or np.any(position > high):
            raise MotionRefused(f"the goal position {np.round(position, 3)} m is outside the workspace {low} .. {high}")

    def _near(self, T_base_tool: np.ndarray) -> bool:
        """Whether the latest reported pose is within tolerance of ``T_base_tool`` (call holding the lock)."""
        reached = matrix_from_pose_message(self._latest[1]) @ self.T_flange_tool
        rotation, translation = transform_error(reached, T_base_tool)
        return rotation <= self._tolerance[0] and translation <= self._tolerance[1]

    def _publish_goal(self, T_base_flange: np.ndarray) -> None:
        goal = {"header": {"frame_id": self._base_frame}, "pose": pose_message_from_matrix(T_base_flange)}
        self._goal_topic.publish(self._message(goal))

    def stop(self) -> None:
        """Hold the arm where it is: publish its latest reported pose as the goal."""
        if self._closed:
            return
        with self._reported:
            latest = self._latest
        if latest is not None:
            self._publish_goal(matrix_from_pose_message(latest[1]))

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._pose_topic.unsubscribe()
            self._goal_topic.unadvertise()
        finally:
            self._client.close()
