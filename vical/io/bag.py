"""ROS1 and ROS 2 bags through the pure-Python ``rosbags`` package (no ROS install), with Kalibr's topic conventions.

A ROS1 bag is a file (``#ROSBAG V2.0``); a ROS 2 bag a folder with ``metadata.yaml`` and its storage file, SQLite
(``.db3``) or MCAP (``.mcap``), or that storage file alone; both are read and written with the same topics and
messages (ROS 2's are CDR-serialised, with ROS 2 Jazzy's message definitions, in rosbag2's format version 9). Writes
``sensor_msgs/Image`` (``mono8``) on ``/cam0/image_raw`` and ``sensor_msgs/Imu`` on
``/imu0`` (gyro in ``angular_velocity`` [rad/s], specific force in ``linear_acceleration``
[m/s^2], ``orientation_covariance[0] = -1``: no orientation), stamped in ``header.stamp`` and the
bag time with the exact ns timestamps, which ``kalibr_calibrate_imu_camera`` reads. Reading
takes the same topics (configurable), decodes ``mono8``/``rgb8``/``bgr8``/``bgra8``/``rgba8``
images and ``sensor_msgs/CompressedImage`` to grey, and stamps with ``header.stamp``. A rig's
cameras are several image topics: ``cam0``'s first (``/cam0/image_raw``, ``/cam1/image_raw``, ...).
"""

from __future__ import annotations

import contextlib
import functools
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from rosbags import rosbag1, rosbag2
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore
from tqdm import tqdm

from vical.data import NS_PER_S, CameraFrames, DataError, ImuSamples, Recording, Target
from vical.io.atomic import remove_stale_temporaries, replace_directory, temporary_prefix
from vical.io.errors import BagFormatError, BagTopicError, FormatError, UnitError
from vical.io.images import ImageDetector, check_size, run_detector, to_gray
from vical.io.sample_checks import check_camera_rates, check_sampling, scale_imu, sort_and_dedupe

IMAGE_TYPE, COMPRESSED_TYPE, IMU_TYPE = (
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs/msg/Imu",
)
COLOR_CODES = {"rgb8": cv2.COLOR_RGB2GRAY, "bgr8": cv2.COLOR_BGR2GRAY, "rgba8": cv2.COLOR_RGBA2GRAY}
COLOR_CODES["bgra8"] = cv2.COLOR_BGRA2GRAY


ROS1, ROS2 = "rosbag1", "rosbag2"
ROS1_MAGIC = b"#ROSBAG V2.0"
ROS2_STORAGES = {".db3": b"SQLite format 3\x00", ".mcap": b"\x89MCAP0\r\n"}  # a storage file's suffix and start
# What write_bag writes: a ROS1 bag, or a ROS 2 bag in SQLite or MCAP storage.
BAG_FORMATS = {"ros1": None, "db3": rosbag2.StoragePlugin.SQLITE3, "mcap": rosbag2.StoragePlugin.MCAP}
LABELS = {ROS1: "ROS1 bag", ROS2: "ROS 2 bag"}
NOT_A_BAG = "neither a ROS1 bag (#ROSBAG V2.0) nor a ROS 2 bag (a folder with metadata.yaml, a .db3 or .mcap file)"


@functools.cache
def ros1_typestore() -> Typestore:
    """ROS1 Noetic message types (built on first use: it takes about 0.1 s)."""
    return get_typestore(Stores.ROS1_NOETIC)


@functools.cache
def ros2_typestore() -> Typestore:
    """ROS 2 Jazzy message types (sensor_msgs' Image, CompressedImage and Imu as in every ROS 2 since Foxy)."""
    return get_typestore(Stores.ROS2_JAZZY)


def _starts_with(path: Path, magic: bytes) -> bool:
    with open(path, "rb") as f:
        return f.read(len(magic)) == magic


