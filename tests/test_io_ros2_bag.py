"""ROS 2 bags (SQLite ``.db3`` and MCAP), written and read by ``vical.io.bag`` through ``rosbags``, checked against
an independent implementation: the MCAP project's own reader and CDR decoder (``mcap``, ``mcap-ros2-support``, what
Foxglove and rosbag2's MCAP storage are built on) for both storages (a ``.db3`` through Python's ``sqlite3`` with
rosbag2's tables), and a bag that MCAP's own ROS 2 writer made is read by vical."""

from __future__ import annotations

import re
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as McapRos2Writer
from test_io_samples import make_recording

from vical.apps.calibrate import main as calibrate_main
from vical.io.bag import IMAGE_TYPE, IMU_TYPE, bag_generation, bag_image_topics, read_bag, write_bag
from vical.io.errors import BagFormatError, FormatError
from vical.io.kalibr import write_target_yaml
from vical.io.sources import detect_source, open_imu

STORAGES = ["db3", "mcap"]


@pytest.fixture(scope="module")
def rec():
    return make_recording(seed=4)


@pytest.fixture(scope="module", params=STORAGES)
def ros2_bag(request, rec, tmp_path_factory) -> tuple[str, Path]:
    return request.param, write_bag(rec, tmp_path_factory.mktemp("ros2") / "calib", bag_format=request.param)


def storage_file(bag: Path, storage: str) -> Path:
    return bag / f"{bag.name}.{storage}"


def test_a_ros2_bag_is_a_folder_with_its_metadata_and_one_storage_file(ros2_bag):
    storage, bag = ros2_bag
    assert sorted(p.name for p in bag.iterdir()) == sorted(["metadata.yaml", f"calib.{storage}"])
    assert "storage_identifier: " + {"db3": "sqlite3", "mcap": "mcap"}[storage] in (bag / "metadata.yaml").read_text()
    assert bag_generation(bag) == bag_generation(storage_file(bag, storage)) == "rosbag2"
    assert detect_source(bag) == detect_source(storage_file(bag, storage)) == "bag"


@pytest.mark.parametrize("alone", [False, True], ids=["folder", "storage file alone"])
def test_the_round_trip_is_lossless(ros2_bag, rec, alone):
    storage, bag = ros2_bag
    back = read_bag(storage_file(bag, storage) if alone else bag, rec.target)
    assert back.metadata["source"] == "rosbag2"
    assert np.array_equal(back.imu.t, rec.imu.t)
    assert np.array_equal(back.imu.gyro, rec.imu.gyro) and np.array_equal(back.imu.accel, rec.imu.accel)
    assert np.array_equal(back.frames.t, rec.frames.t)
    assert np.array_equal(back.frames.images, rec.frames.images)
    assert np.array_equal(open_imu(bag).gyro, rec.imu.gyro)  # vical-imu-noise's reader


