"""The hardware adapters' conversions, which need neither the hardware nor the libraries (vical.robot.*)."""

import base64
import sys

import cv2
import numpy as np
import pytest

from vical.geometry import make_transform, so3_exp, so3_log
from vical.robot import SensorStreamError
from vical.robot.franka import FrankaArm, matrix_from_column_major
from vical.robot.realsense import ImuPairer, RealSenseSensor, grey_image, ns_from_ms
from vical.robot.ros import (
    RosArm,
    RosSensor,
    grey_from_compressed_message,
    grey_from_image_message,
    matrix_from_pose_message,
    pose_message_from_matrix,
    stamp_ns,
)
from vical.robot.ur import URArm, matrix_from_ur_pose, ur_pose_from_matrix


def random_pose(rng: np.random.Generator, angle: float | None = None) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    theta = rng.uniform(0.0, np.pi) if angle is None else angle
    return make_transform(so3_exp(theta * axis), rng.uniform(-1.0, 1.0, 3))


# ----------------------------------------------------------------------------- UR poses


@pytest.mark.parametrize("angle", [None, 0.0, 1e-9, np.pi - 1e-6])
def test_ur_pose_round_trips_through_the_matrix(angle):
    rng = np.random.default_rng(0)
    for _ in range(20):
        T = random_pose(rng, angle)
        pose = ur_pose_from_matrix(T)
        np.testing.assert_allclose(pose[3:], so3_log(T[:3, :3]), atol=1e-12)
        np.testing.assert_allclose(matrix_from_ur_pose(pose), T, atol=1e-9)


