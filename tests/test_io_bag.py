"""ROS1 bags: lossless round trip with Kalibr's topics, configurable topics, corrupt bags and missing topics."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.rosbag1 import Reader, Writer
from test_io_samples import make_recording

from vical.io.bag import IMAGE_TYPE, IMU_TYPE, _image_msg, _imu_msg, read_bag, ros1_typestore, write_bag
from vical.io.errors import BagFormatError, FormatError, UnitError
from vical.io.sample_checks import FormatWarning


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    rec = make_recording()
    path = tmp_path_factory.mktemp("bag") / "calib.bag"
    write_bag(rec, path)
    return rec, path


def test_bag_round_trip_is_lossless(bag):
    rec, path = bag
    back = read_bag(path, rec.target)
    assert np.array_equal(back.imu.t, rec.imu.t)
    assert np.array_equal(back.imu.gyro, rec.imu.gyro) and np.array_equal(back.imu.accel, rec.imu.accel)
    assert np.array_equal(back.frames.t, rec.frames.t)
    assert np.array_equal(back.frames.images, rec.frames.images)


def test_bag_uses_kalibr_topics_and_message_types(bag):
    rec, path = bag
    with Reader(path) as reader:
        topics = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        stamps = [t for _, t, _ in reader.messages()]
    assert topics == {
        "/cam0/image_raw": ("sensor_msgs/msg/Image", len(rec.frames)),
        "/imu0": ("sensor_msgs/msg/Imu", len(rec.imu)),
    }
    assert stamps == sorted(stamps) and stamps[0] == min(rec.imu.t[0], rec.frames.t[0])


def test_bag_detector_and_topics(tmp_path):
    rec = make_recording(seed=3)
    path = write_bag(rec, tmp_path / "x.bag", image_topic="/camera/image", imu_topic="/imu")

    def detector(image):
        return np.array([[float(image[0, 0]), 1.0]]), np.array([int(image[1, 0]) % 20])

    back = read_bag(path, rec.target, detector, image_topic="/camera/image", imu_topic="/imu", keep_images=False)
    assert back.frames.images is None
    assert [c[0, 0] for c in back.frames.corners] == [float(im[0, 0]) for im in rec.frames.images]
    only_images = read_bag(path, rec.target, image_topic="/camera/image", imu_topic=None)
    assert len(only_images.imu) == 0
    assert np.array_equal(only_images.frames.t, rec.frames.t)
    assert np.array_equal(only_images.frames.images, rec.frames.images)
    assert only_images.frames.num_detections.sum() == 0


def test_missing_topic_lists_the_bag_topics(bag):
    rec, path = bag
    with pytest.raises(BagFormatError, match=r"topic /cam1/image_raw is missing; the bag has: /cam0/image_raw"):
        read_bag(path, rec.target, image_topic="/cam1/image_raw")
    with pytest.raises(BagFormatError, match="holds sensor_msgs/msg/Image, expected sensor_msgs/msg/Imu"):
        read_bag(path, rec.target, imu_topic="/cam0/image_raw")


def test_truncated_and_corrupt_bags(bag, tmp_path):
    rec, path = bag
    data = path.read_bytes()
    truncated = tmp_path / "truncated.bag"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagFormatError, match=r"truncated\.bag cannot be read as a ROS1 bag"):
        read_bag(truncated, rec.target)
    garbage = tmp_path / "garbage.bag"
    garbage.write_bytes(b"not a bag at all" * 100)
    with pytest.raises(BagFormatError, match=r"garbage\.bag"):
        read_bag(garbage, rec.target)


def test_write_bag_refuses_to_overwrite_and_needs_images(bag, tmp_path):
    rec, path = bag
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_bag(rec, path)
    with pytest.raises(ValueError, match="has none"):
        write_bag(make_recording(images=False), tmp_path / "none.bag")
    assert list(tmp_path.iterdir()) == []


def _custom_bag(path, images, imu):
    """A bag from (t_ns, image) and (t_ns, gyro, accel) lists; header stamps in the given (possibly unsorted)
    order while the bag's receive times increase, as a driver that stamps late would write."""
    with Writer(path) as writer:
        cam = writer.add_connection("/cam0/image_raw", IMAGE_TYPE, typestore=ros1_typestore())
        imu_conn = writer.add_connection("/imu0", IMU_TYPE, typestore=ros1_typestore())
        for k, (t, image) in enumerate(images):
            writer.write(cam, k * 50_000_000, ros1_typestore().serialize_ros1(_image_msg(t, k, image), IMAGE_TYPE))
        for k, (t, gyro, accel) in enumerate(imu):
            writer.write(imu_conn, t, ros1_typestore().serialize_ros1(_imu_msg(t, k, gyro, accel), IMU_TYPE))
    return path


def _imu_stream(n=40, gyro=0.2):
    return [(k * 5_000_000, np.array([gyro, 0, 0]), np.array([0, 0, 9.81])) for k in range(n)]


def test_bag_flaws_are_fixed_or_named(tmp_path):
    target = make_recording().target
    img = np.zeros((8, 10), np.uint8)
    images = [(k * 50_000_000, img + k) for k in range(4)]
    swapped = [images[0], images[2], images[1], images[3]]
    with pytest.warns(FormatWarning, match="not sorted"):
        rec = read_bag(_custom_bag(tmp_path / "a.bag", swapped, _imu_stream()), target)
    assert np.array_equal(rec.frames.images[:, 0, 0], [0, 1, 2, 3])
    repeated = [*images, (images[3][0], img + 9)]
    with pytest.raises(BagFormatError, match="share timestamp 150000000 ns with different data"):
        read_bag(_custom_bag(tmp_path / "b.bag", repeated, _imu_stream()), target)
    sizes = [*images, (200_000_000, np.zeros((9, 10), np.uint8))]
    with pytest.raises(FormatError, match=r"/cam0/image_raw message \d+: image is 10 x 9 px"):
        read_bag(_custom_bag(tmp_path / "c.bag", sizes, _imu_stream()), target, keep_images=False)
    with pytest.raises(UnitError, match=r"d\.bag topic /imu0: gyro reads up to 120\.0 rad/s.*deg/s"):
        read_bag(_custom_bag(tmp_path / "d.bag", images, _imu_stream(gyro=120.0)), target)