def bag_generation(path: str | os.PathLike) -> str | None:
    """``ROS1`` or ``ROS2`` for the bag ``path`` holds (by its first bytes, or a ROS 2 folder's metadata.yaml), or
    None for anything else."""
    path = Path(path)
    if path.is_dir():
        metadata = path / "metadata.yaml"
        holds = metadata.is_file() and "rosbag2_bagfile_information" in metadata.read_text(errors="replace")
        return ROS2 if holds else None
    if not path.is_file():
        return None
    if _starts_with(path, ROS1_MAGIC):
        return ROS1
    magic = ROS2_STORAGES.get(path.suffix.lower())
    return ROS2 if magic is not None and _starts_with(path, magic) else None


def _check_storage(path: Path) -> None:
    """A ROS 2 bag folder whose ``metadata.yaml`` names a storage rosbags does not read (neither SQLite nor MCAP): a
    ``BagFormatError`` that says so and how to convert it (before rosbags asks for an issue report)."""
    if not path.is_dir():
        return
    try:
        info = yaml.safe_load((path / "metadata.yaml").read_text(errors="replace"))["rosbag2_bagfile_information"]
        storage = info["storage_identifier"]
    except (yaml.YAMLError, KeyError, TypeError):
        return  # rosbags' reader names what is wrong with the metadata
    known = [plugin.name.lower() for plugin in BAG_FORMATS.values() if plugin is not None]  # metadata.yaml's names
    if storage not in known:
        raise BagFormatError(
            f"{path}: its storage {storage!r} is not one vical reads ({' or '.join(known)}); convert the bag to one, "
            "e.g. with ros2 bag convert, or rosbags-convert --dst-storage mcap"
        )


@contextlib.contextmanager
def _opened(path: Path) -> Iterator[tuple[Any, Callable[[bytes, str], Any]]]:
    """The bag at ``path``, open, and the deserialiser of its messages; its faults as ``BagFormatError``."""
    generation = bag_generation(path)
    if generation is None:
        raise BagFormatError(f"{path} is {NOT_A_BAG}" if path.exists() else f"{path} does not exist")
    if generation == ROS2:
        _check_storage(path)
    try:
        if generation == ROS1:
            with rosbag1.Reader(path) as reader:
                yield reader, ros1_typestore().deserialize_ros1
        else:
            with rosbag2.Reader(path) as reader:
                yield reader, ros2_typestore().deserialize_cdr
    except (rosbag1.ReaderError, rosbag2.ReaderError) as exc:
        label = LABELS[generation]
        raise BagFormatError(f"{path} cannot be read as a {label} (corrupt or truncated?): {exc}") from exc


def camera_topics(image_topic: str | Sequence[str], count: int) -> list[str]:
    """The image topics of ``count`` cameras: the given ones, or one topic (cam0's) and ``/camN/image_raw``."""
    topics = [image_topic] if isinstance(image_topic, str) else list(image_topic)
    topics += [f"/cam{n}/image_raw" for n in range(len(topics), count)]
    if len(set(topics)) != len(topics):
        raise FormatError(f"image topics {topics} repeat a topic; give each camera its own")
    return topics


def bag_image_topics(path: str | os.PathLike) -> list[str]:
    """The topics of the bag ``path`` that hold images (raw or compressed), in the bag's order."""
    with _opened(Path(path)) as (reader, _):
        return [c.topic for c in reader.connections if c.msgtype in (IMAGE_TYPE, COMPRESSED_TYPE)]