def test_ur_pose_is_position_then_rotation_vector():
    T = matrix_from_ur_pose([0.1, -0.2, 0.3, 0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(T[:3, 3], [0.1, -0.2, 0.3])
    np.testing.assert_allclose(T[:3, :3] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)  # 90 deg about z
    with pytest.raises(ValueError, match="6 values"):
        matrix_from_ur_pose([0.0] * 7)


# ----------------------------------------------------------------------------- Franka poses


def test_franka_pose_values_are_read_column_by_column():
    T = random_pose(np.random.default_rng(1))
    np.testing.assert_allclose(matrix_from_column_major(T.T.reshape(-1).tolist()), T)


# ----------------------------------------------------------------------------- RealSense stamps and IMU pairing


def test_realsense_stamps_become_integer_nanoseconds():
    assert ns_from_ms(1.5) == 1_500_000
    assert ns_from_ms(0.0004) == 0  # below the device's microsecond tick
    host_clock_ms = 1_700_000_000_123.456  # a global-time stamp: ms since the epoch
    assert ns_from_ms(host_clock_ms) == 1_700_000_000_123_456_000


def accel_of(t_ns: np.ndarray) -> np.ndarray:
    """A specific force linear in time, so that linear interpolation reproduces it exactly."""
    s = (t_ns - 10**12) / 1e9
    return np.column_stack([1.0 + 2.0 * s, -3.0 * s, 9.81 + 0.5 * s])


def synthetic_streams():
    t0 = 10**12
    gyro_t = t0 + np.arange(0, 2 * 10**9, 5_000_000)  # 200 Hz for 2 s
    accel_t = t0 + 1_000_000 + np.arange(0, 2 * 10**9, 15_873_016)  # ~63 Hz, starting 1 ms after the gyro
    gyro = np.column_stack([np.sin(gyro_t / 1e9), np.cos(gyro_t / 1e9), gyro_t / 1e12])
    return gyro_t, gyro, accel_t, accel_of(accel_t)


def test_imu_pairer_interpolates_the_accelerometer_onto_the_gyro_stamps():
    gyro_t, gyro, accel_t, accel = synthetic_streams()
    pairer = ImuPairer()
    for t, w in zip(gyro_t, gyro, strict=True):
        pairer.add_gyro(int(t), w)
    for t, a in zip(accel_t, accel, strict=True):
        pairer.add_accel(int(t), a)
    imu = pairer.pop()
    inside = (gyro_t >= accel_t[0]) & (gyro_t <= accel_t[-1])
    np.testing.assert_array_equal(imu.t, gyro_t[inside])
    np.testing.assert_array_equal(imu.gyro, gyro[inside])
    np.testing.assert_allclose(imu.accel, accel_of(gyro_t[inside]), atol=1e-9)


@pytest.mark.parametrize("gyro_delay_ns", [0, 4_000_000, -4_000_000])
def test_imu_pairer_delivers_every_sample_read_in_pieces_whatever_the_arrival_order(gyro_delay_ns):
    """The two streams arrive from different threads: a gyro sample may come after later accel samples."""
    gyro_t, gyro, accel_t, accel = synthetic_streams()
    gyro_arrivals = [(t + gyro_delay_ns, "gyro", t, w) for t, w in zip(gyro_t, gyro, strict=True)]
    accel_arrivals = [(t, "accel", t, a) for t, a in zip(accel_t, accel, strict=True)]
    pairer, pieces = ImuPairer(), []
    for i, (_, stream, t, value) in enumerate(sorted(gyro_arrivals + accel_arrivals, key=lambda e: e[0])):
        (pairer.add_gyro if stream == "gyro" else pairer.add_accel)(int(t), value)
        if i % 7 == 0:
            pieces.append(pairer.pop())
    pieces.append(pairer.pop())
    t = np.concatenate([p.t for p in pieces])
    expected = gyro_t[(gyro_t >= accel_t[0]) & (gyro_t <= accel_t[-1])]
    np.testing.assert_array_equal(t, expected)
    np.testing.assert_allclose(np.concatenate([p.accel for p in pieces]), accel_of(t), atol=1e-9)


def test_imu_pairer_keeps_gyro_samples_after_the_last_accelerometer_sample_waiting():
    pairer = ImuPairer()
    pairer.add_accel(0, np.zeros(3))
    pairer.add_accel(10, np.full(3, 10.0))
    for t in (5, 10, 15):
        pairer.add_gyro(t, np.zeros(3))
    np.testing.assert_array_equal(pairer.pop().t, [5, 10])
    assert len(pairer.pop()) == 0  # 15 waits for an accelerometer sample at or after it
    pairer.add_accel(20, np.full(3, 20.0))
    imu = pairer.pop()
    np.testing.assert_array_equal(imu.t, [15])
    np.testing.assert_allclose(imu.accel, [[15.0, 15.0, 15.0]])


def test_imu_pairer_refuses_stamps_going_backwards():
    pairer = ImuPairer()
    pairer.add_gyro(10, np.zeros(3))
    with pytest.raises(SensorStreamError, match="gyroscope stamps went backwards"):
        pairer.add_gyro(10, np.zeros(3))
    pairer.add_accel(0, np.zeros(3))
    pairer.add_accel(20, np.zeros(3))
    assert len(pairer.pop()) == 1  # what was checked against is delivered: the check still holds
    with pytest.raises(SensorStreamError, match="gyroscope stamps went backwards"):
        pairer.add_gyro(5, np.zeros(3))


def test_realsense_colour_frames_become_grey():
    bgr = np.zeros((2, 3, 3), np.uint8)
    bgr[..., 2] = 255  # red
    grey = grey_image(bgr, "color")
    assert grey.shape == (2, 3) and grey.dtype == np.uint8
    assert grey[0, 0] == cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)[0, 0] == 76  # 0.299 * 255
    infrared = np.arange(6, dtype=np.uint8).reshape(2, 3)
    np.testing.assert_array_equal(grey_image(infrared, "infrared"), infrared)


# ----------------------------------------------------------------------------- ROS messages (rosbridge JSON)


def image_message(pixels: np.ndarray, encoding: str, padding: int = 0) -> dict:
    """A sensor_msgs/Image as rosbridge delivers it: uint8[] data as base64 text, rows maybe padded."""
    height, width = pixels.shape[:2]
    rows = pixels.reshape(height, -1)
    rows = np.hstack([rows, np.zeros((height, padding), np.uint8)])
    return {
        "header": {"stamp": {"secs": 12, "nsecs": 345}, "frame_id": "camera"},
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": rows.shape[1],
        "data": base64.b64encode(rows.tobytes()).decode("ascii"),
    }


@pytest.fixture
def colour_pixels():
    rng = np.random.default_rng(2)
    return rng.integers(0, 256, (4, 5, 3), dtype=np.uint8)


def test_ros_mono8_image_decodes_unchanged():
    pixels = np.arange(20, dtype=np.uint8).reshape(4, 5)
    np.testing.assert_array_equal(grey_from_image_message(image_message(pixels, "mono8")), pixels)
    np.testing.assert_array_equal(grey_from_image_message(image_message(pixels, "mono8", padding=3)), pixels)


@pytest.mark.parametrize(("encoding", "conversion"), [("rgb8", cv2.COLOR_RGB2GRAY), ("bgr8", cv2.COLOR_BGR2GRAY)])
def test_ros_colour_images_decode_to_grey(colour_pixels, encoding, conversion):
    expected = cv2.cvtColor(colour_pixels, conversion)
    for padding in (0, 1):
        grey = grey_from_image_message(image_message(colour_pixels, encoding, padding))
        assert grey.dtype == np.uint8 and grey.shape == (4, 5)
        np.testing.assert_array_equal(grey, expected)


def test_ros_rgb8_and_bgr8_read_the_channels_in_their_order(colour_pixels):
    rgb = grey_from_image_message(image_message(colour_pixels, "rgb8"))
    bgr_of_same_scene = grey_from_image_message(image_message(colour_pixels[..., ::-1].copy(), "bgr8"))
    np.testing.assert_array_equal(rgb, bgr_of_same_scene)


def test_ros_image_refuses_other_encodings_and_short_data(colour_pixels):
    with pytest.raises(SensorStreamError, match="mono8"):
        grey_from_image_message(image_message(colour_pixels, "rgba8"))
    msg = image_message(colour_pixels, "rgb8")
    msg["height"] = 10
    with pytest.raises(SensorStreamError, match="holds"):
        grey_from_image_message(msg)


def test_ros_image_data_as_a_list_of_ints():
    pixels = np.arange(6, dtype=np.uint8).reshape(2, 3)
    msg = image_message(pixels, "mono8")
    msg["data"] = pixels.reshape(-1).tolist()
    np.testing.assert_array_equal(grey_from_image_message(msg), pixels)


def test_ros_compressed_image_decodes_to_grey():
    pixels = np.arange(48, dtype=np.uint8).reshape(6, 8)
    ok, png = cv2.imencode(".png", pixels)
    assert ok
    msg = {"format": "png", "data": base64.b64encode(png.tobytes()).decode("ascii")}
    np.testing.assert_array_equal(grey_from_compressed_message(msg), pixels)
    with pytest.raises(SensorStreamError, match="did not decode"):
        grey_from_compressed_message({"format": "png", "data": base64.b64encode(b"nonsense").decode("ascii")})


def test_ros_stamps_of_ros1_and_ros2_headers():
    assert stamp_ns({"secs": 12, "nsecs": 345}) == 12_000_000_345
    assert stamp_ns({"sec": 12, "nanosec": 345}) == 12_000_000_345


def test_ros_pose_message_round_trips_through_the_matrix():
    rng = np.random.default_rng(3)
    for _ in range(20):
        T = random_pose(rng)
        msg = pose_message_from_matrix(T)
        assert set(msg["orientation"]) == {"x", "y", "z", "w"}
        np.testing.assert_allclose(matrix_from_pose_message(msg), T, atol=1e-12)


def test_ros_pose_message_quaternion_is_x_y_z_w():
    half = np.sqrt(0.5)
    msg = {"position": {"x": 1.0, "y": 2.0, "z": 3.0}, "orientation": {"x": 0.0, "y": 0.0, "z": half, "w": half}}
    T = matrix_from_pose_message(msg)
    np.testing.assert_allclose(T[:3, :3] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)  # 90 deg about z
    np.testing.assert_allclose(T[:3, 3], [1.0, 2.0, 3.0])


# ----------------------------------------------------------------------------- missing libraries


MISSING = [
    ("panda_py", lambda: FrankaArm("172.16.0.2"), "franka"),
    ("rtde_control", lambda: URArm("192.168.1.10"), "ur"),
    ("pyrealsense2", lambda: RealSenseSensor(), "realsense"),
    ("roslibpy", lambda: RosSensor("localhost", 9090, "/image", "/imu", (640, 480), 30.0, 200.0), "ros"),
    ("roslibpy", lambda: RosArm("localhost", 9090, "/pose", "/goal", "base", {}), "ros"),
]


@pytest.mark.parametrize(("module", "make", "extra"), MISSING, ids=[f"{m[2]}-{i}" for i, m in enumerate(MISSING)])
def test_a_missing_library_names_the_extra_to_install(module, make, extra, monkeypatch):
    monkeypatch.setitem(sys.modules, module, None)  # `import module` fails, as where it is not installed
    with pytest.raises(ImportError, match=rf"pip install 'vical\[{extra}\]'$"):
        make()