def messages_by_an_independent_reader(storage: str, bag: Path) -> list[tuple[str, str, int, object]]:
    """(topic, type, log time, decoded message) of every message, read and CDR-decoded by the MCAP project's
    libraries from the message definitions the bag carries."""
    decoders = DecoderFactory()
    if storage == "mcap":
        with open(storage_file(bag, storage), "rb") as f:
            return [(c.topic, s.name, m.log_time, decoded) for s, c, m, decoded in
                    make_reader(f, decoder_factories=[decoders]).iter_decoded_messages()]  # fmt: skip
    with sqlite3.connect(storage_file(bag, storage)) as db:
        definitions = dict(db.execute("select topic_type, encoded_message_definition from message_definitions"))
        topics = {i: (name, kind) for i, name, kind in db.execute("select id, name, type from topics")}
        rows = db.execute("select topic_id, timestamp, data from messages order by timestamp, id").fetchall()
    schemas = {kind: Schema(id=k + 1, name=kind, encoding="ros2msg", data=definitions[kind].encode())
               for k, kind in enumerate(definitions)}  # fmt: skip
    decode = {kind: decoders.decoder_for("cdr", schema) for kind, schema in schemas.items()}
    return [(topics[i][0], topics[i][1], t, decode[topics[i][1]](data)) for i, t, data in rows]


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_an_independent_reader_decodes_kalibrs_topics_with_the_exact_stamps_images_and_imu_samples(ros2_bag, rec):
    storage, bag = ros2_bag
    messages = messages_by_an_independent_reader(storage, bag)
    images = [(t, msg) for topic, kind, t, msg in messages if (topic, kind) == ("/cam0/image_raw", IMAGE_TYPE)]
    imu = [(t, msg) for topic, kind, t, msg in messages if (topic, kind) == ("/imu0", IMU_TYPE)]
    assert len(messages) == len(images) + len(imu) and len(images) == len(rec.frames) and len(imu) == len(rec.imu)
    log_times = [t for _, _, t, _ in messages]
    assert log_times == sorted(log_times)
    assert [stamp_ns(m) for _, m in images] == [t for t, _ in images] == rec.frames.t.tolist()
    for (_, msg), image in zip(images, rec.frames.images, strict=True):
        assert (msg.encoding, msg.height, msg.width, msg.step) == (
            "mono8",
            48,
            64,
            64,
        ) and msg.header.frame_id == "cam0"
        assert np.array_equal(np.frombuffer(bytes(msg.data), np.uint8).reshape(48, 64), image)
    assert [stamp_ns(m) for _, m in imu] == rec.imu.t.tolist()
    gyro = [[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for _, m in imu]
    accel = [[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for _, m in imu]
    assert np.array_equal(gyro, rec.imu.gyro) and np.array_equal(accel, rec.imu.accel)
    assert all(m.orientation_covariance[0] == -1.0 for _, m in imu)  # ROS: no orientation given


HEADER_DEFINITION = """
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec"""

IMAGE_DEFINITION = (
    """std_msgs/Header header
uint32 height
uint32 width
string encoding
uint8 is_bigendian
uint32 step
uint8[] data"""
    + HEADER_DEFINITION
)

IMU_DEFINITION = (
    """std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance"""
    + HEADER_DEFINITION
    + """
================================================================================
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z"""
)


def header(t: int, frame: str) -> dict:
    return {"stamp": {"sec": t // 1_000_000_000, "nanosec": t % 1_000_000_000}, "frame_id": frame}


def test_a_bag_written_by_mcaps_own_ros2_writer_is_read(rec, tmp_path):
    """rgb8 images on the driver's own topics, written by MCAP's ROS 2 writer (not rosbags): read as grey."""
    path = tmp_path / "driver.mcap"
    with open(path, "wb") as f:
        writer = McapRos2Writer(f)
        image_schema = writer.register_msgdef(IMAGE_TYPE, IMAGE_DEFINITION)
        imu_schema = writer.register_msgdef(IMU_TYPE, IMU_DEFINITION)
        events = [(int(t), "imu", k) for k, t in enumerate(rec.imu.t)] + [(int(t), "image", k) for k, t in
                                                                          enumerate(rec.frames.t)]  # fmt: skip
        for t, kind, k in sorted(events):
            if kind == "image":
                rgb = np.repeat(rec.frames.images[k][:, :, None], 3, axis=2)
                msg = {"header": header(t, "left"), "height": 48, "width": 64, "encoding": "rgb8", "is_bigendian": 0,
                       "step": 64 * 3, "data": rgb.tobytes()}  # fmt: skip
                writer.write_message("/left/image_raw", image_schema, msg, log_time=t, publish_time=t)
            else:
                vec = {"angular_velocity": rec.imu.gyro[k], "linear_acceleration": rec.imu.accel[k]}
                msg = {"header": header(t, "imu"), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                       "orientation_covariance": [-1.0] + [0.0] * 8, "angular_velocity_covariance": [0.0] * 9,
                       "linear_acceleration_covariance": [0.0] * 9}  # fmt: skip
                msg |= {key: dict(zip("xyz", map(float, v), strict=True)) for key, v in vec.items()}
                writer.write_message("/imu/data", imu_schema, msg, log_time=t, publish_time=t)
        writer.finish()
    assert detect_source(path) == "bag" and bag_image_topics(path) == ["/left/image_raw"]
    back = read_bag(path, rec.target, image_topic="/left/image_raw", imu_topic="/imu/data")
    assert np.array_equal(back.frames.t, rec.frames.t) and np.array_equal(back.frames.images, rec.frames.images)
    assert np.array_equal(back.imu.t, rec.imu.t) and np.array_equal(back.imu.gyro, rec.imu.gyro)
    with pytest.raises(BagFormatError, match=r"topic /cam0/image_raw is missing; the bag has: /left/image_raw"):
        read_bag(path, rec.target)


@pytest.mark.parametrize("storage", STORAGES)
def test_a_truncated_or_foreign_ros2_bag_is_named_in_one_line(rec, storage, tmp_path):
    bag = write_bag(rec, tmp_path / "bag", bag_format=storage)
    data = storage_file(bag, storage).read_bytes()
    storage_file(bag, storage).write_bytes(data[: len(data) // 2])
    with pytest.raises(BagFormatError, match=r"bag cannot be read as a ROS 2 bag \(corrupt or truncated\?\)"):
        read_bag(bag, rec.target)
    other = tmp_path / "other"
    other.mkdir()
    (other / "metadata.yaml").write_text("name: a camera driver's own settings\n")
    assert bag_generation(other) is None
    with pytest.raises(BagFormatError, match=r"neither a ROS1 bag .* nor a ROS 2 bag"):
        read_bag(other, rec.target)


def test_a_ros2_bag_in_a_storage_vical_does_not_read_is_named_with_how_to_convert_it(rec, tmp_path, capsys):
    bag = write_bag(rec, tmp_path / "bag", bag_format="db3")
    metadata = bag / "metadata.yaml"
    metadata.write_text(metadata.read_text().replace("storage_identifier: sqlite3", "storage_identifier: zstd_db"))
    line = f"{bag}: its storage 'zstd_db' is not one vical reads (sqlite3 or mcap); convert the bag to one"
    with pytest.raises(BagFormatError, match=f"^{re.escape(line)}, e.g. with ros2 bag convert"):
        read_bag(bag, rec.target)
    write_target_yaml(tmp_path / "target.yaml", rec.target)
    capsys.readouterr()  # the writer's progress
    assert calibrate_main([str(bag), "--target", str(tmp_path / "target.yaml"), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.strip().startswith(f"vical-calibrate: error: {line}")
    assert not (tmp_path / "out").exists()


def test_writing_a_ros2_bag_refuses_an_existing_one_replaces_it_whole_with_overwrite(rec, tmp_path):
    bag = write_bag(rec, tmp_path / "bag", bag_format="mcap")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_bag(rec, bag, bag_format="mcap")
    other = make_recording(seed=5)
    write_bag(other, bag, bag_format="db3", overwrite=True)
    assert sorted(p.name for p in bag.iterdir()) == ["bag.db3", "metadata.yaml"]
    assert np.array_equal(read_bag(bag, other.target).imu.gyro, other.imu.gyro)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]  # no temporary left
    with pytest.raises(FormatError, match="bag format 'ros3': choose one of ros1, db3, mcap"):
        write_bag(rec, tmp_path / "x", bag_format="ros3")