# ------------------------------------------------------------------------------------ write
def write_bag(
    recording: Recording,
    path: str | os.PathLike,
    image_topic: str | Sequence[str] = "/cam0/image_raw",
    imu_topic: str = "/imu0",
    overwrite: bool = False,
    bag_format: str = "ros1",
) -> Path:
    """Write ``recording`` (its cameras must carry images) as a bag, whole or not at all: a ROS1 bag Kalibr can read
    (``bag_format="ros1"``: the file ``path``) or a ROS 2 bag (``"db3"`` or ``"mcap"``: the folder ``path``, its
    ``metadata.yaml`` and ``<name>.db3`` / ``<name>.mcap``).

    ``image_topic``: cam0's topic, or one per camera (the other cameras default to ``/camN/image_raw``).
    """
    if bag_format not in BAG_FORMATS:
        raise FormatError(f"bag format {bag_format!r}: choose one of {', '.join(BAG_FORMATS)}")
    for name in recording.camera_names:
        if recording.frames_of(name).images is None:
            raise FormatError(
                f"a calibration bag holds images, but the recording's {name} has none; record it with images"
            )
    topics = camera_topics(image_topic, len(recording.camera_names))
    final = Path(path)
    is_folder = bag_format != "ros1"
    if final.exists() and (not overwrite or final.is_dir() != is_folder):
        raise FileExistsError(f"{final} already exists; pass overwrite=True to replace it")
    final.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(final.parent, final.name)
    tmp_dir = Path(tempfile.mkdtemp(prefix=temporary_prefix(final), dir=final.parent))
    try:
        written = tmp_dir / final.name
        if is_folder:
            writer = rosbag2.Writer(written, version=9, storage_plugin=BAG_FORMATS[bag_format])
            _write_messages(recording, writer, ros2_typestore(), ros2_typestore().serialize_cdr, topics, imu_topic)
            replace_directory(written, final)
        else:
            writer = rosbag1.Writer(written)
            _write_messages(recording, writer, ros1_typestore(), ros1_typestore().serialize_ros1, topics, imu_topic)
            os.replace(written, final)
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)
    return final


def _write_messages(
    rec: Recording,
    writer: Any,
    store: Typestore,
    serialize: Callable[[Any, str], bytes],
    image_topics: list[str],
    imu_topic: str,
) -> None:
    events = [(int(t), 0, -1, k) for k, t in enumerate(rec.imu.t)]
    for c, name in enumerate(rec.camera_names):
        events += [(int(t), 1, c, k) for k, t in enumerate(rec.frames_of(name).t)]
    events.sort()
    with writer:
        cams = [writer.add_connection(topic, IMAGE_TYPE, typestore=store) for topic in image_topics]
        imu = writer.add_connection(imu_topic, IMU_TYPE, typestore=store)
        for t, is_image, c, k in tqdm(events, desc=f"writing {writer.path.name}", unit="msg", leave=False):
            if not is_image:
                msg = _imu_msg(t, k, rec.imu.gyro[k], rec.imu.accel[k], store)
                writer.write(imu, t, serialize(msg, IMU_TYPE))
            else:
                name = rec.camera_names[c]
                msg = _image_msg(t, k, rec.frames_of(name).images[k], name, store)
                writer.write(cams[c], t, serialize(msg, IMAGE_TYPE))


def _header(t_ns: int, seq: int, frame_id: str, store: Typestore) -> Any:
    sec, nsec = divmod(t_ns, NS_PER_S)
    stamp = store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    header = store.types["std_msgs/msg/Header"]
    numbered = {"seq": seq} if "seq" in header.__dataclass_fields__ else {}  # ROS 2's header has no number
    return header(**numbered, stamp=stamp, frame_id=frame_id)


def _image_msg(t_ns: int, seq: int, image: np.ndarray, frame_id: str = "cam0", store: Typestore | None = None) -> Any:
    store = store or ros1_typestore()
    h, w = image.shape
    return store.types[IMAGE_TYPE](
        header=_header(t_ns, seq, frame_id, store),
        height=h,
        width=w,
        encoding="mono8",
        is_bigendian=0,
        step=w,
        data=np.ascontiguousarray(image).reshape(-1),
    )


def _imu_msg(t_ns: int, seq: int, gyro: np.ndarray, accel: np.ndarray, store: Typestore | None = None) -> Any:
    store = store or ros1_typestore()
    types = store.types
    vec = types["geometry_msgs/msg/Vector3"]
    cov = np.zeros(9)
    orientation_cov = cov.copy()
    orientation_cov[0] = -1.0  # ROS convention: the orientation field is not provided
    return types[IMU_TYPE](
        header=_header(t_ns, seq, "imu0", store),
        orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=orientation_cov,
        angular_velocity=vec(x=float(gyro[0]), y=float(gyro[1]), z=float(gyro[2])),
        angular_velocity_covariance=cov,
        linear_acceleration=vec(x=float(accel[0]), y=float(accel[1]), z=float(accel[2])),
        linear_acceleration_covariance=cov,
    )


# ------------------------------------------------------------------------------------ read
def read_bag(
    path: str | os.PathLike,
    target: Target,
    detector: ImageDetector | None = None,
    image_topic: str | Sequence[str] = "/cam0/image_raw",
    imu_topic: str | None = "/imu0",
    keep_images: bool = True,
    gyro_unit: str = "rad/s",
    accel_unit: str = "m/s^2",
) -> Recording:
    """Recording from a ROS1 or ROS 2 bag: images on ``image_topic`` (corners by ``detector``), IMU on ``imu_topic``.

    ``image_topic`` may list several topics, one per camera of a rig (``cam0``, ``cam1``, ... in that
    order; ``metadata["image_topics"]`` names them, ``metadata["image_sizes"]`` gives each one's
    (W, H) [px]). ``imu_topic=None`` reads images only (intrinsic calibration). Raises
    ``BagFormatError`` naming the bag and topic when the bag is corrupt or truncated, a topic is
    missing or has the wrong type, images change size, or timestamps/units are implausible.
    Cameras at different frame rates get a ``FormatWarning`` naming them.
    """
    path = Path(path)
    topics = camera_topics(image_topic, 1)
    with _opened(path) as (reader, deserialize):
        connections = _connections(reader, path, topics, imu_topic)
        frames, imu = _read_streams(reader, deserialize, connections, path, target, detector, keep_images)
    try:
        imu_samples = _imu_samples(imu, f"{path} topic {imu_topic}", gyro_unit, accel_unit)
        cameras = [_camera_frames(frames[topic], f"{path} topic {topic}", keep_images) for topic in topics]
    except UnitError:
        raise  # it names the unit setting to change
    except (FormatError, DataError) as exc:
        raise BagFormatError(str(exc)) from exc
    names = [f"cam{n}" for n in range(len(topics))]
    check_camera_rates(f"{path} (topics {', '.join(topics)})", {n: c[0].t for n, c in zip(names, cameras, strict=True)})
    metadata = {"source": bag_generation(path), "path": str(path.resolve())}
    metadata["image_topics"] = dict(zip(names, topics, strict=True))
    metadata["image_sizes"] = {n: c[1] for n, c in zip(names, cameras, strict=True)}
    other = {n: c[0] for n, c in zip(names[1:], cameras[1:], strict=True)}
    return Recording(imu_samples, cameras[0][0], target, metadata=metadata, other_frames=other)


def read_bag_imu(
    path: str | os.PathLike, imu_topic: str = "/imu0", gyro_unit: str = "rad/s", accel_unit: str = "m/s^2"
) -> ImuSamples:
    """The IMU samples on ``imu_topic`` of a ROS1 or ROS 2 bag (no images needed: a static IMU recording).

    Raises ``BagFormatError`` naming the bag and topic as ``read_bag`` does.
    """
    path = Path(path)
    with _opened(path) as (reader, deserialize):
        connections = _connections(reader, path, [], imu_topic)
        _, imu = _read_streams(reader, deserialize, connections, path, None, None, False)
    if not imu:
        raise BagFormatError(f"{path} topic {imu_topic}: no IMU messages")
    try:
        return _imu_samples(imu, f"{path} topic {imu_topic}", gyro_unit, accel_unit)
    except UnitError:
        raise  # it names the unit setting to change
    except (FormatError, DataError) as exc:
        raise BagFormatError(str(exc)) from exc


def _connections(reader: Any, path: Path, image_topics: list[str], imu_topic: str | None) -> dict[str, Any]:
    topics = {c.topic: c for c in reader.connections}
    wanted = [(topic, (IMAGE_TYPE, COMPRESSED_TYPE), "image_topic") for topic in image_topics]
    if imu_topic is not None:
        wanted.append((imu_topic, (IMU_TYPE,), "imu_topic"))
    found = {}
    for topic, types, setting in wanted:
        if topic not in topics:
            listing = ", ".join(f"{c.topic} ({c.msgtype})" for c in reader.connections) or "none"
            raise BagTopicError(
                f"{path}: topic {topic} is missing; the bag has: {listing}. Choose the topic ({{fix}})",
                setting, None, None,
            )  # fmt: skip
        if topics[topic].msgtype not in types:
            raise BagFormatError(f"{path}: topic {topic} holds {topics[topic].msgtype}, expected {' or '.join(types)}")
        found[topic] = topics[topic]
    return found


def _read_streams(
    reader: Any,
    deserialize: Callable[[bytes, str], Any],
    connections: dict[str, Any],
    path: Path,
    target: Target | None,
    detector: ImageDetector | None,
    keep_images: bool,
) -> tuple[dict[str, list], list]:
    """Decode every message of the chosen connections (tqdm progress): frame tuples by topic and IMU rows."""
    frames: dict[str, list] = {topic: [] for topic, c in connections.items() if c.msgtype != IMU_TYPE}
    imu, sizes = [], {}
    total = sum(c.msgcount for c in connections.values())
    messages = reader.messages(connections=list(connections.values()))
    for index, (conn, _, raw) in enumerate(tqdm(messages, total=total, desc=path.name, unit="msg", leave=False)):
        msg = deserialize(raw, conn.msgtype)
        t = int(msg.header.stamp.sec) * NS_PER_S + int(msg.header.stamp.nanosec)
        where = f"{path} topic {conn.topic} message {index}"
        if conn.msgtype == IMU_TYPE:
            w, a = msg.angular_velocity, msg.linear_acceleration
            imu.append((t, index, (w.x, w.y, w.z, a.x, a.y, a.z)))
            continue
        image = _decode_image(msg, conn.msgtype, where)
        sizes[conn.topic] = check_size(image, sizes.get(conn.topic), where)
        corners, ids = run_detector(detector, image, target, where) if detector else (np.zeros((0, 2)), np.zeros(0))
        digest = hash(image.tobytes())  # tells repeated messages from conflicting ones with one stamp
        frames[conn.topic].append((t, index, image if keep_images else None, corners, ids, digest, image.shape))
    return frames, imu


def _decode_image(msg: Any, msgtype: str, where: str) -> np.ndarray:
    if msgtype == COMPRESSED_TYPE:
        image = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise BagFormatError(f"{where}: cannot decode the compressed image ({msg.format})")
        return to_gray(image, where)
    channels = {"mono8": 1, "8UC1": 1, **dict.fromkeys(COLOR_CODES, 3)}
    channels.update(rgba8=4, bgra8=4)
    if msg.encoding not in channels:
        raise BagFormatError(f"{where}: image encoding {msg.encoding!r} is not supported; use mono8 (or rgb8/bgr8)")
    n = channels[msg.encoding]
    data = np.frombuffer(msg.data, np.uint8)
    if data.size < msg.step * msg.height or msg.step < msg.width * n:
        raise BagFormatError(f"{where}: image data has {data.size} bytes, too few for {msg.width} x {msg.height}")
    rows = data[: msg.step * msg.height].reshape(msg.height, msg.step)[:, : msg.width * n]
    image = rows.reshape(msg.height, msg.width, n)
    return image[:, :, 0].copy() if n == 1 else cv2.cvtColor(image, COLOR_CODES[msg.encoding])


def _imu_samples(rows: list, where: str, gyro_unit: str, accel_unit: str) -> ImuSamples:
    if not rows:
        return ImuSamples(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    t = np.array([r[0] for r in rows], dtype=np.int64)
    values = np.array([r[2] for r in rows], dtype=np.float64)
    order = sort_and_dedupe(t, values, where, np.array([r[1] for r in rows]))
    check_sampling(t[order], where)
    gyro, accel = scale_imu(values[order, :3], values[order, 3:], gyro_unit, accel_unit, where)
    return ImuSamples(t[order], gyro, accel)


def _camera_frames(frames: list, where: str, keep_images: bool) -> tuple[CameraFrames, list[int]]:
    """One topic's frames and its image size [W, H]."""
    if not frames:
        raise BagFormatError(f"{where}: no image messages")
    t = np.array([f[0] for f in frames], dtype=np.int64)
    digest = np.array([[f[5]] for f in frames])
    order = sort_and_dedupe(t, digest, where, np.array([f[1] for f in frames]))
    check_sampling(t[order], where)
    images = np.stack([frames[k][2] for k in order]) if keep_images else None
    height, width = frames[0][6]
    return CameraFrames(t[order], [frames[k][3] for k in order], [frames[k][4] for k in order], images), [width, height]
